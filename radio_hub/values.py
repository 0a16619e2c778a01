"""The radio hub's pure public face: the values a node and the hub share, with no zenoh, asyncio or threads.

A robot's cores (its managers and controllers, sans-IO) take what they know of the radio from here: frames and
their limits, a transmission's outcome, what the radio and the body's sensors hand a node, the wire's message
types, and the chaos vocabulary (faults a run may schedule and how they read). Importing this module loads none
of the hub's shell nor any I/O; ``radio_hub.interface`` adds the client and the zenoh transport for a process.
"""

from __future__ import annotations

from radio_hub.air.chaos import check_timed_fault, describe_fault
from radio_hub.air.mac import BROADCAST, MAX_PSDU, Frame, FrameError, FrameType, TxStatus, max_payload
from radio_hub.config import MediumConfig, airtime_us
from radio_hub.guard import Faults
from radio_hub.lazy import lazy_numpy
from radio_hub.link.values import (
    MODEL_EPOCH_S,
    BeaconSweep,
    BleMessage,
    HubUnavailable,
    IrSweep,
    LfBurstHeard,
    OwnSensors,
    RadioError,
    RadioIdentity,
    RxFrame,
    TxResult,
)
from radio_hub.link.wire import Message, Relayed

__all__ = [
    "BROADCAST",
    "MAX_PSDU",
    "MODEL_EPOCH_S",
    "BeaconSweep",
    "BleMessage",
    "Faults",
    "Frame",
    "FrameError",
    "FrameType",
    "HubUnavailable",
    "IrSweep",
    "LfBurstHeard",
    "MediumConfig",
    "Message",
    "OwnSensors",
    "RadioError",
    "RadioIdentity",
    "Relayed",
    "RxFrame",
    "TxResult",
    "TxStatus",
    "airtime_us",
    "check_timed_fault",
    "describe_fault",
    "lazy_numpy",
    "max_payload",
]
