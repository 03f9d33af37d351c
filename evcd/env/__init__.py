"""The charging-navigation environment (Gymnasium id ``evcd/ChargingNav-v1``).

    import gymnasium, evcd
    env = gymnasium.make("evcd/ChargingNav-v1", evs=300)

Importing :mod:`evcd` registers the id (by its string entry point, see :mod:`evcd`).
"""

from evcd import ENV_ID
from evcd.env.charging_nav import ChargingNavEnv
from evcd.env.observation import Observation, RouteObserver
from evcd.env.reward import REWARDS, Slot
from evcd.env.target import TARGET_ID
from evcd.env.vector import make_vector_env

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
