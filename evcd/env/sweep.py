"""A Gymnasium vector environment on the batched engine: ``num_envs`` targets co-simulated in one SUMO
run of their day, on one decision clock.

    envs = SweepVectorEnv(ChargingNavEnv(evs=400, departure_window=(25200, 36000), reward="time"), 16)
    obs, infos = envs.reset(seed=0)                      # (16, 3m): one target per sub-environment
    obs, rewards, terminated, truncated, infos = envs.step(actions)

The single environment simulates the whole city for one target; the batched engine
(:mod:`evcd.env.runners.batched`) simulates it once for many, which is what makes evcd fast. A
:class:`gymnasium.vector.VectorEnv` steps every sub-environment at every call, while the engine's
targets decide at their own seconds, and a simulation only goes forward in time. So this vector
environment puts every target on **one decision clock**, as the fleet does (and sumo-rl's one
``delta_time``):

- **A sweep** is the departure window of one background day in one SUMO run, started from the day's
  snapshot at the window's start. Ticks fall every ``decision_interval`` from the window's start.
- **A sub-environment is a slot** that always holds one target. At every tick every slot's target
  decides (one vector step = one decision of every target); between ticks SUMO runs
  ``decision_interval`` seconds with everything the engine does (arrivals, the target's place in a
  station's queue beside the background's FIFO (:class:`~evcd.env.runners.ghost.GhostWait`: targets
  never see each other at stations, only on the road), teleports, the episode's rules).
- **Episodes start on the clock.** A slot whose episode ended gets a new target that departs one
  SUMO step before the next tick (so it is on the road and observed at the tick) from an origin
  drawn as the environment draws one, with a drawn battery: departures follow the sweep, not a
  uniform draw over the window. Autoreset is Gymnasium's ``SAME_STEP`` (SB3's convention too): the
  step in which an episode ends returns the new episode's first observation, the last one in
  ``infos["final_obs"]`` (and ``final_info``).
- **At the window's end** every running episode is truncated (``reason`` ``window_end``, its slot
  rewarded as any truncated slot) and the next sweep starts on another day (drawn among the
  environment's ``demand_seeds`` by the reset seed's generator).
- **Late insertion** (SUMO could not insert a target at once; 2 of about 1,100 targets in the README
  job's world): until the next tick it heads for the nearest station by road (its one-edge route
  would otherwise end and take it out of the simulation), then it is observed again and decides
  there; the seconds before are in no slot's reward, and its step showed a zero observation whose
  action was ignored.

What differs from the single environment on the same episodes (same day, departure, origin) is
measured by :func:`evcd.bench.vector.sweep_equivalence`: the other targets on the road, and the
truncations at the window's end. One seed gives the same sweeps, episodes and rewards.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import logging
from typing import Any

import gymnasium
import numpy as np
from gymnasium.vector.utils import batch_space
from gymnasium.vector.vector_env import AutoresetMode

from evcd.env.charging_nav import ChargingNavEnv
from evcd.env.episode_rules import TIME_EPS
from evcd.env.runners.base import EpisodeRow, EpisodeSpec
from evcd.env.runners.batch import BatchSimulation
from evcd.env.runners.live import TARGET_VTYPE, LiveTarget, Phase, TargetIds
from evcd.env.target import Target, TargetPlan, draw_plan
from evcd.env.transition import Transition
from evcd.sim.driver import SUMO_ERRORS
from evcd.utils.validation import check_int

log = logging.getLogger(__name__)

#: ``reason`` of an episode cut by the end of its sweep.
WINDOW_END = "window_end"


@dataclasses.dataclass(frozen=True)
class SweepEpisode:
    """A finished episode of a sweep: its row, its day (index into ``demand_seeds``) and its target's
    plan (departure, origin, position), so that the single environment can replay it
    (``reset(options={"day": day, "departure": ..., "origin": ..., "depart_pos": ...})``)."""

    row: EpisodeRow
    day: int
    plan: TargetPlan

    def replay_options(self) -> dict[str, Any]:
        """The single environment's ``reset`` options that play this episode's day and target."""
        p = self.plan
        return {"day": self.day, "departure": p.departure, "origin": p.origin, "depart_pos": p.depart_pos}


class _Slots:
    """What :class:`BatchSimulation` hands an agent, kept per slot instead (the vector env answers
    the decisions itself)."""

    def __init__(self) -> None:
        self.transitions: dict[int, Transition] = {}

    def observe(self, transition: Transition, slot: int | None = None) -> None:
        self.transitions[int(slot)] = transition  # type: ignore[arg-type]

    def end_episode(self, slot: int | None = None) -> None:
        pass


class _Sweep(BatchSimulation):
    """One sweep's simulation, stepped tick by tick by :class:`SweepVectorEnv`."""

    def __init__(self, env: ChargingNavEnv, day: int, slots: _Slots, ids: TargetIds) -> None:
        self.rows: dict[int, tuple[EpisodeRow, LiveTarget]] = {}
        super().__init__(env, [], slots, explore=False, learn=True, reward=env.world.reward,  # type: ignore[arg-type]
                         ids=ids, finished=self._finished, day=day)  # fmt: skip
        self.due: dict[int, LiveTarget] = {}  # the targets to decide at the next vector step, by slot
        self.due_at: dict[int, float] = {}  # when each was observed
        self.between_ticks = False  # simulating an interval (not a step in which targets depart)

    def _finished(self, live: LiveTarget, row: EpisodeRow) -> None:
        self.rows[int(live.agent_state)] = (row, live)

    def _decide(self, due: list[LiveTarget], now: float) -> None:
        """Keep the targets due: the vector env decides them at the tick. A target SUMO inserted
        between ticks (late) heads for the nearest station by road until then, so that it does not
        reach the end of its one-edge route and leave the simulation."""
        for live in due:
            self.due[int(live.agent_state)] = live
            self.due_at[int(live.agent_state)] = now
            if self.between_ticks and live.slot is None and live.obs is not None:
                self._head_for_nearest(live, now)
        self._deliver()

    def _head_for_nearest(self, live: LiveTarget, now: float) -> None:
        m = len(self.env.stations)
        index = int(np.argmin(live.obs.vector[:m]))  # type: ignore[union-attr]
        try:
            live.target.drive_to(self.sim.api, self.sim.controller, index, self.env.stations[index],
                                 live.obs.routes[index], self.env.observer, live.road, live.pos,
                                 now)  # type: ignore[union-attr]  # fmt: skip
        except SUMO_ERRORS as exc:
            self._abort(live, "sumo_error", now, str(exc), on_road=True)

    def depart(self, live: LiveTarget) -> None:
        """``live`` departs at its plan's departure (the sweep adds it when the time comes)."""
        self.pending.append(live)
        self.pending.sort(key=lambda x: (x.plan.departure, x.order))

    def run_to(self, tick: float) -> None:
        """Simulate up to ``tick`` (s of day), adding targets at their departures."""
        while self.sim.time < tick - TIME_EPS:
            now = self.sim.time
            while self.pending and self.pending[0].plan.departure <= now + TIME_EPS:
                self._add(self.pending.pop(0), now)
            now = self.sim.driver.step()
            self._after_step(now)

    def cut(self, now: float) -> None:
        """End every running episode (the sweep is over): truncated, with its last observation."""
        for live in sorted(self.live, key=lambda x: x.order):
            if not live.done:
                if live.phase is Phase.INSERTING:
                    live.in_sim = False
                    self._abort(live, WINDOW_END, now)
                else:
                    self._finish(live, WINDOW_END, now)
        self._deliver()
        self._remove_finished()


class SweepVectorEnv(gymnasium.vector.VectorEnv):
    """``num_envs`` targets of one :class:`~evcd.env.ChargingNavEnv`'s world on one decision clock, in
    one SUMO run per sweep (module docstring).

    Args:
        env: the world (scenario, days, window, reward, observation units, rules); its own episode
            API is not used, and closing the vector env closes it.
        num_envs: targets at once (>= 1).
        keep_episodes: how many of the latest finished episodes :attr:`episodes` keeps (their rows
            and plans: what a replay in the single environment needs).

    Raises:
        ValueError: ``num_envs`` < 1, or the ``paper`` protocol (a sweep starts from a snapshot).
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP}  # noqa: RUF012  (gymnasium's convention)

    def __init__(self, env: ChargingNavEnv, num_envs: int, keep_episodes: int = 10_000) -> None:
        self.num_envs = check_int("num_envs", num_envs, minimum=1)
        check_int("keep_episodes", keep_episodes, minimum=0)
        if not isinstance(env.unwrapped, ChargingNavEnv):
            raise ValueError(f"a sweep needs a ChargingNavEnv, not {type(env.unwrapped).__name__}")
        self.env = env.unwrapped
        if self.env.config.protocol != "fast":
            raise ValueError("protocol='paper': a sweep starts from the day's snapshot (protocol 'fast')")
        self.single_observation_space = self.env.observation_space
        self.single_action_space = self.env.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.ids = TargetIds()
        self._rng = np.random.default_rng()
        self._sweep: _Sweep | None = None
        self._slots = _Slots()
        self._order = 0
        self.sweeps = 0  # SUMO runs (for the benchmark)
        #: the latest ``keep_episodes`` finished episodes, in the order they ended
        self.episodes: collections.deque[SweepEpisode] = collections.deque(maxlen=keep_episodes)

    # ------------------------------------------------------------------ the API
    def reset(
        self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start a sweep on a day drawn from ``seed``'s generator; every slot's target departs now."""
        if isinstance(seed, list | tuple):
            seed = seed[0]
        if seed is not None or self._sweep is None:
            self._rng = np.random.default_rng(seed)
        if self._sweep is not None:
            self.env.simulation.close()
        self._start_sweep()
        return self._observations(), {}

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Every slot's target drives to its station for one interval; episodes that end are
        replaced at once (``SAME_STEP``); at the window's end the sweep starts anew on another day.

        Raises:
            ValueError: actions of another shape, or one that is not a station index (naming the
                sub-environment); nothing is applied then.
        """
        sweep = self._sweep
        if sweep is None:
            raise RuntimeError("call reset() first")
        chosen = self._check(actions)
        cfg = self.env.config
        now = sweep.sim.time
        for slot, live in sorted(sweep.due.items()):
            if not live.done:
                sweep._apply(live, chosen[slot], now)
        sweep.due, sweep.due_at = {}, {}
        sweep._deliver()
        tick = now + cfg.decision_interval
        over = tick >= cfg.departure_window[1] - TIME_EPS
        sweep.between_ticks = True
        over = not self._run(sweep, tick) or over
        sweep.between_ticks = False
        if over:
            sweep.cut(sweep.sim.time if sweep.sim.running else tick)
        rewards, terminated, truncated, infos = self._collect(sweep)
        if over:
            self._start_sweep()
        else:
            ended = np.flatnonzero(terminated | truncated)
            for slot in ended:  # the next target of the slot departs now, observed one step later
                self._new_target(int(slot), sweep.sim.time)
            if len(ended) and not self._run(sweep, sweep.sim.time + cfg.step_length):
                # SUMO failed while the new targets entered: the episodes it cut end in this step too
                _, more_terminated, more_truncated, more = self._collect(sweep)
                terminated, truncated = terminated | more_terminated, truncated | more_truncated
                infos = _merge_final(infos, more)
                self._start_sweep()
        return self._observations(), rewards, terminated, truncated, infos

    def _check(self, actions: Any) -> list[int]:
        m = int(self.single_action_space.n)
        values = np.asarray(actions)
        if values.shape != (self.num_envs,):
            raise ValueError(f"actions of shape {values.shape}: need ({self.num_envs},), one station index "
                             "per sub-environment")  # fmt: skip
        out = []
        for i, a in enumerate(values.tolist()):
            if isinstance(a, bool) or not float(a).is_integer() or not 0 <= int(a) < m:
                raise ValueError(f"actions[{i}]={a!r}: must be a station index in [0, {m}) "
                                 f"(sub-environment {i})")  # fmt: skip
            out.append(int(a))
        return out

    def _run(self, sweep: _Sweep, until: float) -> bool:
        """Simulate to ``until``; ``False`` if SUMO failed (the running episodes are truncated)."""
        try:
            sweep.run_to(until)
            return True
        except SUMO_ERRORS as exc:
            log.warning("SUMO error in a sweep (t=%s): %s; truncating its %d episodes in flight",
                        sweep.sim.time if sweep.sim.running else until, exc, len(sweep.live))  # fmt: skip
            sweep._fail(sweep.live, until, str(exc))
            sweep.sim.close()
            return False

    def _collect(self, sweep: _Sweep) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """The rewards of the slots that ended and the episodes that ended since the last step."""
        n = self.num_envs
        rewards = np.zeros(n, np.float64)
        terminated, truncated = np.zeros(n, bool), np.zeros(n, bool)
        final_obs = np.zeros((n, *self.single_observation_space.shape), np.float32)
        reasons = np.full(n, None, dtype=object)
        travel = np.full(n, np.nan)
        for slot, transition in self._slots.transitions.items():
            rewards[slot] = transition.reward
            if transition.terminated or transition.truncated:
                final_obs[slot] = transition.next_obs
        self._slots.transitions = {}
        for slot, (row, live) in sweep.rows.items():
            terminated[slot], truncated[slot] = not row.truncated, row.truncated
            reasons[slot], travel[slot] = row.reason, row.travel_time
            self.episodes.append(SweepEpisode(row, live.day, live.plan))
        sweep.rows = {}
        ended = terminated | truncated
        if not ended.any():
            return rewards, terminated, truncated, {}
        final_info = {"reason": reasons, "_reason": ended, "travel_time": travel, "_travel_time": ended}
        infos = {"final_obs": final_obs, "_final_obs": ended, "final_info": final_info, "_final_info": ended}
        return rewards, terminated, truncated, infos

    def close_extras(self, **kwargs: Any) -> None:
        """Close the simulation."""
        self.env.close()

    # ------------------------------------------------------------------ sweeps and slots
    def _start_sweep(self) -> None:
        """A new sweep on a day drawn from the generator: SUMO from the window's start snapshot, every
        slot's target departing then (observed one step later)."""
        cfg = self.env.config
        for attempt in range(2):
            day = int(self._rng.integers(len(self.env.days)))
            self._sweep = sweep = _Sweep(self.env, day, self._slots, self.ids)
            self._slots.transitions = {}
            start = cfg.departure_window[0]
            try:
                sweep._start(start)
            except SUMO_ERRORS as exc:
                log.warning("SUMO could not start a sweep on day %d (%s)%s", day, exc,
                            "; trying another" if attempt == 0 else "")  # fmt: skip
                continue
            self.sweeps += 1
            for slot in range(self.num_envs):
                self._new_target(slot, start)
            if self._run(sweep, start + cfg.step_length):
                sweep.rows = {}
                return
        raise RuntimeError("SUMO failed to start two sweeps in a row")

    def _new_target(self, slot: int, departure: float) -> None:
        """Slot ``slot``'s next target, departing at ``departure`` (now) from a drawn origin."""
        cfg = self.env.config
        sweep = self._sweep
        assert sweep is not None
        window, battery = cfg.departure_window, cfg.demand_config
        plan = draw_plan(self._rng, self.env.origins, window, cfg.step_length, battery)
        plan = dataclasses.replace(plan, departure=float(departure))
        target = Target(plan, self.ids.route(), self.ids.vehicle(), TARGET_VTYPE, battery=False)
        spec = EpisodeSpec(self._order, 0, np.random.SeedSequence(0))
        sweep.depart(LiveTarget(self._order, spec, self._rng, sweep.day, target, agent_state=slot))
        self._order += 1

    def _observations(self) -> np.ndarray:
        """Every slot's observation now: a target due earlier (inserted late) is observed again; a
        slot whose target SUMO has not inserted yet shows zeros (its action is ignored)."""
        sweep = self._sweep
        assert sweep is not None
        now = sweep.sim.time
        obs = np.zeros((self.num_envs, *self.single_observation_space.shape), np.float32)
        for slot, live in sweep.due.items():
            if live.done:
                continue
            if sweep.due_at[slot] < now - TIME_EPS and live.phase is Phase.DRIVING:
                with contextlib.suppress(*SUMO_ERRORS):
                    live.road, live.pos, _ = Target.location(sweep.sim.api, live.vid)
                live.obs = sweep._observe(live)
                sweep.due_at[slot] = now
            obs[slot] = live.obs.vector  # type: ignore[union-attr]
        return obs


def _merge_final(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    """The final-step infos of two collections of ended episodes (disjoint slots)."""
    if not a or not b:
        return a or b
    mask = b["_final_obs"]
    a["final_obs"][mask] = b["final_obs"][mask]
    a["_final_obs"] = a["_final_info"] = a["_final_obs"] | mask
    for key in ("reason", "travel_time"):
        a["final_info"][key][mask] = b["final_info"][key][mask]
        a["final_info"][f"_{key}"] = a["_final_obs"]
    return a
