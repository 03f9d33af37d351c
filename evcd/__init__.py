"""evcd: deep reinforcement learning for electric-vehicle charging dispatch on SUMO."""

__version__ = "0.1.0"
