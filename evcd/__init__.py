"""evcd: deep reinforcement learning for electric-vehicle charging dispatch on SUMO."""

__version__ = "0.1.0"

from evcd import env as env  # registers evcd/ChargingNav-v0 with Gymnasium
