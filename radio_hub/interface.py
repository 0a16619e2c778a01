"""The radio hub's public face: what a node (a robot, a wearable, a test) uses to get on the air.

``RadioClient`` gives an asyncio node the RF calls of a real 802.15.4 radio driver:
``await send(frame) -> TxResult``, ``await receive() -> RxFrame`` (or ``async for``), and
``await configure(pan_id=..., short_addr=..., channel=...)`` at run time. It talks to the hub's
environment through a ``HubLink``: over zenoh between processes (``radio_hub.link.zenoh_link``), or in memory in
a model-time run. The types both sides share live in ``radio_hub.link.port``, which imports no zenoh; this module
adds the zenoh helpers a process needs (sessions and hub queries).

It also carries the entry points of the lab that hosts the environment itself (a model-time or lockstep
run, a bench): the environment, its coordinator, the lockstep link, config loading. Robots' and
wearables' knowledge of the hub's parts is in ``radio_hub.datasheet``.
"""

from __future__ import annotations

import importlib
from typing import Any

from radio_hub.air.mac import BROADCAST, MAX_PSDU, Frame, FrameError, FrameType, TxStatus, max_payload
from radio_hub.air.security import LinkSecurity, SecurityError, load_key, read_key_file, swarm_key
from radio_hub.config import MediumConfig, airtime_us
from radio_hub.link.keys import DEFAULT_ENDPOINT, DEFAULT_WORLD, WORLD_THREAD, Keys
from radio_hub.link.port import (
    MODEL_EPOCH_S,
    REQUEST_TIMEOUT_S,
    RESEND_S,
    BeaconSweep,
    BleMessage,
    HubLink,
    HubUnavailable,
    IrSweep,
    LfBurstHeard,
    OwnSensors,
    RadioClient,
    RadioError,
    RadioIdentity,
    RxFrame,
    TxResult,
)
from radio_hub.link.zenoh_link import ZenohLink, open_session, query_hub
from radio_hub.physics.light import IrConfig

__all__ = [
    "BROADCAST",
    "DEFAULT_ENDPOINT",
    "DEFAULT_WORLD",
    "MAX_PSDU",
    "MODEL_EPOCH_S",
    "REQUEST_TIMEOUT_S",
    "RESEND_S",
    "WORLD_THREAD",
    "BeaconSweep",
    "BleMessage",
    "Frame",
    "FrameError",
    "FrameType",
    "HubLink",
    "HubUnavailable",
    "IrConfig",
    "IrSweep",
    "Keys",
    "LfBurstHeard",
    "LinkSecurity",
    "MediumConfig",
    "OwnSensors",
    "RadioClient",
    "RadioError",
    "RadioIdentity",
    "RxFrame",
    "SecurityError",
    "TxResult",
    "TxStatus",
    "ZenohLink",
    "airtime_us",
    "load_key",
    "max_payload",
    "open_session",
    "query_hub",
    "read_key_file",
    "swarm_key",
]


_LAB_ENTRY_POINTS = {
    "Coordinator": "radio_hub.coordinator",
    "EnvironmentConfig": "radio_hub.environment",
    "HANDED_OVER": "radio_hub.environment",
    "Faults": "radio_hub.guard",
    "LockstepLink": "radio_hub.shell.lockstep",
    "MODEL_EPOCH_US": "radio_hub.coordinator",
    "OPERATOR": "radio_hub.link.trust",
    "HUB_PROFILES": "radio_hub.profiles",
    "apply_profile": "radio_hub.profiles",
    "profile_tables": "radio_hub.profiles",
    "Message": "radio_hub.link.wire",
    "Relayed": "radio_hub.link.wire",
    "check_name": "radio_hub.link.keys",
    "check_timed_fault": "radio_hub.air.chaos",
    "describe_fault": "radio_hub.air.chaos",
    "config_problem": "radio_hub.environment",
    "environment_from_dict": "radio_hub.environment",
    "lazy_numpy": "radio_hub.lazy",
    "load_config": "radio_hub.shell.hub",
    "parse_obstacle": "radio_hub.physics.world",
    "receiver_axes_rad": "radio_hub.physics.light",
    "receiver_readings": "radio_hub.physics.light",
    "read_pcap": "radio_hub.air.pcap",
    "put_up": "radio_hub.link.zenoh_link",
    "reliable_publisher": "radio_hub.link.zenoh_link",
    "wait_for_up_key": "radio_hub.link.up_keys",
}
"""What the lab (model-time and lockstep runs, benches) takes from the hub's side, loaded on first use so
that a robot process, which imports this module too, never loads the hub's models."""


def __getattr__(name: str) -> Any:
    """A lab entry point, imported from its module when first asked for."""
    module = _LAB_ENTRY_POINTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)
