"""The forecasters' errors on an experiment's held-out days.

    python scripts/forecast_errors.py                         # README regime: 400 EVs, morning peak, calm
    python scripts/forecast_errors.py perturbations=mixed     # the same days with every perturbation
    python scripts/forecast_errors.py experiment=table evs=300

For each evaluation day, decision time in the departure window and horizon, each forecaster's
forecast of the vehicles at each station at the time plus the horizon, against what the day's
records say (:mod:`evcd.experiments.forecast_report`). Writes ``forecast_errors.json`` (every row)
and ``forecast_errors.md`` (a table per forecaster, stations by hour) into the Hydra run directory.
The forecasters that learn (history, anomaly, sessions) learn from ``days.train`` only;
``forecast.split=tuning`` scores the tuning days instead (where settings are chosen, e.g.
``+forecast.settings.sessions.history_weight=0.25``).
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from evcd.cli.errors import stop_on_bad_setting
from evcd.cli.run_record import write_run_record
from evcd.env.config import forecaster_setting
from evcd.experiments.forecast_report import day_timelines, forecaster_errors, overall
from evcd.experiments.schema import register_configs
from evcd.experiments.worlds import split_kwargs
from evcd.forecast import FORECASTERS, format_mae_table
from evcd.utils.atomic import atomic_write_json, atomic_write_text
from evcd.utils.validation import check_choice, check_real

log = logging.getLogger("forecast_errors")


def report(cfg: DictConfig, out_dir: Path) -> dict:
    """Compute and write the errors of ``cfg``'s forecasters; return the report."""
    names = [str(n) for n in cfg.forecast.forecasters]
    unknown = sorted(set(names) - set(FORECASTERS))
    if unknown or not names:
        raise ValueError(f"forecast.forecasters={names}: choose among {', '.join(FORECASTERS)}")
    horizons = [check_real("forecast.horizons_s", h, low=0.0) for h in cfg.forecast.horizons_s]
    every = check_real("forecast.every_s", cfg.forecast.every_s, low=0.0, low_open=True)
    split = check_choice("forecast.split", str(cfg.forecast.split), ("eval", "tuning"))
    settings = OmegaConf.to_container(cfg.forecast.settings, resolve=True) or {}
    stray = sorted(set(settings) - set(names))
    if stray:
        raise ValueError(f"forecast.settings names {stray}: settings go to the forecasters compared, {names}")
    for name, given in settings.items():  # checks the names and values of the settings before any day
        forecaster_setting({"name": name, **given})
    train_kwargs, eval_kwargs = split_kwargs(cfg, "train", 0), split_kwargs(cfg, split, 0)
    write_run_record(out_dir, cfg)
    t0 = time.perf_counter()
    train, held_out = day_timelines(train_kwargs), day_timelines(eval_kwargs)
    window = tuple(eval_kwargs["departure_window"])
    rows = forecaster_errors(train, held_out, window, names, horizons, every, settings)
    wall = time.perf_counter() - t0
    perturbed = OmegaConf.to_container(cfg.perturbations, resolve=True) or {}
    data = {
        "evs": int(cfg.evs), "train_days": list(train_kwargs["demand_seeds"]),
        "evaluation_days": list(eval_kwargs["demand_seeds"]), "split": split, "settings": settings,
        "window": list(window),
        "perturbations": perturbed, "horizons_s": horizons, "every_s": every,
        "overall_mae": {n: overall(r) for n, r in rows.items()}, "rows": rows, "wall_s": round(wall, 1),
    }  # fmt: skip
    atomic_write_json(out_dir / "forecast_errors.json", data)
    lines = [
        f"# Forecast errors: vehicles at each station at arrival (MAE, vehicles), {cfg.evs} EVs",
        "",
        f"{'Held-out' if split == 'eval' else 'Tuning'} days {data['evaluation_days']} (history fitted on "
        f"days {data['train_days']}; settings {settings or 'the defaults'}); decision "
        f"times every {every:g} s in {window[0]:g}-{window[1]:g} s of day; horizons {horizons} s; "
        f"perturbations: {', '.join(perturbed) or 'none (calm)'}. Wall {wall:.0f} s.",
        "",
    ]
    for name, r in rows.items():
        lines += [f"## {name}: overall MAE {overall(r):.2f}", "", "```", format_mae_table(r), "```", ""]
    atomic_write_text(out_dir / "forecast_errors.md", "\n".join(lines))
    for name in rows:
        log.info("%s: overall MAE %.3f vehicles", name, data["overall_mae"][name])
    log.info("wrote %s and %s", out_dir / "forecast_errors.json", out_dir / "forecast_errors.md")
    return data


register_configs(Path(__file__).resolve().parents[1] / "conf")


@hydra.main(version_base="1.3", config_path="../conf", config_name="forecast_errors")
def main(cfg: DictConfig) -> None:
    """Hydra entry point; a bad setting exits with code 2."""
    out_dir = Path(HydraConfig.get().runtime.output_dir)
    try:
        report(cfg, out_dir)
    except (ValueError, FileNotFoundError) as exc:
        stop_on_bad_setting(exc, log, out_dir, cfg)


if __name__ == "__main__":
    main()
