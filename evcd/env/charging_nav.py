"""``evcd/ChargingNav-v1``: guide one EV to a charging station, one decision per time slot.

    env = gymnasium.make("evcd/ChargingNav-v1", evs=400)        # the committed Jurong West scenario
    obs, info = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())

An episode is one target EV (:mod:`evcd.env.target`) departing at a random time of the departure
window from a random origin. Every ``decision_interval`` seconds the agent sees ``[D, N, Z]``
(:mod:`evcd.env.observation`) and picks a station; the episode terminates when the target starts
charging (it holds a charging point; queueing is not charging), with the reward of
:mod:`evcd.env.reward`. It is truncated, never crashed, when the target teleported, vanished, is
stuck, or exceeds ``max_travel_time``, or SUMO reports an error; ``info["reason"]`` says which.

Version history:

- ``v1`` (2026-11-29): the dynamics of ``v0``'s last state (commit a3e96b2), under an id that names
  them from now on: every ``results.json`` records the id with evcd's version and commit.
- ``v0`` (2026-11-22 to 2026-11-29, commits f6d6a86 to a3e96b2): the id through several changes of
  behaviour (observations made through ``gymnasium.make`` became normalised; fixes changed episode
  outcomes), so a result labelled ``v0`` is tied to its commit, not to the id. Refused now.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np

from evcd.env.config import PAPER_DAY_END, EnvConfig
from evcd.env.episode_rules import (
    MAX_INSERT_TRIES,
    TIME_EPS,
    Motion,
    another_origin,
    check_action,
    final_info,
    slot_deadline,
    slot_end_reason,
    visits_of,
)
from evcd.env.observation import Observation, layout_of, observation_bounds
from evcd.env.reward import Slot
from evcd.env.target import TARGET_ID, OriginSampler, Target, TargetPlan, draw_plan
from evcd.env.world import InWorld, World
from evcd.scenario.demand import DAY, DemandConfig
from evcd.scenario.scenario import JURONG_WEST
from evcd.sim.driver import SUMO_ERRORS
from evcd.sim.perturbations import Perturbations

log = logging.getLogger(__name__)

_OPTIONS = {"departure", "origin", "depart_pos", "day"}


@dataclass
class _Episode:
    target: Target
    day: int
    obs: Observation
    road: str
    pos: float
    motion: Motion
    done: bool = False


class ChargingNavEnv(InWorld, gymnasium.Env):
    """Navigate one EV to one of the scenario's charging stations (Gymnasium environment).

    Args:
        scenario: scenario folder (network, ``stations.add.xml``, ``vtypes.add.xml``); default the
            committed Jurong West one. Any folder of that shape works.
        evs: background EVs in the day (default: :class:`DemandConfig`'s).
        decision_interval: seconds per slot (one decision each).
        departure_window: ``(start, end)`` s of day in which the target departs (uniformly, on a
            step boundary).
        max_travel_time: seconds after departure at which the episode is truncated.
        reward: ``"paper"`` (``7200 / T_travel`` at charge start), ``"time"`` (minus hours per
            slot) or a callable taking a :class:`~evcd.env.reward.Slot`.
        normalize_obs: scale ``D`` to km, ``N`` to tens, ``Z`` to multiples of the points.
        protocol: ``"fast"`` (snapshots, stop at charge start) or ``"paper"`` (every episode a
            fresh simulation from 00:00, run on to ``day_end`` = 23:59 after the episode).
        charging_points: overrides every station's number of charging points.
        demand: a :class:`DemandConfig` or a dict of overrides of its defaults.
        demand_seeds: seeds of the background days an episode may run in, one drawn per episode.
            Default ``(0,)``: one day, so every episode shares its background traffic and only the
            target (departure, origin) varies; give more seeds for more varied traffic (each day is
            simulated once into the snapshot cache).
        route_file: a SUMO route file to use as the (only) background day instead of generated
            demand (then leave ``demand``, ``evs`` and ``demand_seeds`` unset).
        cache_dir: snapshot cache root (default ``$EVCD_CACHE`` or ``~/.cache/evcd``).
        snapshot_every: seconds between day snapshots.
        step_length: SUMO step (s).
        time_to_teleport: SUMO's jam teleport threshold (s).
        stuck_limit: seconds without moving (outside a car park) after which the episode is
            truncated as ``"stuck"``.
        day_end: where the paper protocol's simulation stops (s of day).
        max_insert_delay: seconds the target may wait for insertion before another origin is drawn.
        gui: watch the episodes in ``sumo-gui`` (through TraCI, slow); day snapshots are still built
            headless with libsumo.
        perturbations: a day that is not calm (:mod:`evcd.sim.perturbations`: e.g.
            ``{"outages": {"per_day": 2}}``, charger outages drawn from each day's seed); ``None``
            (default): every day calm, as before.
        observe: observation options, blocks after ``[D, N, Z]`` (:mod:`evcd.env.observation`):
            ``"points_in_service"`` (``P``: each station's points in service now) and
            ``"route_time"`` (``T``: the route's current travel time, s) and ``"forecast"`` (``F``: the
            vehicles forecast at each station at the target's arrival); default none. The
            observation's layout is :attr:`layout` (e.g. ``"DNZP"``).
        forecaster: what ``F`` comes from (:mod:`evcd.forecast`): ``"history"`` (per station and time
            of day, the mean of ``forecast_days``), ``"trend"`` (a line through the current day's last
            15 min), ``"anomaly"`` (the history plus today's deviation from it now, fading with the
            horizon), ``"sessions"`` (the queue now, less the charging sessions likely to end by the
            arrival, plus the arrivals expected by then) or ``"oracle"`` (the day's own future:
            analysis only), or a mapping with ``name`` and its settings (``bin_s``, ``window_s``,
            ``sample_s``, ``max_lag_s``, ``history_weight``, ``statistic``).
        forecast_days: the demand seeds of the days the history, anomaly and sessions forecasters learn from
            (the scripts give them their training days); those forecasters refuse to run without them.

    Every invalid argument raises ``ValueError`` naming it before SUMO starts. The seed is given
    through ``reset(seed=...)``: one generator drives the day, the departure, the origin and the
    battery. ``reset(options=...)`` may fix ``departure``, ``origin``, ``depart_pos`` or ``day``
    (an index into ``demand_seeds``). libsumo runs one simulation per process: use one env per
    process (see :func:`evcd.env.make_vector_env`) and :meth:`close` it.
    """

    metadata = {"render_modes": []}  # noqa: RUF012  (gymnasium's convention)

    def __init__(
        self,
        scenario: str | Path = JURONG_WEST,
        evs: int | None = None,
        decision_interval: float = 60.0,
        departure_window: tuple[float, float] = (0.0, float(DAY)),
        max_travel_time: float = 7200.0,
        reward: str | Callable[[Slot], float] = "paper",
        normalize_obs: bool = False,
        protocol: str = "fast",
        *,
        charging_points: int | None = None,
        demand: DemandConfig | Mapping[str, Any] | None = None,
        demand_seeds: Sequence[int] = (0,),
        route_file: str | Path | None = None,
        cache_dir: str | Path | None = None,
        snapshot_every: float = 300.0,
        step_length: float = 1.0,
        time_to_teleport: float = 300.0,
        stuck_limit: float = 600.0,
        day_end: float = PAPER_DAY_END,
        max_insert_delay: float = 600.0,
        gui: bool = False,
        perturbations: Perturbations | Mapping[str, Any] | None = None,
        observe: Sequence[str] = (),
        forecaster: str | Mapping[str, Any] = "history",
        forecast_days: Sequence[int] | None = None,
    ) -> None:
        self.world = World(EnvConfig(
            scenario=scenario, evs=evs, decision_interval=decision_interval,
            departure_window=departure_window, max_travel_time=max_travel_time, reward=reward,
            normalize_obs=normalize_obs, protocol=protocol, charging_points=charging_points,
            demand=demand, demand_seeds=demand_seeds, route_file=route_file, cache_dir=cache_dir,
            snapshot_every=snapshot_every, step_length=step_length, time_to_teleport=time_to_teleport,
            stuck_limit=stuck_limit, day_end=day_end, max_insert_delay=max_insert_delay, gui=gui,
            perturbations=perturbations, observe=observe, forecaster=forecaster, forecast_days=forecast_days,
        ))  # fmt: skip
        m = len(self.stations)
        self.action_space = gymnasium.spaces.Discrete(m)
        #: the observation's blocks, one letter each (:func:`evcd.env.observation.check_layout`)
        self.layout = layout_of("DNZ", self.config.observe)
        low, high = observation_bounds(self.stations, self.config.normalize_obs, self.layout)
        self.observation_space = gymnasium.spaces.Box(low, high, dtype=np.float32)
        self._episode: _Episode | None = None
        self._episodes = 0

    # ------------------------------------------------------------------ lazily built helpers
    @cached_property
    def origins(self) -> OriginSampler:
        """Where targets may depart."""
        return OriginSampler(self.scenario.net, self.graph, self.stations)

    @property
    def last_observation(self) -> Observation | None:
        """The latest observation with its raw parts (``D`` in m, routes); ``None`` before reset."""
        return None if self._episode is None else self._episode.obs

    def prepare(self, workers: int | None = None) -> None:
        """Build (or verify) every background day's snapshots now instead of at first use, the days
        not cached side by side (``workers`` processes at a time; default: this process's cores)."""
        self.world.prepare(workers)

    def draw_episode(
        self, rng: np.random.Generator, options: Mapping[str, Any] | None = None
    ) -> tuple[int, TargetPlan]:
        """The background day (an index into ``demand_seeds``) and the target's plan of an episode,
        drawn from ``rng`` exactly as :meth:`reset` draws them from the generator of its seed, with
        :meth:`reset`'s ``options`` applied (the batched engine, :mod:`evcd.env.runners.batched`, calls
        this too).

        Raises:
            ValueError: an unknown or invalid option.
        """
        options = dict(options or {})
        unknown = sorted(set(options) - _OPTIONS)
        if unknown:
            raise ValueError(f"reset options {unknown} unknown; known: {sorted(_OPTIONS)}")
        cfg = self.config
        day = int(rng.integers(len(self.days)))
        plan = draw_plan(rng, self.origins, cfg.departure_window, cfg.step_length, cfg.demand_config)
        return self._override(day, plan, options)

    # ------------------------------------------------------------------ gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode: draw the target, position the simulation, wait for its insertion."""
        super().reset(seed=seed)
        rng = self.np_random
        day, plan = self.draw_episode(rng, options)
        self._episode = None
        for attempt in range(2):
            try:
                self.simulation.start_at(day, plan.departure)
                target = self._insert(plan, rng)
                road, pos, odo = Target.location(self.simulation.api)
                break
            except SUMO_ERRORS as exc:  # a simulation broken by an earlier error: start afresh
                if attempt:
                    raise
                log.warning("SUMO error while starting an episode (%s); restarting SUMO", exc)
                self.simulation.close()
        obs = self._observe(road, pos)
        now = self.simulation.time
        self._episode = _Episode(target, day, obs, road, pos, Motion(odo, now))
        info = {
            "time": now,
            "departure": target.plan.departure,
            "origin": target.plan.origin,
            "day": self._day_seed(day),
        }
        return obs.vector.copy(), info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Drive to station ``action`` for one slot (or until the target starts charging)."""
        index = check_action(action, len(self.stations))
        ep = self._episode
        if ep is None or ep.done:
            raise RuntimeError("the episode is over (or never began): call reset()")
        sim = self.simulation
        t0 = sim.time
        error = ""
        try:
            if index != ep.target.station:
                station = self.stations[index]
                route = ep.obs.routes[index]
                ep.target.drive_to(
                    sim.api, sim.controller, index, station, route, self.observer, ep.road, ep.pos, t0
                )
            reason = self._advance(ep)
        except SUMO_ERRORS as exc:
            reason, error = "sumo_error", str(exc)
            log.warning("SUMO error in an episode (t=%s): %s; truncating it", t0, exc)
        now = sim.time if sim.running else t0
        departure = ep.target.plan.departure
        started = reason == "charging"
        record = sim.controller.current(TARGET_ID) if reason != "sumo_error" else None
        travel = (record.start_time - departure) if started and record is not None else None
        if reason in (None, "charging", "stuck", "max_travel_time"):  # the target's position is known
            ep.obs = self._observe(ep.road, ep.pos)
        done = reason is not None
        slot = Slot(now - t0, now - departure, started, done and not started, travel)
        reward = float(self.world.reward(slot))
        info: dict[str, Any] = {"time": now, "station": ep.target.station}
        if done:
            ep.done = True
            info.update(self._final_info(ep, reason, now, travel, error))
            if self.config.protocol == "paper" and reason != "sumo_error":
                sim.finish_day()
        return ep.obs.vector.copy(), reward, started, done and not started, info

    def close(self) -> None:
        """Close the SUMO simulation (idempotent)."""
        self.simulation.close()
        self._episode = None

    # ------------------------------------------------------------------ episode mechanics
    def _insert(self, plan: TargetPlan, rng: np.random.Generator) -> Target:
        """Add the target and step until SUMO inserts it; redraw the origin if it cannot be."""
        sim = self.simulation
        for _ in range(MAX_INSERT_TRIES):
            self._episodes += 1
            target = Target(plan, route_id=f"evcd_target_route{self._episodes}")
            target.add(sim.api, sim.controller)
            deadline = plan.departure + self.config.max_insert_delay
            departed = sim.api.simulation.getDepartedIDList
            while sim.driver.step() < deadline:
                if TARGET_ID in departed():
                    return target
            if TARGET_ID in departed():
                return target
            log.warning(
                "target not inserted on %s within %.0f s; drawing another origin",
                plan.origin,
                self.config.max_insert_delay,
            )
            sim.api.vehicle.remove(TARGET_ID)
            plan = another_origin(plan, self.origins, rng, sim.time)
        raise RuntimeError(f"the target could not be inserted after {MAX_INSERT_TRIES} origins")

    def _advance(self, ep: _Episode) -> str | None:
        """Simulate one slot; return why the episode ends, or ``None``."""
        sim = self.simulation
        cfg = self.config
        driver, api, ctrl = sim.driver, sim.api, sim.controller
        departure = ep.target.plan.departure
        now = driver.time
        end = slot_deadline(now, departure, cfg.decision_interval, cfg.max_travel_time)
        teleports = api.simulation.getStartingTeleportNumber
        while now < end - TIME_EPS:
            now = driver.step()
            if ctrl.status(TARGET_ID) == "charging":
                break
            if teleports() and TARGET_ID in api.simulation.getStartingTeleportIDList():
                return "teleported"
        try:
            ep.road, ep.pos, odo = Target.location(api)
        except SUMO_ERRORS:
            return "vanished"
        status = ctrl.status(TARGET_ID)
        if status == "charging":
            return "charging"
        ep.motion.update(now, odo, parked=status is not None)
        return slot_end_reason(ep.motion, now, departure, cfg.stuck_limit, cfg.max_travel_time)

    def _observe(self, road: str, pos: float) -> Observation:
        ctrl = self.simulation.controller
        record = ctrl.current(TARGET_ID)
        at = None if record is None else self._station_index[record.station]
        return self.observer.observe(self.simulation.api, ctrl, road, pos, at)

    def _final_info(
        self, ep: _Episode, reason: str, now: float, travel: float | None, error: str
    ) -> dict[str, Any]:
        records = self.simulation.controller.records if reason != "sumo_error" else []
        plan = ep.target.plan
        return final_info(
            reason=reason, now=now, departure=plan.departure, origin=plan.origin, travel=travel,
            visits=visits_of(records, TARGET_ID, now),
            day=self._day_seed(ep.day), switches=ep.target.switches, station=ep.target.station,
            stations=self.stations, error=error,
        )  # fmt: skip

    # ------------------------------------------------------------------ checks
    @cached_property
    def _station_index(self) -> dict[str, int]:
        return {st.id: i for i, st in enumerate(self.stations)}

    def _override(self, day: int, plan: TargetPlan, options: dict[str, Any]) -> tuple[int, TargetPlan]:
        cfg = self.config
        if "day" in options:
            day = int(options["day"])
            if not 0 <= day < len(self.days):
                raise ValueError(f"options day={day}: must index demand_seeds (0..{len(self.days) - 1})")
        if "departure" in options:
            t = float(options["departure"])
            if not 0 <= t < DAY or abs(t / cfg.step_length - round(t / cfg.step_length)) > 1e-9:
                raise ValueError(f"options departure={t}: must be a step boundary within the day")
            if cfg.protocol == "fast" and not cfg.departure_window[0] <= t < cfg.departure_window[1]:
                raise ValueError(f"options departure={t}: outside departure_window={cfg.departure_window}")
            plan = replace(plan, departure=t)
        if "origin" in options:
            origin = str(options["origin"])
            if origin not in self.graph:
                raise ValueError(f"options origin={origin!r}: not a drivable edge of the network")
            length = float(self.graph.lengths[self.graph.index[origin]])
            plan = replace(plan, origin=origin, depart_pos=round(length / 2, 2))
        if "depart_pos" in options:
            plan = replace(plan, depart_pos=float(options["depart_pos"]))
        return day, plan

    def _day_seed(self, day: int) -> int:
        return self.days[day].demand_seed
