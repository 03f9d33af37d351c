"""Simulate one day of a scenario and report its network, traffic and charging queues.

    python scripts/inspect_scenario.py evs=400 seed=0
    python scripts/inspect_scenario.py -m evs=200,300,400          # one run per EV count
    python scripts/inspect_scenario.py scenario.path=/data/my_city begin=25200 end=36000
    python scripts/inspect_scenario.py perturbations=mixed seed=3   # a day that is not calm

Prints the network size, the station-to-station road distances, per hour the vehicles running, their
mean speed and teleports, and per station the EVs served, the longest queue and the mean wait. Writes
``report.json``, ``routes.rou.xml.gz`` and ``scenario_day.png`` into the Hydra run directory; with
perturbations, the day's events (drawn from its seed as in every environment) are played, listed in
``report.json`` and drawn in ``day_events.png`` (where the incidents and road works are, when the
rain, the incidents and the charger outages happen).
"""

from __future__ import annotations

import json
import logging
import sys
from dataclasses import asdict
from pathlib import Path

import hydra
import numpy as np
from hydra.core.hydra_config import HydraConfig
from hydra.utils import to_absolute_path
from omegaconf import DictConfig, OmegaConf

from evcd.experiments.worlds import demand_config
from evcd.report.events_figure import plot_day_events
from evcd.report.figures import plot_scenario_day
from evcd.report.scenario import day_summary, format_table, station_distance_matrix, station_table
from evcd.scenario.demand import DAY, generate_demand, write_demand
from evcd.scenario.netstats import format_summary, network_summary
from evcd.scenario.scenario import load_scenario
from evcd.sim.day import simulate_day
from evcd.sim.perturbations import Perturbations
from evcd.utils.atomic import atomic_write_text

log = logging.getLogger("inspect_scenario")


def inspect(cfg: DictConfig, out_dir: Path) -> dict:
    """Run the inspection described by ``cfg``; write its files into ``out_dir``; return the report."""
    # every check before SUMO starts
    if not 0 <= cfg.begin < cfg.end <= DAY:
        raise ValueError(f"need 0 <= begin < end <= {DAY}, got begin={cfg.begin}, end={cfg.end}")
    demand_cfg = demand_config(cfg)
    scenario = load_scenario(
        to_absolute_path(cfg.scenario.path), charging_points=cfg.scenario.charging_points
    )
    block = OmegaConf.select(cfg, "perturbations")
    perturbations = Perturbations.from_value(OmegaConf.to_container(block, resolve=True) if block else None)
    outages = perturbations.outages_of(scenario.stations, int(cfg.seed))
    lots = {st.lane for st in scenario.stations}  # the car parks' lanes stay open
    roads = perturbations.roads_of(scenario.net, demand_cfg.hourly_profile, int(cfg.seed), lots)

    net = network_summary(scenario.net_file)
    dist = station_distance_matrix(scenario)
    log.info("network %s: %s", scenario.net_file.name, format_summary(net))
    names = [s.id for s in scenario.stations]
    rows = [
        {"from/to": a, **{b: float(dist[i, j]) for j, b in enumerate(names)}} for i, a in enumerate(names)
    ]
    log.info("station-to-station road distance (m):\n%s", format_table(rows, "{:.0f}"))
    off = dist[~np.eye(len(names), dtype=bool)]
    log.info("closest pair of stations: %.0f m by road", off.min() if off.size else float("nan"))

    demand = generate_demand(scenario.net, list(scenario.stations), demand_cfg, seed=int(cfg.seed))
    routes = write_demand(demand, out_dir / "routes.rou.xml.gz")
    in_span = sum(1 for t in demand.trips if cfg.begin <= t.depart < cfg.end)

    day = simulate_day(
        scenario, routes, seed=int(cfg.seed), begin=float(cfg.begin), end=float(cfg.end),
        sample_every=float(cfg.sample_every), step_length=float(cfg.sumo.step_length),
        time_to_teleport=float(cfg.sumo.time_to_teleport), outages=outages, roads=roads,
    )  # fmt: skip
    hourly = day.traffic.hourly()
    stations = station_table(scenario, day)
    summary = day_summary(day, in_span)
    log.info("per hour:\n%s", format_table(hourly))
    log.info("per station:\n%s", format_table(stations))
    log.info("day (evs=%d, seed=%d):\n%s", cfg.evs, cfg.seed, format_table([summary], "{:.4g}"))

    png = plot_scenario_day(
        scenario.net, scenario.stations, np.asarray(day.traffic.sample_times),
        {k: np.asarray(v) for k, v in day.traffic.waiting.items()},
        {k: np.asarray(v) for k, v in day.traffic.charging.items()},
        out_dir / "scenario_day.png",
        title=f"{scenario.root.name}: {demand_cfg.cars_per_day} cars, {cfg.evs} EVs, seed {cfg.seed}",
    )  # fmt: skip
    if not perturbations.calm:
        events_png = plot_day_events(
            scenario.net, scenario.stations, roads, outages, out_dir / "day_events.png",
            title=f"{scenario.root.name}, seed {cfg.seed}: the day's perturbations",
        )  # fmt: skip
        counts = (len(roads.incidents), len(roads.rain), len(roads.roadworks), len(outages))
        log.info("the day's events: %d incidents, %d rain spells, %d road works, %d charger outages (%s)",
                 *counts, events_png)  # fmt: skip
    report = {
        "config": OmegaConf.to_container(cfg, resolve=True),
        "events": {**roads.to_dict(), "outages": [asdict(o) for o in outages]},
        "network": net,
        "station_distance_m": dist.tolist(),
        "hourly": hourly,
        "stations": stations,
        "summary": summary,
        "charges": [r.to_dict() for r in day.charges],
        "demand": asdict(demand_cfg),
    }
    atomic_write_text(out_dir / "report.json", json.dumps(report, indent=1))
    log.info("wrote %s and %s", out_dir / "report.json", png)
    return report


@hydra.main(version_base="1.3", config_path="../conf", config_name="inspect")
def main(cfg: DictConfig) -> None:
    """Hydra entry point."""
    out_dir = Path(HydraConfig.get().runtime.output_dir)
    try:
        inspect(cfg, out_dir)
    except (ValueError, FileNotFoundError) as exc:
        log.error("%s", exc)
        sys.exit(2)


if __name__ == "__main__":
    main()
