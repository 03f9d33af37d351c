"""The simulation loop of the batched engine: one SUMO run of one background day carrying a batch of
targets (:class:`BatchSimulation`; the planning of batches is :mod:`evcd.env.runners.batched`).

After every SUMO step, in this order: targets SUMO inserted start driving (a first one is due to
decide), targets that parked at their station start waiting beside the queue
(:class:`~evcd.env.runners.ghost.GhostWait`), waiting targets whose turn came start charging,
teleported ones end, and every target whose decision slot is over is checked against the episode's
rules (:mod:`evcd.env.episode_rules`); then the transitions of the step reach ``agent.observe`` in
the order of the specs, and the targets due decide together in one ``agent.decide`` call.

An episode ends in one of two ways: :meth:`BatchSimulation._finish`, by the rules, with a final
observation (charging, stuck, time cap); or :meth:`BatchSimulation._abort`, where the target can no
longer be observed (it vanished or teleported, could not be inserted, or SUMO failed): its last slot
reaches no learner (:data:`~evcd.env.episode_rules.UNOBSERVED`). Either way a learner then hears of
the episode's end (``agent.end_episode``).
"""

from __future__ import annotations

import contextlib
import logging
from collections import Counter
from collections.abc import Callable, Sequence

import numpy as np

from evcd.env.charging_nav import ChargingNavEnv
from evcd.env.episode_rules import (
    MAX_INSERT_TRIES,
    TIME_EPS,
    Motion,
    another_origin,
    final_info,
    slot_deadline,
    slot_end_reason,
)
from evcd.env.observation import Observation
from evcd.env.reward import RewardFn, Slot
from evcd.env.runners.base import EpisodeRow, Policy, row_from_info
from evcd.env.runners.ghost import GhostWait
from evcd.env.runners.live import TARGET_VTYPE, LiveTarget, OpenSlot, Phase, TargetIds
from evcd.env.target import Target
from evcd.env.transition import Transition
from evcd.scenario.vtypes import EV_TYPE
from evcd.sim.driver import SUMO_ERRORS

log = logging.getLogger(__name__)

Finished = Callable[[LiveTarget, EpisodeRow], None]


class BatchSimulation:
    """One simulation of one day carrying a batch of targets, played to its last episode's end.

    Args:
        env: the environment whose scenario, settings and SUMO simulation are used.
        batch: the batch's targets (one background day).
        agent: the dispatcher.
        explore: let the agent explore.
        learn: hand the agent every transition.
        reward: the reward of a slot.
        ids: the runner's source of SUMO ids.
        finished: called with each episode's row as it ends, in the order of the specs per step.
        day: the background day (index; default the batch's); a batch that starts empty and gets
            its targets as it goes (:mod:`evcd.env.sweep`) names it.
    """

    def __init__(
        self,
        env: ChargingNavEnv,
        batch: Sequence[LiveTarget],
        agent: Policy,
        *,
        explore: bool,
        learn: bool,
        reward: RewardFn,
        ids: TargetIds,
        finished: Finished,
        day: int | None = None,
    ) -> None:
        self.env = env
        self.cfg = env.config
        self.sim = env.simulation
        self.station_index = {st.id: i for i, st in enumerate(env.stations)}
        self.pending = sorted(batch, key=lambda live: (live.plan.departure, live.order))
        self.live: list[LiveTarget] = []
        self.agent = agent
        self.explore = explore
        self.learn = learn
        self.reward = reward
        self.ids = ids
        self.finished = finished
        self.day = batch[0].day if day is None else day
        self.sumo_errors = 0
        self._roads: dict[str, str] | None = None  # road of each target on an edge this step
        self._events: list[tuple[LiveTarget, Transition | None, EpisodeRow | None]] = []

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
                while self.pending and self.pending[0].plan.departure <= now + TIME_EPS:
                    self._add(self.pending.pop(0), now)
                now = self.sim.driver.step()
                self._after_step(now)
                failures = 0
            except SUMO_ERRORS as exc:  # the simulation is broken: truncate what is in flight
                failures += 1
                self.sumo_errors += 1
                now = self.sim.time if self.sim.running else 0.0
                log.warning("SUMO error in a batch (t=%s): %s; truncating its %d episodes in flight",
                            now, exc, len(self.live))  # fmt: skip
                self._fail(self.live, now, str(exc))
                self.sim.close()

    def _fail(self, lives: Sequence[LiveTarget], now: float, error: str) -> None:
        """Truncate ``lives`` with ``sumo_error`` (their simulation is gone)."""
        for live in sorted(lives, key=lambda x: x.order):
            live.in_sim = False
            start = live.slot.start if live.slot is not None else 0.0
            self._abort(live, "sumo_error", max(now, start, live.plan.departure), error)
        self._deliver()
        self.live = [x for x in self.live if not x.done]

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
        if departure <= now + TIME_EPS:
            return
        if self.cfg.protocol == "fast":
            snap = self.sim.caches[self.day].latest_before(departure)
            if snap.time > now + TIME_EPS:
                self._start(departure)
                return
        self.sim.driver.step(until=departure)

    def _add(self, live: LiveTarget, now: float) -> None:
        live.target.add(self.sim.api, self.sim.controller)
        live.in_sim = True
        live.deadline = now + self.cfg.max_insert_delay
        live.phase = Phase.INSERTING
        self.live.append(live)
        self.live.sort(key=lambda x: x.order)

    # ------------------------------------------------------------------ after every step
    def _after_step(self, now: float) -> None:
        api, ctrl = self.sim.api, self.sim.controller
        self._roads = None
        due: list[LiveTarget] = []
        sim = api.simulation
        entering = (Phase.INSERTING, Phase.REENTERING)
        if any(x.phase in entering for x in self.live):
            departed = set(sim.getDepartedIDList())
            for live in [x for x in self.live if x.phase in entering]:
                if live.vid in departed:
                    self._entered(live, now, due)
                elif live.phase is Phase.INSERTING and now >= live.deadline - TIME_EPS:
                    self._redraw(live, now)
        parked = list(sim.getParkingStartingVehiclesIDList())
        if parked:
            by_vid = {x.vid: x for x in self.live if x.phase is Phase.DRIVING}
            for k, vid in enumerate(parked):
                if vid in by_vid:
                    self._arrive(by_vid[vid], now, parked[k + 1 :])
        for live in [x for x in self.live if x.phase is Phase.WAITING]:
            if live.wait is not None and live.wait.started(ctrl):
                self._finish(live, "charging", now)
        if sim.getStartingTeleportNumber():
            teleported = set(sim.getStartingTeleportIDList())
            for live in [x for x in self.live if x.phase is Phase.DRIVING and x.vid in teleported]:
                self._abort(live, "teleported", now)
        for live in [x for x in self.live if not x.done and x.slot is not None]:
            if now >= live.slot.end - TIME_EPS:  # type: ignore[union-attr]
                self._slot_end(live, now, due)
        self._deliver()
        if due:
            self._decide([x for x in due if not x.done], now)
        self._remove_finished()

    def _entered(self, live: LiveTarget, now: float, due: list[LiveTarget]) -> None:
        """SUMO inserted the target (first departure, or back on the road after a queue)."""
        first = live.phase is Phase.INSERTING
        live.phase = Phase.DRIVING
        try:
            live.road, live.pos, odo = Target.location(self.sim.api, live.vid)
        except SUMO_ERRORS:
            self._abort(live, "vanished", now)
            return
        live.motion = Motion(odo, now)
        if first:
            live.obs = self._observe(live)
            due.append(live)

    def _redraw(self, live: LiveTarget, now: float) -> None:
        """Not inserted within ``max_insert_delay``: another origin, departing now (the episode's rule)."""
        api = self.sim.api
        log.warning("target %s not inserted on %s within %.0f s; drawing another origin",
                    live.vid, live.plan.origin, self.cfg.max_insert_delay)  # fmt: skip
        api.vehicle.remove(live.vid)
        if live.tries >= MAX_INSERT_TRIES:
            live.in_sim = False
            self._abort(live, "not_inserted", now)
            return
        plan = another_origin(live.plan, self.env.origins, live.rng, now)
        live.target = Target(plan, self.ids.route(), self.ids.vehicle(), TARGET_VTYPE, battery=False)
        live.tries += 1
        live.target.add(api, self.sim.controller)
        live.deadline = now + self.cfg.max_insert_delay

    def _arrive(self, live: LiveTarget, now: float, behind: Sequence[str]) -> None:
        """The target parked at its station: it waits beside the queue, out of the simulation."""
        api = self.sim.api
        station = self.env.stations[int(live.target.station)]  # type: ignore[arg-type]
        live.road = api.vehicle.getRoadID(live.vid)
        live.pos = api.vehicle.getLanePosition(live.vid)
        live.lane = int(api.parkingarea.getLaneID(station.parking_area).rsplit("_", 1)[1])  # the lot's
        live.wait = GhostWait.arrive(self.sim.controller, station.id, station.points, now, behind)
        live.visits.append([now, None])
        live.phase = Phase.WAITING
        api.vehicle.remove(live.vid)
        live.in_sim = False

    def _slot_end(self, live: LiveTarget, now: float, due: list[LiveTarget]) -> None:
        """The decision slot is over: check the episode's rules, then observe."""
        if live.phase is Phase.DRIVING:
            try:
                live.road, live.pos, odo = Target.location(self.sim.api, live.vid)
            except SUMO_ERRORS:
                live.in_sim = False
                self._abort(live, "vanished", now)
                return
            live.motion.update(now, odo, parked=False)
        else:  # waiting at a station (or leaving its car park): not stuck
            live.motion.update(now, None, parked=True)
        cfg = self.cfg
        reason = slot_end_reason(live.motion, now, live.plan.departure, cfg.stuck_limit, cfg.max_travel_time)
        if reason is not None:
            self._finish(live, reason, now)
        else:
            live.obs = self._observe(live)
            self._events.append((live, self._transition(live, now, started=False, done=False), None))
            due.append(live)

    # ------------------------------------------------------------------ observations
    def _observe(self, live: LiveTarget) -> Observation:
        """The target's observation; ``N`` does not count the other targets (the observer discounts
        the target itself), ``Z`` of its station counts it while it waits there."""
        at = None if live.wait is None else self.station_index[live.wait.station]
        others = Counter(road for vid, road in self._target_roads().items() if vid != live.vid)
        return self.env.observer.observe(self.sim.api, self.sim.controller, live.road, live.pos, at,
                                         others=others, queued_at=at)  # fmt: skip

    def _target_roads(self) -> dict[str, str]:
        """The edge of every target on an edge in this step."""
        if self._roads is None:
            get = self.sim.api.vehicle.getRoadID
            self._roads = {}
            for x in self.live:
                if x.phase is Phase.DRIVING or x.on_road:
                    with contextlib.suppress(*SUMO_ERRORS):  # gone: its slot end finds it vanished
                        self._roads[x.vid] = get(x.vid)
        return self._roads

    # ------------------------------------------------------------------ ends and transitions
    def _finish(self, live: LiveTarget, reason: str, now: float) -> None:
        """End the episode by the rules (charging, stuck, time cap): it sees its last observation."""
        self._end(live, reason, now, observe=True, on_road=live.phase is Phase.DRIVING)

    def _abort(
        self, live: LiveTarget, reason: str, now: float, error: str = "", on_road: bool = False
    ) -> None:
        """End the episode of a target that can no longer be observed (vanished, teleported, not
        inserted, SUMO error): its last slot has no true next observation, so the agent gets no
        transition for it, only the episode's end. ``on_road``: its vehicle still stands on an edge
        in this step (the other targets' ``N`` discounts it)."""
        self._end(live, reason, now, observe=False, on_road=on_road, error=error)

    def _end(self, live: LiveTarget, reason: str, now: float, *, observe: bool, on_road: bool,
             error: str = "") -> None:  # fmt: skip
        """Queue the episode's last transition and its row for :meth:`_deliver`."""
        started = reason == "charging"
        live.on_road = on_road
        live.phase = Phase.DONE
        if observe and live.obs is not None:
            live.obs = self._observe(live)
        visits = live.close_visits(now)
        travel = now - live.plan.departure if started else None
        transition = self._transition(live, now, started=started, done=True, travel=travel)
        if not observe:  # no true next observation: the slot is not learnt from (UNOBSERVED)
            transition = None
        target = live.target
        info = final_info(
            reason=reason, now=now, departure=live.plan.departure, origin=live.plan.origin,
            travel=travel, visits=visits,
            day=self.env.days[live.day].demand_seed, switches=target.switches, station=target.station,
            stations=self.env.stations, error=error,
        )  # fmt: skip
        row = row_from_info(live.spec, info, live.choices, live.total, not started, 0.0)
        self._events.append((live, transition, row))

    def _transition(
        self, live: LiveTarget, now: float, *, started: bool, done: bool, travel: float | None = None
    ) -> Transition | None:
        """The slot's transition (``None`` before the first decision); adds its reward."""
        slot = live.slot
        if slot is None or live.obs is None:
            return None
        truncated = done and not started
        reward = float(self.reward(Slot(now - slot.start, now - live.plan.departure, started, truncated,
                                        travel)))  # fmt: skip
        live.total += reward
        return Transition(slot.obs, slot.action, reward, live.obs.vector.copy(), started, truncated)

    def _deliver(self) -> None:
        """Hand this step's transitions to the agent and the ended episodes' rows to the caller, in
        the order of the specs."""
        events = sorted(self._events, key=lambda e: e[0].order)
        self._events = []
        for live, transition, row in events:
            if self.learn and transition is not None:
                self.agent.observe(transition, live.agent_state)
            if self.learn and row is not None and live.agent_state is not None:
                self.agent.end_episode(live.agent_state)
        for live, _, row in events:
            if row is not None:
                self.finished(live, row)

    def _remove_finished(self) -> None:
        api = self.sim.api
        for live in [x for x in self.live if x.done]:
            if live.in_sim:
                try:
                    api.vehicle.remove(live.vid)
                except SUMO_ERRORS as exc:
                    log.debug("removing %s: %s", live.vid, exc)
                live.in_sim = False
        self.live = [x for x in self.live if not x.done]

    # ------------------------------------------------------------------ decisions
    def _decide(self, due: list[LiveTarget], now: float) -> None:
        """One batched decision for every target due now, applied in the order of the specs."""
        for live in due:
            if live.agent_state is None:
                live.agent_state = self.agent.new_episode(live.spec.agent_rng())
        obs = np.stack([live.obs.vector for live in due])  # type: ignore[union-attr]
        actions = self.agent.decide(obs, [live.agent_state for live in due], self.explore)
        m = len(self.env.stations)
        for live, action in zip(due, actions, strict=True):
            if not 0 <= int(action) < m:
                raise ValueError(f"action={action!r}: must be a station index in [0, {m})")
            self._apply(live, int(action), now)
        self._deliver()

    def _apply(self, live: LiveTarget, index: int, now: float) -> None:
        """Drive the target to station ``index`` for one slot."""
        cfg = self.cfg
        live.choices.append(index)
        end = slot_deadline(now, live.plan.departure, cfg.decision_interval, cfg.max_travel_time)
        live.slot = OpenSlot(now, end, live.obs.vector.copy(), index)  # type: ignore[union-attr]
        if index == live.target.station:
            return
        try:
            if live.phase is Phase.DRIVING:
                live.target.drive_to(self.sim.api, self.sim.controller, index, self.env.stations[index],
                                     live.obs.routes[index], self.env.observer, live.road, live.pos,
                                     now)  # type: ignore[union-attr]  # fmt: skip
            else:
                self._leave(live, index, now)
        except SUMO_ERRORS as exc:
            log.warning("SUMO error for target %s (t=%s): %s; truncating its episode", live.vid, now, exc)
            self._abort(live, "sumo_error", now, str(exc), on_road=live.phase is Phase.DRIVING)

    def _leave(self, live: LiveTarget, index: int, now: float) -> None:
        """Leave the station's queue (or the car park being left) for station ``index``: the
        target re-enters the road at its car park as a new vehicle."""
        api = self.sim.api
        if live.in_sim:  # still leaving the last car park: start over with the new route
            api.vehicle.remove(live.vid)
            live.in_sim = False
        if live.wait is not None:
            live.visits[-1][1] = now
            live.wait = None
        route = live.obs.routes[index] if live.obs is not None else ()
        live.in_sim = True  # from here on its (new) vehicle is removed when the episode ends
        at, ids = (live.road, live.pos, live.lane), (self.ids.vehicle(), self.ids.route())
        live.target.reenter(api, index, self.env.stations[index], route, self.env.observer, at, now, ids)
        live.phase = Phase.REENTERING
