"""The fleet: the navigation centre guides many EVs of one background day at once (PettingZoo).

    from evcd.env.fleet import parallel_env
    env = parallel_env(evs=400, guided_share=0.5)            # the committed Jurong West scenario
    observations, infos = env.reset(seed=0)
    while env.agents:
        actions = {agent: env.action_space(agent).sample() for agent in env.agents}
        observations, rewards, terminations, truncations, infos = env.step(actions)

An episode is the departure window of a background day (default the morning peak, 07:00-10:00),
started from the day's cached snapshot at the window's start. The guided EVs are a share
``guided_share`` of the day's own charging EVs that depart in the window (drawn per episode,
:mod:`evcd.env.fleet.trips`); the others drive to the station nearest their origin as in every day.
Guided EVs are real SUMO vehicles: they queue at the FIFO points behind everybody already there,
each other included.

One clock: every ``decision_interval`` seconds from the window's start (a *tick*) every guided EV
still on its way observes and picks a station (it may switch). An EV becomes an agent at the first
tick after SUMO inserted it (until then it drives towards its trip's own station) and leaves at the
tick after it started charging (terminated) or was truncated by the single environment's rules
(:mod:`evcd.env.episode_rules`: teleported, vanished, stuck, ``max_travel_time``, a SUMO error;
judged at ticks). An EV that started charging before its first tick is never an agent, and one SUMO
could not insert within ``max_insert_delay`` is dropped (``not_inserted``); both still count in
:meth:`FleetEnv.outcomes`. The episode ends when every guided EV is done.

Observation per agent: its ``[D, N, Z]`` (:mod:`evcd.env.observation`; ``N`` counts the other guided
EVs too, they are traffic) and ``H``: per station, the *other* guided EVs currently sent there and
still driving (not yet in its car park; the waiting ones are in ``Z``). With ``normalize_obs``, ``H``
is in multiples of the station's points, like ``Z``. The observation options (``observe=``: ``P``,
``T``, ``F``) follow ``H`` as in the single environment, each agent's ``F`` at its own arrival, and
the fleet's own ``G`` (``guided_ahead``) comes last: per station, the other guided EVs driving there
that are due before this one (their route time to the station they are sent to shorter than this
one's ``T`` there; :func:`~evcd.env.fleet.events.guided_ahead`), the part of ``H`` ahead of it. The
``history`` forecaster learns the training days' queues, where the charging EVs drive to their own
stations (nobody dispatches them), and ``oracle`` is refused (the guided EVs change the cached day's
future). Reward per agent and slot: the single environment's (``"time"`` by default: minus the slot's
hours, so that an agent's rewards sum to minus its travel time: an agent's first slot runs from its
departure; the step in which it appears gives it 0).

Version history (``metadata["name"]``, PettingZoo's versioned name):

- ``evcd_fleet_v1`` (2026-11-29): the dynamics of ``evcd_fleet_v0``'s last state (commit a3e96b2),
  under a name that ties a result to them from now on (every ``results.json`` records it with evcd's
  version and commit); ``env()`` (PettingZoo's AEC factory) beside ``parallel_env()``.
- ``evcd_fleet_v0`` (2026-11-24 to 2026-11-29): the name through changes of behaviour (among them an
  EV sent elsewhere while crossing a junction losing its new stop, fixed in 0756257); a result
  labelled ``v0`` is tied to its commit, not to the name.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from gymnasium.utils import seeding
from pettingzoo import AECEnv, ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec

from evcd import FLEET_ENV_ID
from evcd.env.config import EnvConfig
from evcd.env.episode_rules import TIME_EPS, Motion, check_action, slot_end_reason
from evcd.env.fleet.events import advance, heading
from evcd.env.fleet.guided import GuidedEV, Stage
from evcd.env.fleet.measures import FleetMeasures, measure
from evcd.env.fleet.observe import TickObserver
from evcd.env.fleet.trips import ChargingTrip, draw_guided, in_window, read_charging_trips
from evcd.env.observation import layout_of, observation_bounds
from evcd.env.reward import Slot
from evcd.env.target import Target
from evcd.env.world import InWorld, World
from evcd.scenario.demand import ev_id
from evcd.scenario.scenario import JURONG_WEST
from evcd.sim.charge_record import ChargeRecord
from evcd.sim.driver import SUMO_ERRORS
from evcd.utils.validation import check_real

log = logging.getLogger(__name__)

#: The morning peak (s of day): the fleet's default departure window.
MORNING_PEAK = (25_200.0, 36_000.0)
#: The world's settings a fleet takes as keywords besides its own (:class:`~evcd.env.config.EnvConfig`).
WORLD_OPTIONS = tuple(f.name for f in dataclasses.fields(EnvConfig)
                      if f.init and f.name not in ("scenario", "departure_window", "reward"))  # fmt: skip
_OPTIONS = {"day"}


class FleetEnv(InWorld, ParallelEnv):
    """Guide a share of a background day's charging EVs at once (PettingZoo ``ParallelEnv``).

    Args:
        scenario: scenario folder (default the committed Jurong West one).
        guided_share: share of the window's charging EVs the centre guides, in (0, 1].
        departure_window: ``(start, end)`` s of day: the guided EVs depart in it (default the
            morning peak).
        reward: ``"time"`` (minus hours per slot; the default), ``"paper"`` (``7200 / T_travel`` at
            charge start) or a callable taking a :class:`~evcd.env.reward.Slot`.
        world: the rest of the world's description, the keyword arguments of
            :class:`~evcd.env.ChargingNavEnv` with the same meaning and defaults (:data:`WORLD_OPTIONS`:
            ``evs``, ``decision_interval`` (seconds between ticks), ``max_travel_time`` (per guided
            EV), ``normalize_obs`` (also ``H``, in multiples of the points), ``charging_points``,
            ``demand``, ``demand_seeds``, ``route_file``, ``cache_dir``, ``snapshot_every``,
            ``step_length``, ``time_to_teleport``, ``stuck_limit``, ``max_insert_delay``, ``day_end``;
            ``protocol`` only ``"fast"`` and ``gui`` only false).

    Both environments describe their world with one :class:`~evcd.env.config.EnvConfig` and play in
    a :class:`~evcd.env.world.World`. Every invalid argument raises ``ValueError`` naming it before
    SUMO starts. ``reset(seed=...)`` draws the day and the guided EVs;
    ``reset(options={"day": i})`` fixes the day (an index into ``demand_seeds``). Agents are the
    guided EVs' SUMO ids. libsumo runs one simulation per process: one fleet per process.
    """

    metadata = {"name": FLEET_ENV_ID, "render_modes": [], "is_parallelizable": True}  # noqa: RUF012

    def __init__(
        self,
        scenario: str | Path = JURONG_WEST,
        guided_share: float = 1.0,
        *,
        departure_window: tuple[float, float] = MORNING_PEAK,
        reward: str | Callable[[Slot], float] = "time",
        **world: Any,
    ) -> None:
        self.guided_share = check_real("guided_share", guided_share, low=0.0, high=1.0, low_open=True)
        unknown = sorted(set(world) - set(WORLD_OPTIONS))
        if unknown:
            raise ValueError(f"FleetEnv: unknown arguments {unknown}; besides scenario, guided_share, "
                             f"departure_window and reward it takes {', '.join(WORLD_OPTIONS)}")  # fmt: skip
        if world.get("protocol", "fast") != "fast":
            raise ValueError(f"protocol={world['protocol']!r}: the fleet runs from the day's snapshot at the "
                             "window's start, so it takes protocol='fast' only")  # fmt: skip
        if world.get("gui", False):
            raise ValueError("gui=True: the fleet runs headless (watch a single target's episodes with "
                             "ChargingNavEnv(gui=True))")  # fmt: skip
        config = EnvConfig(scenario=scenario, departure_window=departure_window, reward=reward, **world)
        if "forecast" in config.observe and config.forecaster["name"] == "oracle":
            raise ValueError("forecaster='oracle' reads the cached background day's future, which the "
                             "fleet's guided EVs change: use 'history', 'trend', 'anomaly' or "
                             "'sessions'")  # fmt: skip
        self.world = World(config)
        m = len(self.stations)
        #: the observation's blocks: ``[D, N, Z, H]`` and the observation options' (e.g. ``"DNZHP"``)
        self.layout = layout_of("DNZH", config.observe)
        low, high = observation_bounds(self.stations, config.normalize_obs, self.layout)
        self._obs_space = gymnasium.spaces.Box(low, high, dtype=np.float32)
        self._act_space = gymnasium.spaces.Discrete(m)
        self.render_mode: str | None = None  # nothing to render (sumo-gui watches single targets)
        self.agents: list[str] = []
        self.guided: dict[str, GuidedEV] = {}  # this episode's guided EVs by vehicle id
        self.day: int | None = None
        #: per tick of the episode: (time, vehicles at each station, guided EVs heading to each)
        self.trace: list[tuple[float, tuple[int, ...], tuple[int, ...]]] = []
        self._tick = 0.0
        self._ended = False

    # ------------------------------------------------------------------ the parts
    @functools.cached_property
    def _views(self) -> TickObserver:
        """What the guided EVs observe at a tick."""
        return TickObserver(self.observer, self.stations, self.layout, self.config.normalize_obs)

    @functools.cached_property
    def candidates(self) -> list[list[ChargingTrip]]:
        """Per day (index into ``demand_seeds``): its charging EVs departing in the window (the day's
        route file is generated if needed; no SUMO)."""
        out = []
        for cache in self.simulation.caches:
            trips = read_charging_trips(cache.ensure_routes(), self.stations)
            out.append(in_window(trips, self.config.departure_window))
        return out

    @functools.cached_property
    def possible_agents(self) -> list[str]:  # type: ignore[override]
        """Every vehicle that can become an agent, known without generating or simulating a day: with
        generated demand every EV of a day (``ev0`` .. ``ev{evs-1}``; an episode's agents are the
        charging ones departing in the window, whatever the day), with a ``route_file`` its charging
        EVs departing in the window (read from the file)."""
        cfg = self.config
        if cfg.route_file is not None:
            trips = in_window(read_charging_trips(cfg.route_file, self.stations), cfg.departure_window)
            return sorted({trip.vehicle for trip in trips})
        return [ev_id(i) for i in range(cfg.demand_config.evs)]

    @functools.cache  # noqa: B019  (PettingZoo wants the same object per agent)
    def observation_space(self, agent: str) -> gymnasium.spaces.Box:
        """``Box`` of ``[D, N, Z, H]`` (length ``4m``), the same for every agent."""
        return self._obs_space

    @functools.cache  # noqa: B019
    def action_space(self, agent: str) -> gymnasium.spaces.Discrete:
        """``Discrete(m)``: a station index."""
        return self._act_space

    def prepare(self, workers: int | None = None) -> None:
        """Check that every day has EVs to guide, then build (or verify) every day's snapshots now
        instead of at the first reset, the days not cached side by side (``workers`` processes at a
        time; default: this process's cores).

        Raises:
            ValueError: a day has no charging EV departing in the window (before SUMO starts).
        """
        self.check_days()
        self.world.prepare(workers)

    def check_days(self) -> None:
        """Raise ``ValueError`` (no SUMO needed) if a day has no charging EV departing in the window."""
        for day, trips in enumerate(self.candidates):
            if not trips:
                raise ValueError(self._nothing_to_guide(day))

    def _nothing_to_guide(self, day: int) -> str:
        lo, hi = self.config.departure_window
        return (f"no charging EV of day {self.days[day].demand_seed} departs in departure_window="
                f"[{lo:g}, {hi:g}) s: nothing to guide (widen the window or add EVs)")  # fmt: skip

    # ------------------------------------------------------------------ the API
    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        """Start an episode: draw the day and the guided EVs, load the window's start, and run to the
        first tick at which some guided EV is on its way."""
        rng, _ = seeding.np_random(seed)
        options = dict(options or {})
        unknown = sorted(set(options) - _OPTIONS)
        if unknown:
            log.warning("reset options %s ignored; known: %s", unknown, sorted(_OPTIONS))
        day = int(rng.integers(len(self.days)))
        if "day" in options:
            day = int(options["day"])
            if not 0 <= day < len(self.days):
                raise ValueError(f"options day={day}: must index demand_seeds (0..{len(self.days) - 1})")
        trips = draw_guided(self.candidates[day], self.guided_share, rng)
        if not trips:
            raise ValueError(self._nothing_to_guide(day))
        self.day = day
        self.guided = {trip.vehicle: GuidedEV(trip, trip.station) for trip in trips}
        self.agents = []
        self._ended = False
        sim = self.simulation
        start = self.config.departure_window[0]
        # a fresh SUMO per episode: after loadState into a simulation that ran other vehicles, SUMO
        # keeps traces of them (a fleet run after three others teleported five EVs a fresh run did
        # not), and an episode must not depend on the ones before it
        sim.close()
        sim.start_at(day, start)
        present = set(sim.api.vehicle.getIDList())
        for ev in self.guided.values():
            if ev.vehicle in present:
                ev.on_insert(sim.api, sim.time)
        self._tick = start
        self.trace = []
        self._record_tick()
        new = self._run_until_agents()
        self._observe(self.agents)
        obs = {ev.vehicle: ev.obs.vector for ev in new if ev.obs is not None}
        infos = {ev.vehicle: self._info(ev) for ev in new}
        return obs, infos

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Send every agent to its chosen station (an agent left out keeps its station) and run to the
        next tick (further, while no guided EV is on its way and some will still depart)."""
        if self._ended or not self.agents:
            raise RuntimeError("the episode is over (or never began): call reset()")
        if not isinstance(actions, Mapping):
            raise TypeError(f"step takes a dict {{agent: station index}} (the agents: env.agents), not a "
                            f"{type(actions).__name__}: {actions!r}")  # fmt: skip
        sim = self.simulation
        now = sim.time
        chosen = {}  # every action checked before any is applied: a bad one leaves the episode as it was
        for agent, action in actions.items():
            ev = self.guided.get(agent)
            if ev is None or ev.stage is not Stage.ACTIVE:
                raise ValueError(f"actions for {agent!r}: not an agent of this step (agents: {self.agents})")
            chosen[agent] = (ev, check_action(action, len(self.stations), f"actions[{agent!r}]"))
        for agent, (ev, index) in chosen.items():
            ev.decisions += 1
            if index == ev.station:
                continue
            try:
                ev.send(sim.api, sim.controller, index, self.stations[index], self.observer, now)
            except SUMO_ERRORS as exc:
                log.warning(
                    "t=%s SUMO refused to send %s to station %d (%s); truncating it", now, agent, index, exc
                )
                ev.reason, ev.end = "sumo_error", now
        stepped = list(self.agents)
        self._tick += self.config.decision_interval
        self._advance(self._tick)
        self._record_tick()
        ended = self._judge_agents(stepped)
        new = self._new_agents()
        if not self.agents and not new:
            new = self._run_until_agents()
        self._observe(self.agents)
        obs: dict[str, np.ndarray] = {}
        rewards: dict[str, float] = {}
        terminations: dict[str, bool] = {}
        truncations: dict[str, bool] = {}
        infos: dict[str, dict[str, Any]] = {}
        for agent in stepped:
            ev = self.guided[agent]
            obs[agent] = ev.obs.vector if ev.obs is not None else self._obs_space.low
            started = agent in ended and ev.reason == "charging"
            done = agent in ended
            end = ev.end if done and ev.end is not None else self._tick
            slot = Slot(
                end - ev.slot_start, end - ev.trip.depart, started, done and not started, ev.travel_time
            )
            rewards[agent] = float(self.world.reward(slot))
            terminations[agent], truncations[agent] = started, done and not started
            infos[agent] = self._info(ev)
            ev.slot_start = self._tick
        for ev in new:
            obs[ev.vehicle] = ev.obs.vector if ev.obs is not None else self._obs_space.low
            rewards[ev.vehicle] = 0.0
            terminations[ev.vehicle] = truncations[ev.vehicle] = False
            infos[ev.vehicle] = self._info(ev)
        return obs, rewards, terminations, truncations, infos

    def close(self) -> None:
        """Close the SUMO simulation (idempotent)."""
        self.simulation.close()
        self.agents = []

    # ------------------------------------------------------------------ what happened
    def outcomes(self) -> list[dict[str, Any]]:
        """Per guided EV of the episode so far: its final info (:func:`~evcd.env.episode_rules.final_info`
        keys) if done, plus ``vehicle``, ``agent`` (whether it ever decided) and ``decisions``."""
        return [
            {**self._info(ev), "vehicle": ev.vehicle, "agent": ev.decisions > 0, "decisions": ev.decisions}
            for ev in self.guided.values()
        ]

    def measures(self) -> FleetMeasures:
        """The episode's measures (:mod:`evcd.env.fleet.measures`; call when it is over)."""
        if self.day is None:
            raise RuntimeError("no episode yet: call reset()")
        window = self.config.departure_window
        return measure(self.outcomes(), self.candidates[self.day], self.charge_records(), window[0])

    def charge_records(self) -> list[ChargeRecord]:
        """Every station visit of the running day so far (guided EVs and background alike)."""
        return self.simulation.controller.records

    # ------------------------------------------------------------------ the clock
    def _advance(self, until: float) -> None:
        """Step SUMO to ``until`` (:func:`~evcd.env.fleet.events.advance`)."""
        advance(self.simulation.driver, self.simulation.controller, self.guided, until)

    def _record_tick(self) -> None:
        counts, _ = heading(self.guided, self.simulation.controller, len(self.stations))
        occupancy = tuple(self.simulation.controller.occupancies())
        self.trace.append((self.simulation.time, occupancy, tuple(int(h) for h in counts)))

    def _judge_agents(self, agents: Sequence[str]) -> set[str]:
        """At a tick: which of ``agents`` are done (ends them); the others stay agents."""
        sim = self.simulation
        now = sim.time
        cfg = self.config
        ended: set[str] = set()
        for agent in agents:
            ev = self.guided[agent]
            if ev.reason is None:
                try:
                    ev.road, ev.pos, odo = Target.location(sim.api, agent)
                except SUMO_ERRORS:
                    ev.reason, ev.end = "vanished", now
                else:
                    assert ev.motion is not None
                    ev.motion.update(now, odo, parked=sim.controller.status(agent) is not None)
                    reason = slot_end_reason(
                        ev.motion, now, ev.trip.depart, cfg.stuck_limit, cfg.max_travel_time
                    )
                    if reason is not None:
                        ev.reason, ev.end = reason, now
            if ev.reason is not None:
                ev.finish(ev.reason, ev.end if ev.end is not None else now)
                ended.add(agent)
        self.agents = [a for a in agents if a not in ended]
        return ended

    def _new_agents(self) -> list[GuidedEV]:
        """At a tick: the EVs inserted since the last tick become agents; EVs done before their first
        tick and EVs never inserted are done."""
        sim = self.simulation
        now = sim.time
        delay = self.config.max_insert_delay
        new: list[GuidedEV] = []
        for ev in self.guided.values():
            if ev.stage is Stage.INSERTED:
                if ev.reason is not None:
                    ev.finish(ev.reason, ev.end if ev.end is not None else now)
                    continue
                try:
                    ev.road, ev.pos, odo = Target.location(sim.api, ev.vehicle)
                except SUMO_ERRORS:
                    ev.finish("vanished", now)
                    continue
                ev.stage, ev.slot_start = Stage.ACTIVE, ev.trip.depart  # its first slot counts from departure
                ev.motion = Motion(odo, now)
                new.append(ev)
            elif ev.stage is Stage.PENDING and now >= ev.trip.depart + delay - TIME_EPS:
                log.warning(
                    "guided EV %s not inserted within %.0f s; dropped",
                    ev.vehicle,
                    delay,
                )
                ev.finish("not_inserted", now)
        self.agents += [ev.vehicle for ev in new]
        return new

    def _run_until_agents(self) -> list[GuidedEV]:
        """Run tick after tick until some guided EV becomes an agent or every one is done."""
        new = self._new_agents()
        while not new and not all(ev.stage is Stage.DONE for ev in self.guided.values()):
            self._tick += self.config.decision_interval
            self._advance(self._tick)
            self._record_tick()
            new = self._new_agents()
        if not new:
            self._ended = True
        return new

    # ------------------------------------------------------------------ observations and rewards
    def _observe(self, agents: Sequence[str]) -> None:
        """The observations of ``agents`` at this tick (:class:`~evcd.env.fleet.observe.TickObserver`)."""
        if not agents:
            return
        sim = self.simulation
        for agent, obs in self._views.observe(sim.api, sim.controller, self.guided, agents).items():
            self.guided[agent].obs = obs

    # ------------------------------------------------------------------ info and checks
    def _info(self, ev: GuidedEV) -> dict[str, Any]:
        sim = self.simulation
        day = self.days[self.day].demand_seed if self.day is not None else None
        records = sim.controller.records if ev.stage is Stage.DONE and ev.reason != "sumo_error" else []
        return ev.info(sim.time if sim.running else ev.end, day, records, self.stations)


def parallel_env(**kwargs: Any) -> FleetEnv:
    """A :class:`FleetEnv` (PettingZoo's factory convention, as in sumo-rl)."""
    return FleetEnv(**kwargs)


def env(**kwargs: Any) -> AECEnv:
    """The fleet in PettingZoo's AEC form (its conversion of :class:`FleetEnv`; PettingZoo's name for
    the AEC factory): the agents due at a tick act one after the other, and the tick is simulated when
    the last of them has acted, so the episodes are the parallel form's."""
    return parallel_to_aec(FleetEnv(**kwargs))
