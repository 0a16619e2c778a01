"""The radio hub's face for a lab that hosts the environment in its own process: a model-time run, a bench,
a scenario's checks. It names the environment and its settings, the coordinator that runs it on model time,
the hub's profiles and the readers of what a hub writes (pcap). Robots and wearables never import it: they
see the hub through ``radio_hub.values`` and ``radio_hub.interface`` only.

Importing it loads the environment's models (numpy among them) but no zenoh: a process that only parses
a command line or runs a robot imports it inside the function that needs it.
"""

from __future__ import annotations

from radio_hub.air.pcap import read_pcap
from radio_hub.coordinator import MODEL_EPOCH_US, Coordinator
from radio_hub.environment import (
    HANDED_OVER,
    EnvironmentConfig,
    config_problem,
    environment_from_dict,
    load_config,
)
from radio_hub.physics.light import receiver_readings
from radio_hub.physics.world import parse_obstacle
from radio_hub.profiles import HUB_PROFILES, apply_profile, profile_tables

__all__ = [
    "HANDED_OVER",
    "HUB_PROFILES",
    "MODEL_EPOCH_US",
    "Coordinator",
    "EnvironmentConfig",
    "apply_profile",
    "config_problem",
    "environment_from_dict",
    "load_config",
    "parse_obstacle",
    "profile_tables",
    "read_pcap",
    "receiver_readings",
]
