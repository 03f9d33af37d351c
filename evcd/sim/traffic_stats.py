"""Traffic and station statistics sampled while a simulation runs (for inspection and calibration)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class TrafficRecorder:
    """Counts per step and samples per interval, aggregated per hour of day.

    Call :meth:`on_step` after every simulation step and :meth:`sample` every ``sample_every`` s.
    """

    station_ids: list[str]
    departed: int = 0
    arrived: int = 0
    teleports: int = 0
    teleported_ids: list[str] = field(default_factory=list)
    hourly_teleports: np.ndarray = field(default_factory=lambda: np.zeros(24, dtype=int))
    sample_times: list[float] = field(default_factory=list)
    running: list[int] = field(default_factory=list)
    mean_speed: list[float] = field(default_factory=list)
    waiting: dict[str, list[int]] = field(default_factory=dict)
    charging: dict[str, list[int]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for sid in self.station_ids:
            self.waiting.setdefault(sid, [])
            self.charging.setdefault(sid, [])

    def on_step(self, api, time: float) -> None:
        """Count departures, arrivals and teleports of the step just simulated (3-4 libsumo calls)."""
        sim = api.simulation
        self.departed += sim.getDepartedNumber()
        self.arrived += sim.getArrivedNumber()
        n = sim.getStartingTeleportNumber()
        if n:
            self.teleports += n
            self.teleported_ids.extend(sim.getStartingTeleportIDList())
            self.hourly_teleports[int(time // 3600) % 24] += n

    def sample(
        self, api, time: float, parked: int, waiting: dict[str, int], charging: dict[str, int]
    ) -> None:
        """Record vehicles on the road, their mean speed, and the queue of every station.

        ``parked`` vehicles (in car parks) are not counted as running.
        """
        ids = api.vehicle.getIDList()
        speeds = [api.vehicle.getSpeed(v) for v in ids]
        moving = max(len(ids) - parked, 0)
        self.sample_times.append(time)
        self.running.append(moving)
        self.mean_speed.append(float(np.sum(speeds)) / moving if moving else float("nan"))
        for sid in self.station_ids:
            self.waiting[sid].append(waiting[sid])
            self.charging[sid].append(charging[sid])

    def hourly(self) -> list[dict]:
        """Per hour of day: mean running vehicles, mean speed (km/h) and teleports (hours with samples)."""
        t = np.asarray(self.sample_times)
        run = np.asarray(self.running, dtype=float)
        spd = np.asarray(self.mean_speed, dtype=float)
        rows = []
        for h in range(24):
            m = (t > h * 3600) & (t <= (h + 1) * 3600)  # a sample closes the interval before it
            if not m.any():
                continue
            rows.append(
                {
                    "hour": h,
                    "running": float(run[m].mean()),
                    "mean_speed_kmh": float(np.nanmean(spd[m]) * 3.6) if np.isfinite(spd[m]).any() else 0.0,
                    "teleports": int(self.hourly_teleports[h]),
                }
            )
        return rows
