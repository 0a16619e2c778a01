"""The datasheet of the parts robots and wearables are built from: what their code may know of the hub.

A real robot knows its IR module and the wearable its LF receiver from the parts' datasheets, never from the
world. So robot and wearable code (``petswarm``) takes the hub's physics only from here (or, for the radio,
through ``radio_hub.interface``), never from the hub's models or their private names.

IR module (``radio_hub.physics.light``)
    ``RECEIVERS`` receivers, evenly spaced around the body; ``IrConfig`` the module's
    settings (emitter power, receivers' gain and noise, range, sweep timing) with their defaults;
    ``PERSON_BEACON_POWER`` the emitter power of the beacon a person wears; ``receiver_axes_rad()`` each
    receiver's axis from the heading.
LF antennas (``radio_hub.physics.lf``)
    ``LfConfig`` the robots' two LF antennas (baseline, field strength, RSSI curve, burst timing);
    ``wake_pattern(robot_id)`` the wake-up pattern a robot's bursts carry and ``wakes(register, pattern)``
    whether a belt's receiver wakes on it.
Settings tables (``radio_hub.config``)
    ``build_config(cls, table, where)`` builds a settings dataclass from a TOML/JSON table, refusing unknown
    keys and wrong types with the table's name; ``check_keys`` refuses unknown keys. Every settings file
    petswarm reads goes through them.
"""

from __future__ import annotations

from radio_hub.config import build_config, check_keys
from radio_hub.physics.lf import LfConfig, wake_pattern, wakes
from radio_hub.physics.light import PERSON_BEACON_POWER, RECEIVERS, IrConfig, receiver_axes_rad

__all__ = [
    "PERSON_BEACON_POWER",
    "RECEIVERS",
    "IrConfig",
    "LfConfig",
    "build_config",
    "check_keys",
    "receiver_axes_rad",
    "wake_pattern",
    "wakes",
]
