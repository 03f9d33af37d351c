"""evcd: deep reinforcement learning for electric-vehicle charging dispatch on SUMO.

Importing :mod:`evcd` registers the Gymnasium id ``evcd/ChargingNav-v1`` by its string entry point,
so that importing any module of the package (say :mod:`evcd.sim.snapshots`) does not pull in the
environment layer; ``gymnasium.make`` imports it when the environment is made. The id makes
:func:`evcd.experiments.make_env`: an experiment's world per split
(``gymnasium.make("evcd/ChargingNav-v1", experiment="peak", split="train")``), or a
:class:`~evcd.env.ChargingNavEnv` of the arguments given; observations normalised unless
``normalize_obs=False``.

The environments' versions follow Gymnasium's rule: a new version for any change of behaviour a result
depends on (the history is in :mod:`evcd.env.charging_nav` and :mod:`evcd.env.fleet.fleet_env`). An
older id is refused by Gymnasium, naming today's (``DeprecatedEnv``).
"""

import gymnasium

__version__ = "0.1.0"

#: The Gymnasium id of :class:`evcd.env.ChargingNavEnv` (made by :func:`evcd.experiments.make_env`).
ENV_ID = "evcd/ChargingNav-v1"
#: The name of the fleet, :class:`evcd.env.fleet.FleetEnv` (PettingZoo's ``metadata["name"]``).
FLEET_ENV_ID = "evcd_fleet_v1"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="evcd.experiments.make:make_env")
