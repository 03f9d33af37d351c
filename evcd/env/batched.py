"""Many episodes in one SUMO run: targets co-simulated in their background day (``engine=batched``).

    runner = BatchedRunner(ChargingNavEnv(evs=400, departure_window=(25200, 36000)), batch_episodes=25)
    rows = runner.run(specs, agent, explore=True, learn=True)

What an episode costs is the city around its target, and the city is the same for every target of
a day: :class:`BatchedRunner` simulates it once for many. It plays the episodes named by
:class:`~evcd.env.runner.EpisodeSpec`\\ s, like :class:`~evcd.env.runner.SingleEnvRunner`, with the
semantics of :class:`~evcd.env.ChargingNavEnv`:

- **Plans.** Each episode's background day and target (departure, origin, battery) come from
  :meth:`ChargingNavEnv.draw_episode` with the generator ``env.reset(seed=s)`` would use: the same
  code, so ``engine=single`` and ``engine=batched`` play the same episodes.
- **Batches.** Episodes are grouped by background day, sorted by departure and cut into batches of
  ``batch_episodes``. A batch is one simulation from the latest snapshot before its first departure;
  each target enters at its own departure (its own vehicle, redrawn origin if it cannot be
  inserted, as the environment does), is asked for a station at each of its own decision slots, and
  ends by the environment's rules: charge start, or a truncation (``teleported``, ``vanished``,
  ``stuck``, ``max_travel_time``, ``sumo_error``; ``not_inserted`` where the environment would
  raise). While no target is in flight the simulation jumps ahead by loading a later snapshot.
- **Targets never see each other at stations.** A target waits beside the queue as a
  :class:`~evcd.env.ghost.GhostWait` (it leaves the simulation on arriving, so waiting targets never
  fill a car park), starts charging exactly when the FIFO would give it a point were it the only
  target, and may still leave to drive elsewhere (it re-enters the road at the car park). ``N`` and
  ``Z`` count background vehicles only (``Z`` of its own station counts the waiting target itself,
  as the environment's queue does). On the road the targets are ordinary vehicles.
- **Decisions and transitions.** All targets due at the same second are decided in one
  :meth:`~evcd.agents.base.Agent.act_episodes` call (one forward pass for a network agent), each
  with its own episode state (generator, exploration draw). At each second, the transitions that
  ended are handed to ``observe`` first, in the order of the specs, then the due targets decide:
  the same specs, agent state and batch size give the same rows and the same learning.
- **Errors.** A SUMO error in a target's command truncates that episode (``sumo_error``); one that
  breaks the simulation truncates the batch's episodes in flight, and the run goes on from a fresh
  start.

In the ``paper`` protocol a batch simulates its day from 00:00 (no snapshots) and does not run on to
the end of the day (nothing after the last charge start changes a result).
"""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import logging
import math
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gymnasium.utils import seeding

from evcd.env.charging_nav import ChargingNavEnv
from evcd.env.ghost import GhostWait
from evcd.env.observation import Observation
from evcd.env.reward import Slot, reward_fn
from evcd.env.runner import (
    EpisodeCallback,
    EpisodeRow,
    EpisodeRunner,
    EpisodeSpec,
    Policy,
    SingleEnvRunner,
    Transition,
    row_from_info,
)
from evcd.env.target import Target, TargetPlan
from evcd.scenario.vtypes import EV_TYPE
from evcd.sim.driver import SUMO_ERRORS

log = logging.getLogger(__name__)

#: SUMO vehicle type of the co-simulated targets: ``ev`` without a battery device, so the charging
#: controller never queues them (the engine queues them itself, :mod:`evcd.env.ghost`).
TARGET_VTYPE = "evcd_target_ev"
#: Default number of targets per simulation. Measured (README, the batched engine): the travel
#: times drift from the single environment's as batches grow (25: greedy within 1.4 %; 100: 3 %;
#: 400 targets to one station jam it), while the cost per episode is nearly flat from 25 to 400
#: when a call brings hundreds of episodes (batches are consecutive slices of the departure window).
DEFAULT_BATCH_EPISODES = 25
#: The runners ``engine=`` names.
ENGINES = ("batched", "single")
_MOVED_M = 1.0  # as in ChargingNavEnv
_MAX_INSERT_TRIES = 5
_EPS = 1e-9

# A target's phases.
_INSERTING = "inserting"  # added, waiting for SUMO to insert it
_DRIVING = "driving"
_WAITING = "waiting"  # at its station, beside the queue (not in the simulation)
_REENTERING = "reentering"  # left a queue: added again at the car park, not inserted yet
_DONE = "done"


@dataclass
class _Live:
    """One target of a batch."""

    order: int  # position in the specs: ties are broken by it
    spec: EpisodeSpec
    rng: np.random.Generator
    day: int
    target: Target
    phase: str = _INSERTING
    deadline: float = math.inf  # insertion deadline
    tries: int = 1
    obs: Observation | None = None
    road: str = ""
    pos: float = 0.0
    lane: int = 0
    odo_mark: float = 0.0
    t_mark: float = 0.0
    slot_start: float = 0.0
    slot_end: float = math.inf
    prev: np.ndarray | None = None  # observation vector at the slot's start
    action: int | None = None
    choices: list[int] = field(default_factory=list)
    total: float = 0.0
    wait: GhostWait | None = None
    visits: list[list[float | None]] = field(default_factory=list)  # [arrival, end] per station visit
    agent_state: Any = None
    begun: bool = False
    in_sim: bool = False  # its vehicle is in the simulation (removed at the end of the step it ends in)
    on_road: bool = False  # ended this step while on an edge (still counted there until removed)

    @property
    def plan(self) -> TargetPlan:
        return self.target.plan

    @property
    def vid(self) -> str:
        return self.target.vehicle_id


class BatchedRunner(EpisodeRunner):
    """Plays episodes many at a time, co-simulated in their background day (module docstring).

    Args:
        env: the environment whose scenario, days, settings and SUMO simulation are used (its
            episode API is not); the runner closes it in :meth:`close`.
        batch_episodes: targets per simulation (>= 1).
    """

    def __init__(self, env: ChargingNavEnv, batch_episodes: int = DEFAULT_BATCH_EPISODES) -> None:
        _, batch_episodes = check_engine("batched", batch_episodes)
        if not isinstance(env.unwrapped, ChargingNavEnv):
            raise ValueError(f"the batched engine needs a ChargingNavEnv, not {type(env.unwrapped).__name__}")
        self.env = env.unwrapped
        self.batch_episodes = int(batch_episodes)
        self._reward = reward_fn(self.env.config.reward)
        self._serial = itertools.count()
        self.station_index = {st.id: i for i, st in enumerate(self.env.stations)}
        self.batches = 0  # simulations run (for the benchmark)
        self.sumo_errors = 0

    @property
    def n_stations(self) -> int:
        """Number of stations (actions)."""
        return len(self.env.stations)

    def prepare(self) -> None:
        """Build (or verify) the days' snapshots."""
        self.env.prepare()

    def close(self) -> None:
        """Close the simulation."""
        self.env.close()

    # ------------------------------------------------------------------ planning
    def plan(self, specs: Sequence[EpisodeSpec]) -> list[tuple[int, TargetPlan]]:
        """Each spec's background day (index) and target plan, as ``env.reset`` would draw them."""
        return [self._draw(spec)[1:] for spec in specs]  # type: ignore[misc]

    def _draw(self, spec: EpisodeSpec) -> tuple[np.random.Generator, int, TargetPlan]:
        rng, _ = seeding.np_random(spec.reset_seed)
        day, plan = self.env.draw_episode(rng, spec.options)
        return rng, day, plan

    def batches_of(self, specs: Sequence[EpisodeSpec]) -> list[list[int]]:
        """The positions in ``specs`` of each batch: by day, then departure, ``batch_episodes`` each."""
        return self._batches(self.plan(specs))

    def _batches(self, plans: Sequence[tuple[int, TargetPlan]]) -> list[list[int]]:
        order = sorted(range(len(plans)), key=lambda i: (plans[i][0], plans[i][1].departure, i))
        out: list[list[int]] = []
        for _, group in itertools.groupby(order, key=lambda i: plans[i][0]):
            members = list(group)
            out += [members[k : k + self.batch_episodes] for k in range(0, len(members), self.batch_episodes)]
        return out

    # ------------------------------------------------------------------ running
    def run(
        self,
        specs: Sequence[EpisodeSpec],
        agent: Policy,
        *,
        explore: bool = False,
        learn: bool = False,
        on_episode: EpisodeCallback | None = None,
    ) -> list[EpisodeRow]:
        """Play ``specs`` (see :meth:`EpisodeRunner.run`); ``on_episode`` gets each row as its
        episode ends (in the order they end); the rows come back in the order of the specs."""
        for method in ("episode_state", "set_episode_state", "act_episodes"):
            if not callable(getattr(agent, method, None)):
                raise TypeError(f"the batched engine needs agent.{method}() (evcd.agents.Agent has it)")
        rows: list[EpisodeRow | None] = [None] * len(specs)
        clock = [time.perf_counter()]

        def finished(live: _Live, row: EpisodeRow) -> None:
            now = time.perf_counter()
            row = dataclasses.replace(row, wall_s=now - clock[0])
            clock[0] = now
            rows[live.order] = row
            if on_episode is not None:
                on_episode(row)

        draws = [self._draw(spec) for spec in specs]  # each plan once; its rng redraws origins
        for members in self._batches([(day, plan) for _, day, plan in draws]):
            batch = []
            for i in members:
                rng, day, plan = draws[i]
                target = Target(plan, self._route_id(), self._vehicle_id(), TARGET_VTYPE, battery=False)
                batch.append(_Live(i, specs[i], rng, day, target))
            _Batch(self, batch, agent, explore, learn, finished).run()
            self.batches += 1
        assert all(r is not None for r in rows)
        return rows  # type: ignore[return-value]

    def _route_id(self) -> str:
        return f"evcd_batch_route{next(self._serial)}"

    def _vehicle_id(self) -> str:
        return f"evcd_batch_target{next(self._serial)}"


class _Batch:
    """One simulation of one day carrying a batch of targets."""

    def __init__(
        self,
        runner: BatchedRunner,
        batch: list[_Live],
        agent: Policy,
        explore: bool,
        learn: bool,
        finished: Any,
    ) -> None:
        self.runner = runner
        self.env = runner.env
        self.cfg = runner.env.config
        self.sim = runner.env.simulation
        self.pending = sorted(batch, key=lambda live: (live.plan.departure, live.order))
        self.live: list[_Live] = []
        self.agent = agent
        self.explore = explore
        self.learn = learn
        self.finished = finished
        self.day = batch[0].day
        self._roads: dict[str, str] | None = None  # road of each target on an edge this step
        self._events: list[tuple[_Live, Transition | None, EpisodeRow | None]] = []

    # ------------------------------------------------------------------ the loop
    def run(self) -> None:
        """Play the batch to its last episode's end."""
        failures = 0
        started = False
        while self.pending or self.live:
            if failures >= 2:  # SUMO cannot even start this day: give the rest up
                self._abandon("SUMO failed twice in a row without progress")
                return
            try:
                if not started or not self.sim.running:  # a batch starts from its own snapshot
                    self._start(self.pending[0].plan.departure)
                    started = True
                elif not self.live:
                    self._skip_to(self.pending[0].plan.departure)
                now = self.sim.time
                while self.pending and self.pending[0].plan.departure <= now + _EPS:
                    self._add(self.pending.pop(0), now)
                now = self.sim.driver.step()
                self._after_step(now)
                failures = 0
            except SUMO_ERRORS as exc:  # the simulation is broken: truncate what is in flight
                failures += 1
                self.runner.sumo_errors += 1
                now = self.sim.time if self.sim.running else 0.0
                log.warning("SUMO error in a batch (t=%s): %s; truncating its %d episodes in flight",
                            now, exc, len(self.live))  # fmt: skip
                self._fail(self.live, now, str(exc))
                self.sim.close()

    def _fail(self, lives: Sequence[_Live], now: float, error: str) -> None:
        """Truncate ``lives`` with ``sumo_error`` (their simulation is gone)."""
        for live in sorted(lives, key=lambda x: x.order):
            live.in_sim = False
            self._end(live, "sumo_error", max(now, live.slot_start, live.plan.departure), error=error,
                      observe=False, on_road=False)  # fmt: skip
        self._deliver()
        self.live = [x for x in self.live if x.phase != _DONE]

    def _abandon(self, error: str) -> None:
        log.error("%s: truncating the batch's %d remaining episodes", error, len(self.pending))
        rest, self.pending = self.pending, []
        self._fail(rest, 0.0, error)

    def _start(self, time_: float) -> None:
        self.sim.start_at(self.day, time_)
        api = self.sim.api
        if TARGET_VTYPE not in api.vehicletype.getIDList():  # a loaded state may lack it: add it
            api.vehicletype.copy(EV_TYPE, TARGET_VTYPE)
            api.vehicletype.setParameter(TARGET_VTYPE, "has.battery.device", "false")

    def _skip_to(self, departure: float) -> None:
        """Nothing in flight: jump to a later snapshot if one lies before ``departure``."""
        now = self.sim.time
        if departure <= now + _EPS:
            return
        if self.cfg.protocol == "fast":
            snap = self.sim.caches[self.day].latest_before(departure)
            if snap.time > now + _EPS:
                self._start(departure)
                return
        self.sim.driver.step(until=departure)

    def _add(self, live: _Live, now: float) -> None:
        live.target.add(self.sim.api, self.sim.controller)
        live.in_sim = True
        live.deadline = now + self.cfg.max_insert_delay
        live.phase = _INSERTING
        self.live.append(live)
        self.live.sort(key=lambda x: x.order)

    # ------------------------------------------------------------------ after every step
    def _after_step(self, now: float) -> None:
        api, ctrl = self.sim.api, self.sim.controller
        self._roads = None
        due: list[_Live] = []
        sim = api.simulation
        if any(x.phase in (_INSERTING, _REENTERING) for x in self.live):
            departed = set(sim.getDepartedIDList())
            for live in [x for x in self.live if x.phase in (_INSERTING, _REENTERING)]:
                if live.vid in departed:
                    self._entered(live, now, due)
                elif live.phase == _INSERTING and now >= live.deadline - _EPS:
                    self._redraw(live, now)
        parked = list(sim.getParkingStartingVehiclesIDList())
        if parked:
            by_vid = {x.vid: x for x in self.live if x.phase == _DRIVING}
            for k, vid in enumerate(parked):
                if vid in by_vid:
                    self._arrive(by_vid[vid], now, parked[k + 1 :])
        for live in [x for x in self.live if x.phase == _WAITING]:
            if live.wait is not None and live.wait.started(ctrl):
                self._end(live, "charging", now)
        if sim.getStartingTeleportNumber():
            teleported = set(sim.getStartingTeleportIDList())
            for live in [x for x in self.live if x.phase == _DRIVING and x.vid in teleported]:
                self._end(live, "teleported", now, observe=False, on_road=False)
        for live in [x for x in self.live if x.phase != _DONE and x.action is not None]:
            if now >= live.slot_end - _EPS:
                self._slot_end(live, now, due)
        self._deliver()
        if due:
            self._decide([x for x in due if x.phase != _DONE], now)
        self._remove_finished()

    def _entered(self, live: _Live, now: float, due: list[_Live]) -> None:
        """SUMO inserted the target (first departure, or back on the road after a queue)."""
        first = live.phase == _INSERTING
        live.phase = _DRIVING
        try:
            live.road, live.pos, odo = Target.location(self.sim.api, live.vid)
        except SUMO_ERRORS:
            self._end(live, "vanished", now, observe=False, on_road=False)
            return
        live.odo_mark, live.t_mark = odo, now
        if first:
            live.obs = self._observe(live)
            due.append(live)

    def _redraw(self, live: _Live, now: float) -> None:
        """Not inserted within ``max_insert_delay``: another origin, departing now (as the env)."""
        api = self.sim.api
        log.warning("target %s not inserted on %s within %.0f s; drawing another origin",
                    live.vid, live.plan.origin, self.cfg.max_insert_delay)  # fmt: skip
        api.vehicle.remove(live.vid)
        if live.tries >= _MAX_INSERT_TRIES:
            live.in_sim = False
            self._end(live, "not_inserted", now, observe=False, on_road=False)
            return
        origin, pos = self.env.origins.draw(live.rng)
        plan = dataclasses.replace(live.plan, departure=now, origin=origin, depart_pos=pos)
        live.target = Target(plan, self.runner._route_id(), self.runner._vehicle_id(), TARGET_VTYPE,
                             battery=False)  # fmt: skip
        live.tries += 1
        live.target.add(api, self.sim.controller)
        live.deadline = now + self.cfg.max_insert_delay

    def _arrive(self, live: _Live, now: float, behind: Sequence[str]) -> None:
        """The target parked at its station: it waits beside the queue, out of the simulation."""
        api = self.sim.api
        station = self.env.stations[int(live.target.station)]  # type: ignore[arg-type]
        live.road = api.vehicle.getRoadID(live.vid)
        live.pos = api.vehicle.getLanePosition(live.vid)
        live.lane = int(api.parkingarea.getLaneID(station.parking_area).rsplit("_", 1)[1])  # the lot's
        live.wait = GhostWait.arrive(self.sim.controller, station.id, station.points, now, behind)
        live.visits.append([now, None])
        live.phase = _WAITING
        api.vehicle.remove(live.vid)
        live.in_sim = False

    def _slot_end(self, live: _Live, now: float, due: list[_Live]) -> None:
        """The decision slot is over: check the environment's end rules, then observe."""
        if live.phase == _DRIVING:
            try:
                live.road, live.pos, odo = Target.location(self.sim.api, live.vid)
            except SUMO_ERRORS:
                live.in_sim = False
                self._end(live, "vanished", now, observe=False, on_road=False)
                return
            if odo - live.odo_mark >= _MOVED_M:
                live.odo_mark, live.t_mark = odo, now
        else:  # waiting at a station (or leaving its car park): not stuck
            live.t_mark = now
        if now - live.t_mark >= self.cfg.stuck_limit:
            self._end(live, "stuck", now)
        elif now - live.plan.departure >= self.cfg.max_travel_time - _EPS:
            self._end(live, "max_travel_time", now)
        else:
            live.obs = self._observe(live)
            self._events.append((live, self._transition(live, now, started=False, done=False), None))
            due.append(live)

    # ------------------------------------------------------------------ observations
    def _observe(self, live: _Live) -> Observation:
        """The target's observation; ``N`` does not count the other targets (the observer discounts
        the target itself), ``Z`` of its station counts it while it waits there."""
        at = None if live.wait is None else self.runner.station_index[live.wait.station]
        others = Counter(road for vid, road in self._target_roads().items() if vid != live.vid)
        return self.env.observer.observe(self.sim.api, self.sim.controller, live.road, live.pos, at,
                                         others=others, queued_at=at)  # fmt: skip

    def _target_roads(self) -> dict[str, str]:
        """The edge of every target on an edge in this step."""
        if self._roads is None:
            get = self.sim.api.vehicle.getRoadID
            self._roads = {}
            for x in self.live:
                if x.phase == _DRIVING or x.on_road:
                    with contextlib.suppress(*SUMO_ERRORS):  # gone: its slot end finds it vanished
                        self._roads[x.vid] = get(x.vid)
        return self._roads

    # ------------------------------------------------------------------ ends and transitions
    def _end(
        self,
        live: _Live,
        reason: str,
        now: float,
        *,
        error: str = "",
        observe: bool = True,
        on_road: bool | None = None,
    ) -> None:
        """End the episode; queue its transition and row for :meth:`_deliver`."""
        started = reason == "charging"
        live.on_road = live.phase == _DRIVING if on_road is None else on_road
        live.phase = _DONE
        if observe and live.obs is not None:
            live.obs = self._observe(live)
        for visit in live.visits:
            if visit[1] is None:
                visit[1] = now
        travel = now - live.plan.departure if started else None
        transition = self._transition(live, now, started=started, done=True, travel=travel)
        waits = [float(end) - float(arr) for arr, end in live.visits]  # type: ignore[arg-type]
        info: dict[str, Any] = {
            "reason": reason,
            "charged": started,
            "travel_time": travel if travel is not None else now - live.plan.departure,
            "queue_wait": float(sum(waits)),
            "arrival": live.visits[-1][0] if live.visits else None,
            "departure": live.plan.departure,
            "origin": live.plan.origin,
            "day": self.env.days[live.day].demand_seed,
            "switches": live.target.switches,
            "station": live.target.station,
        }
        if live.target.station is not None:
            info["station_id"] = self.env.stations[live.target.station].id
        if error:
            info["error"] = error
        row = row_from_info(live.spec, info, live.choices, live.total, not started, 0.0)
        self._events.append((live, transition, row))

    def _transition(
        self, live: _Live, now: float, *, started: bool, done: bool, travel: float | None = None
    ) -> Transition | None:
        """The slot's transition (``None`` before the first decision); adds its reward."""
        if live.action is None or live.prev is None or live.obs is None:
            return None
        slot = Slot(now - live.slot_start, now - live.plan.departure, started, done and not started, travel)
        reward = float(self.runner._reward(slot))
        live.total += reward
        return Transition(live.prev, live.action, reward, live.obs.vector.copy(), started,
                          done and not started)  # fmt: skip

    def _deliver(self) -> None:
        """Hand this step's transitions to the agent and the ended episodes' rows to the caller, in
        the order of the specs."""
        events = sorted(self._events, key=lambda e: e[0].order)
        self._events = []
        for _, transition, _ in events:
            if self.learn and transition is not None:
                self.agent.observe(transition)
        for live, _, row in events:
            if row is not None:
                self.finished(live, row)

    def _remove_finished(self) -> None:
        api = self.sim.api
        for live in [x for x in self.live if x.phase == _DONE]:
            if live.in_sim:
                try:
                    api.vehicle.remove(live.vid)
                except SUMO_ERRORS as exc:
                    log.debug("removing %s: %s", live.vid, exc)
                live.in_sim = False
        self.live = [x for x in self.live if x.phase != _DONE]

    # ------------------------------------------------------------------ decisions
    def _decide(self, due: list[_Live], now: float) -> None:
        """One batched decision for every target due now, applied in the order of the specs."""
        agent = self.agent
        for live in due:
            if not live.begun:
                agent.begin_episode(live.spec.agent_rng())
                live.agent_state, live.begun = agent.episode_state(), True
        obs = np.stack([live.obs.vector for live in due])  # type: ignore[union-attr]
        actions, states = agent.act_episodes(obs, [live.agent_state for live in due], self.explore)
        for live, action, state in zip(due, actions, states, strict=True):
            live.agent_state = state
            m = len(self.env.stations)
            if not 0 <= int(action) < m:
                raise ValueError(f"action={action!r}: must be a station index in [0, {m})")
            self._apply(live, int(action), now)
        self._deliver()

    def _apply(self, live: _Live, index: int, now: float) -> None:
        """Drive the target to station ``index`` for one slot."""
        live.choices.append(index)
        live.prev = live.obs.vector.copy()  # type: ignore[union-attr]
        live.action = index
        live.slot_start = now
        live.slot_end = min(now + self.cfg.decision_interval, live.plan.departure + self.cfg.max_travel_time)
        if index == live.target.station:
            return
        try:
            if live.phase == _DRIVING:
                live.target.drive_to(self.sim.api, self.sim.controller, index, self.env.stations[index],
                                     live.obs.routes[index], self.env.observer, live.road, live.pos,
                                     now)  # type: ignore[union-attr]  # fmt: skip
            else:
                self._leave(live, index, now)
        except SUMO_ERRORS as exc:
            log.warning("SUMO error for target %s (t=%s): %s; truncating its episode", live.vid, now, exc)
            self._end(live, "sumo_error", now, error=str(exc), observe=False)

    def _leave(self, live: _Live, index: int, now: float) -> None:
        """Leave the station's queue (or the car park being left) for station ``index``: the
        target re-enters the road at its car park."""
        api = self.sim.api
        if live.in_sim:  # still leaving the last car park: start over with the new route
            api.vehicle.remove(live.vid)
            live.in_sim = False
        if live.wait is not None:
            live.visits[-1][1] = now
            live.wait = None
        target = live.target
        target.switches += 1
        target.station = index
        target.vehicle_id = self.runner._vehicle_id()
        target.route_id = self.runner._route_id()
        station = self.env.stations[index]
        route = live.obs.routes[index] if live.obs is not None else ()  # type: ignore[union-attr]
        api.route.add(target.route_id, list(route) or [live.road])
        api.vehicle.add(target.vehicle_id, target.route_id, typeID=TARGET_VTYPE, depart="now",
                        departLane=str(live.lane), departPos=f"{live.pos:.2f}", departSpeed="0")  # fmt: skip
        live.in_sim = True
        if not route:
            api.vehicle.changeTarget(target.vehicle_id, station.edge)
        target.stop_at(api, station, self.env.observer, live.road, live.pos, now)
        live.phase = _REENTERING


def check_engine(engine: Any, batch_episodes: Any) -> tuple[str, int]:
    """``(engine, batch_episodes)`` checked without starting anything.

    Raises:
        ValueError: an unknown engine or a batch size that is not an integer >= 1.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine={engine!r}: must be one of {', '.join(ENGINES)}")
    is_int = isinstance(batch_episodes, int | np.integer) and not isinstance(batch_episodes, bool)
    if not is_int or batch_episodes < 1:
        raise ValueError(f"batch_episodes={batch_episodes!r}: must be an integer >= 1")
    return str(engine), int(batch_episodes)


def make_runner(env: ChargingNavEnv, engine: str = "batched", batch_episodes: int = DEFAULT_BATCH_EPISODES
                ) -> EpisodeRunner:  # fmt: skip
    """The runner ``engine`` names over ``env``: ``"batched"`` (:class:`BatchedRunner`) or
    ``"single"`` (:class:`~evcd.env.runner.SingleEnvRunner`, one episode after another).

    Raises:
        ValueError: an unknown engine or a bad ``batch_episodes``.
    """
    engine, batch_episodes = check_engine(engine, batch_episodes)
    return SingleEnvRunner(env) if engine == "single" else BatchedRunner(env, batch_episodes)
