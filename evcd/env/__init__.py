"""The charging-navigation environment (Gymnasium id ``evcd/ChargingNav-v0``).

    import gymnasium, evcd
    env = gymnasium.make("evcd/ChargingNav-v0", evs=300)

Importing :mod:`evcd` registers the id.
"""

import gymnasium

from evcd.env.charging_nav import ChargingNavEnv
from evcd.env.observation import Observation, RouteObserver
from evcd.env.reward import REWARDS, Slot
from evcd.env.target import TARGET_ID
from evcd.env.vector import make_vector_env

ENV_ID = "evcd/ChargingNav-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="evcd.env.charging_nav:ChargingNavEnv")

__all__ = [
    "ENV_ID",
    "REWARDS",
    "TARGET_ID",
    "ChargingNavEnv",
    "Observation",
    "RouteObserver",
    "Slot",
    "make_vector_env",
]
