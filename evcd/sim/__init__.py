"""The simulation: one SUMO run (:class:`SumoDriver`) and the stations' charging queues."""

from evcd.sim.charging import ChargeRecord, ChargingController, Outcome
from evcd.sim.driver import SumoDriver

__all__ = ["ChargeRecord", "ChargingController", "Outcome", "SumoDriver"]
