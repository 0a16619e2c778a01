"""Named testbed profiles, the hub's half: the physics a profile sets (MAC settings, BLE link, IR noise).

``ideal`` (the default) changes nothing: the 802.15.4-2006 defaults of ``radio_hub.config``, the BLE link
of ``radio_hub.physics.ble`` and the IR module of ``radio_hub.physics.light``. ``kim2017`` is the swarm
paper's testbed (Kim, Kim & Kang, Sensors 2017) as far as the paper states or its figures imply; every
value's source is in docs/PROFILES.md. The robots' half (MCU and UART latency per frame, the belt's
recognition delay, the organizing steps' deadline) is ``petswarm.profiles``: a robot knows its own
hardware, the hub the world's.
"""

from __future__ import annotations

import copy
import dataclasses
from typing import Any

from radio_hub.environment import EnvironmentConfig

PROFILES = ("ideal", "kim2017")
HUB_PROFILES = PROFILES
"""The profiles the hub knows (``petswarm.profiles.PROFILES`` names the same ones without loading the hub)."""

_TABLES: dict[str, dict[str, dict[str, Any]]] = {
    "ideal": {},
    "kim2017": {
        # the paper's robots speak the IEEE 802.15.4 MAC: the standard's default attributes, stated
        "mac": {
            "min_be": 3,
            "max_be": 5,
            "max_csma_backoffs": 4,
            "max_frame_retries": 3,
            "ack_enabled": True,
            # macSIFSPeriod and macLIFSPeriod of the 2.4 GHz O-QPSK PHY (12 and 40 symbols, 5.1.1.3)
            "sifs_us": 192,
            "lifs_us": 640,
        },
        # a wearable's BLE connection as a phone-class central negotiates it (30 ms) plus the stacks
        "ble": {"interval_ms": 30.0, "latency_ms": 5.0},
        # fit to Table 4's RMSE with equations (1)-(3): 7.898 cm and 5.8 degrees
        "ir": {"relative_noise": 0.04, "noise_floor_counts": 1.8, "emitter_noise": 0.1},
    },
}


def check_profile(name: str) -> str:
    """``name`` when it is a known profile; ValueError naming the known ones otherwise."""
    if name not in _TABLES:
        raise ValueError(f"unknown profile {name!r}: one of {', '.join(PROFILES)}")
    return name


def profile_tables(name: str) -> dict[str, dict[str, Any]]:
    """The hub tables (``mac``, ``ble``, ``ir``) ``name`` sets, as a hub config file would."""
    return copy.deepcopy(_TABLES[check_profile(name)])


def apply_profile(config: EnvironmentConfig, name: str) -> EnvironmentConfig:
    """A copy of ``config`` with profile ``name``'s values set (``ideal``: the same values)."""
    tables = profile_tables(name)
    medium = config.medium
    mac = dataclasses.replace(medium.mac, **tables.get("mac", {}))
    mac.validate()
    ble = dataclasses.replace(config.ble, **tables.get("ble", {})).validate()
    ir = dataclasses.replace(config.ir, **tables.get("ir", {}))
    ir.validate()
    return dataclasses.replace(config, medium=dataclasses.replace(medium, mac=mac), ble=ble, ir=ir)
