"""The fleet task: many guided EVs of one background day at once, competing at the stations
(a PettingZoo ``ParallelEnv``).

    from evcd.env import fleet
    env = fleet.parallel_env(evs=400, guided_share=0.5)       # or fleet.env(...): PettingZoo's AEC form
"""

from evcd.env.fleet.fleet_env import MORNING_PEAK, FleetEnv, env, parallel_env
from evcd.env.fleet.guided import GuidedEV, Stage
from evcd.env.fleet.trips import ChargingTrip, draw_guided, in_window, read_charging_trips

__all__ = [
    "MORNING_PEAK",
    "ChargingTrip",
    "FleetEnv",
    "GuidedEV",
    "Stage",
    "draw_guided",
    "env",
    "in_window",
    "parallel_env",
    "read_charging_trips",
]
