"""The simulated world an environment plays in: one description shared by both environments.

    world = World(EnvConfig(evs=400, departure_window=(25200, 36000), reward="time"))
    world.stations, world.days, world.simulation, world.observer     # what an episode needs

A :class:`World` is built from an :class:`~evcd.env.config.EnvConfig` (the scenario, its background
days, the departure window, the charging points, the reward, the observation units, the protocol,
SUMO's settings; every value checked before SUMO starts) and holds what both
:class:`~evcd.env.ChargingNavEnv` (one target) and :class:`~evcd.env.fleet.FleetEnv` (many guided
EVs) play on: the scenario and its stations, the days, this process's episode simulation
(:class:`~evcd.env.simulation.EpisodeSimulation`), the reward function, the road graph and the route
observer. Both environments reach it through :class:`InWorld`, so a setting means the same in both.
"""

from __future__ import annotations

from functools import cached_property

from evcd.env.config import EnvConfig
from evcd.env.day_builds import available_cores, build_days
from evcd.env.forecast_source import ForecastSource
from evcd.env.observation import RouteObserver
from evcd.env.reward import RewardFn, reward_fn
from evcd.env.simulation import EpisodeSimulation
from evcd.scenario.routing import RoadGraph
from evcd.scenario.scenario import Scenario
from evcd.scenario.stations_file import Station
from evcd.sim.snapshots import DayCache, DaySpec


class World:
    """The scenario, its background days and this process's simulation of them (module docstring).

    Args:
        config: the world's settings (checked already: :class:`~evcd.env.config.EnvConfig`).

    Raises:
        ValueError: the scenario folder is missing or malformed (no SUMO yet).
    """

    def __init__(self, config: EnvConfig) -> None:
        self.config = config
        self.scenario, self.days = config.load()
        self.reward: RewardFn = reward_fn(config.reward)
        self.forecast = self._forecast_source() if "forecast" in config.observe else None
        self.simulation = EpisodeSimulation(
            self.scenario, self.days, config.protocol, config.departure_window, config.snapshot_every,
            config.cache_dir, config.day_end, gui=config.gui, forecast=self.forecast,
        )  # fmt: skip

    def _forecast_source(self) -> ForecastSource:
        """The forecast block's source: the configured forecaster, fitted on the history days."""
        cfg = self.config
        settings = {k: v for k, v in cfg.forecaster.items() if k != "name"}
        history = [DayCache(spec, cfg.cache_dir) for spec in cfg.history_days(self.scenario)]
        times = cfg.snapshot_times()
        return ForecastSource(
            cfg.forecaster["name"], settings, [st.id for st in self.stations], history, times
        )

    @property
    def stations(self) -> tuple[Station, ...]:
        """The charging stations (the actions, in order)."""
        return self.scenario.stations

    @cached_property
    def graph(self) -> RoadGraph:
        """The network's drivable edges."""
        return RoadGraph.from_net(self.scenario.net)

    @cached_property
    def observer(self) -> RouteObserver:
        """Computes ``[D, N, Z]`` and the observation options' blocks (:mod:`evcd.env.observation`) in the
        configured units."""
        cfg = self.config
        return RouteObserver(self.stations, self.graph, normalize=cfg.normalize_obs, observe=cfg.observe,
                             forecast=self.forecast, static_routes=self.static_roads)  # fmt: skip

    @property
    def static_roads(self) -> bool:
        """Whether no day of the world plays road events (:mod:`evcd.sim.road_player`): the roads'
        speed limits, permissions and the router's weights stay as the network has them."""
        return all(spec.roads.empty for spec in self.days)

    def prepare(self, workers: int | None = None) -> None:
        """Build (or verify) every background day's snapshots now instead of at first use: the days not
        cached yet are built side by side, ``workers`` processes at a time (default: the cores this
        process may use; :mod:`evcd.env.day_builds`), then each is verified here."""
        sim = self.simulation
        missing = [day for day in range(len(self.days)) if not sim.cached(day)]
        workers = available_cores() if workers is None else workers
        if len(missing) > 1 and workers > 1:
            build_days(self.config, missing, workers)
        for day in range(len(self.days)):
            sim.prepare(day)


class InWorld:
    """What an environment in a :class:`World` offers of it (``self.world`` set by its constructor)."""

    world: World

    @property
    def config(self) -> EnvConfig:
        """The world's settings."""
        return self.world.config

    @property
    def scenario(self) -> Scenario:
        """The scenario (network, stations, vehicle types)."""
        return self.world.scenario

    @property
    def days(self) -> list[DaySpec]:
        """The background days (one per ``demand_seeds`` entry)."""
        return self.world.days

    @property
    def stations(self) -> tuple[Station, ...]:
        """The charging stations (the actions, in order)."""
        return self.world.stations

    @property
    def simulation(self) -> EpisodeSimulation:
        """This process's simulation of the days."""
        return self.world.simulation

    @property
    def graph(self) -> RoadGraph:
        """The network's drivable edges."""
        return self.world.graph

    @property
    def observer(self) -> RouteObserver:
        """Computes the observations' ``[D, N, Z]``."""
        return self.world.observer
