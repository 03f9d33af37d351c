"""The fleet task: many guided EVs of one background day at once, competing at the stations
(a PettingZoo ``ParallelEnv``).

    from evcd.env.fleet import parallel_env, aec_env
    env = parallel_env(evs=400, guided_share=0.5)       # or aec_env(...): PettingZoo's AEC form
"""

from evcd.env.fleet.fleet_env import MORNING_PEAK, FleetEnv, aec_env, parallel_env
from evcd.env.fleet.guided import GuidedEV, Stage
from evcd.env.fleet.trips import ChargingTrip, draw_guided, in_window, read_charging_trips

__all__ = [
    "MORNING_PEAK",
    "ChargingTrip",
    "FleetEnv",
    "GuidedEV",
    "Stage",
    "aec_env",
    "draw_guided",
    "in_window",
    "parallel_env",
    "read_charging_trips",
]
