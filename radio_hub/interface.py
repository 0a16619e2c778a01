"""The radio hub's public face: what a node (a robot, a wearable, a test) uses to get on the air.

``RadioClient`` gives an asyncio node the RF calls of a real 802.15.4 radio driver:
``await send(frame) -> TxResult``, ``await receive() -> RxFrame`` (or ``async for``), and
``await configure(pan_id=..., short_addr=..., channel=...)`` at run time. It talks to the hub's
environment through a ``HubLink``: over zenoh between processes (``radio_hub.zenoh_link``), or in memory in
a model-time run. The types both sides share live in ``radio_hub.port``, which imports no zenoh; this module
adds the zenoh helpers a process needs (sessions and hub queries).
"""

from __future__ import annotations

from radio_hub.config import MediumConfig, airtime_us
from radio_hub.keys import DEFAULT_ENDPOINT, DEFAULT_WORLD, Keys
from radio_hub.light import IrConfig
from radio_hub.mac import BROADCAST, MAX_PSDU, Frame, FrameError, FrameType, TxStatus, max_payload
from radio_hub.port import (
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
from radio_hub.zenoh_link import ZenohLink, open_session, query_hub

__all__ = [
    "BROADCAST",
    "DEFAULT_ENDPOINT",
    "DEFAULT_WORLD",
    "MAX_PSDU",
    "MODEL_EPOCH_S",
    "REQUEST_TIMEOUT_S",
    "RESEND_S",
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
    "MediumConfig",
    "OwnSensors",
    "RadioClient",
    "RadioError",
    "RadioIdentity",
    "RxFrame",
    "TxResult",
    "TxStatus",
    "ZenohLink",
    "airtime_us",
    "max_payload",
    "open_session",
    "query_hub",
]
