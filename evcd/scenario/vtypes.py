"""The scenario's vehicle types: a conventional car ``car`` and an electric car ``ev``.

Written as a SUMO additional file (``vtypes.add.xml``) loaded before the demand. The ``ev`` type
carries SUMO's battery device (parameter names of SUMO >= 1.20; older releases used
``maximumBatteryCapacity`` / ``actualBatteryCapacity``):

- ``has.battery.device = true``: every ``ev`` vehicle gets the device, no command-line option needed.
- ``device.battery.capacity`` (Wh): battery size; a vehicle ``<param>`` of the same key overrides it.
- ``device.battery.maximumChargeRate`` (W): the most the car accepts. Keep it above the stations'
  power so that the station (100 kW) sets the pace; the charging controller sets it to 0 to hold a
  waiting car and back to this value when the car gets a charging point.
- ``emissionClass = Energy/unknown``: SUMO's electric consumption model with its default car
  (mass, drag, ...), so driving drains the battery and braking recuperates.

Per vehicle, the demand sets ``device.battery.chargeLevel`` (Wh, the initial charge; default half the
capacity) and optionally ``evcd.targetSoc`` (see :mod:`evcd.sim.charging`).

Both types drive deterministically by default (``sigma = 0``: no Krauss dawdling; ``speedDev = 0``:
every driver at its ``speedFactor``, 1 unless the demand sets one per vehicle from its own seed).
SUMO 1.28 does not restore its random number generators from a saved state (``--save-state.rng``
makes it worse: vehicles went missing), so randomness drawn inside SUMO makes a run continued from a
snapshot diverge from the uninterrupted run at once; without it the two agree closely (in a test, one
insertion in 200 came one step later). Drivers' variety belongs in per-vehicle ``speedFactor`` values
written by the demand generator.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from evcd.utils.atomic import atomic_write_text

CAR_TYPE = "car"
EV_TYPE = "ev"


@dataclass(frozen=True)
class VehicleTypes:
    """Parameters of the ``car`` and ``ev`` types.

    Attributes:
        ev_capacity_wh: default battery capacity of an ``ev`` (Wh).
        ev_max_charge_rate_w: the most power an ``ev`` accepts while charging (W).
        speed_dev: deviation of the drivers' speed factor (SUMO ``speedDev``), both types; > 0 draws
            inside SUMO (see the module note on snapshots).
        sigma: driver imperfection of the Krauss model (SUMO ``sigma``, 0..1), both types; SUMO's own
            default is 0.5; > 0 draws inside SUMO at every step.
    """

    ev_capacity_wh: float = 60_000.0
    ev_max_charge_rate_w: float = 150_000.0
    speed_dev: float = 0.0
    sigma: float = 0.0

    def __post_init__(self) -> None:
        if self.ev_capacity_wh <= 0:
            raise ValueError(f"ev_capacity_wh={self.ev_capacity_wh} must be > 0")
        if self.ev_max_charge_rate_w <= 0:
            raise ValueError(f"ev_max_charge_rate_w={self.ev_max_charge_rate_w} must be > 0")
        if self.speed_dev < 0:
            raise ValueError(f"speed_dev={self.speed_dev} must be >= 0")
        if not 0.0 <= self.sigma <= 1.0:
            raise ValueError(f"sigma={self.sigma} must be in [0, 1]")

    def elements(self) -> list[ET.Element]:
        """The ``<vType>`` elements of ``car`` and ``ev`` (to embed in a route or additional file)."""
        driving = {"vClass": "passenger", "speedDev": f"{self.speed_dev:g}", "sigma": f"{self.sigma:g}"}
        car = ET.Element("vType", id=CAR_TYPE, **driving)
        ev = ET.Element("vType", id=EV_TYPE, emissionClass="Energy/unknown", **driving)
        for key, value in (
            ("has.battery.device", "true"),
            ("device.battery.capacity", f"{self.ev_capacity_wh:.1f}"),
            ("device.battery.maximumChargeRate", f"{self.ev_max_charge_rate_w:.1f}"),
        ):
            ET.SubElement(ev, "param", key=key, value=value)
        return [car, ev]


def vtypes_to_xml(types: VehicleTypes | None = None) -> str:
    """The text of an additional file defining ``car`` and ``ev`` (default :class:`VehicleTypes`)."""
    root = ET.Element("additional")
    root.extend((types or VehicleTypes()).elements())
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def write_vtypes(path: str | Path, types: VehicleTypes | None = None) -> Path:
    """Write :func:`vtypes_to_xml` to ``path`` atomically."""
    return atomic_write_text(path, vtypes_to_xml(types))
