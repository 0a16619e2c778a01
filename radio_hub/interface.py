"""The radio hub's public face for a node process: what a robot, a wearable, a run's orchestrator or a test
uses to get on the air over zenoh.

``RadioClient`` gives an asyncio node the RF calls of a real 802.15.4 radio driver:
``await send(frame) -> TxResult``, ``await receive() -> RxFrame`` (or ``async for``), and
``await configure(pan_id=..., short_addr=..., channel=...)`` at run time. It talks to the hub's
environment through a ``HubLink``: over zenoh between processes (``ZenohLink``, or ``LockstepLink`` on the
lockstep clock), or in memory in a model-time run. Here too: the zenoh helpers a process needs (sessions,
hub queries, reliable publishers), the key expressions, link security and key files.

The pure values both sides share (frames, TX results, sensor samples, wire messages, chaos) are
``radio_hub.values``, named here as well; a pure core imports them from there, so it never loads zenoh,
asyncio or threads. A lab that hosts the environment itself takes it from ``radio_hub.hosting``.
"""

from __future__ import annotations

from radio_hub.air.security import LinkSecurity, SecurityError, load_key, read_key_file, swarm_key
from radio_hub.link.keys import DEFAULT_ENDPOINT, DEFAULT_WORLD, WORLD_THREAD, Keys, check_name
from radio_hub.link.lockstep_link import LockstepLink
from radio_hub.link.port import REQUEST_TIMEOUT_S, RESEND_S, HubLink, RadioClient
from radio_hub.link.trust import OPERATOR
from radio_hub.link.up_keys import wait_for_up_key
from radio_hub.link.zenoh_link import ZenohLink, open_session, put_up, query_hub, reliable_publisher
from radio_hub.physics.light import IrConfig
from radio_hub.values import (
    BROADCAST,
    MAX_PSDU,
    MODEL_EPOCH_S,
    BeaconSweep,
    BleMessage,
    Faults,
    Frame,
    FrameError,
    FrameType,
    HubUnavailable,
    IrSweep,
    LfBurstHeard,
    MediumConfig,
    Message,
    OwnSensors,
    RadioError,
    RadioIdentity,
    Relayed,
    RxFrame,
    TxResult,
    TxStatus,
    airtime_us,
    check_timed_fault,
    describe_fault,
    lazy_numpy,
    max_payload,
)

__all__ = [
    "BROADCAST",
    "DEFAULT_ENDPOINT",
    "DEFAULT_WORLD",
    "MAX_PSDU",
    "MODEL_EPOCH_S",
    "OPERATOR",
    "REQUEST_TIMEOUT_S",
    "RESEND_S",
    "WORLD_THREAD",
    "BeaconSweep",
    "BleMessage",
    "Faults",
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
    "LockstepLink",
    "MediumConfig",
    "Message",
    "OwnSensors",
    "RadioClient",
    "RadioError",
    "RadioIdentity",
    "Relayed",
    "RxFrame",
    "SecurityError",
    "TxResult",
    "TxStatus",
    "ZenohLink",
    "airtime_us",
    "check_name",
    "check_timed_fault",
    "describe_fault",
    "lazy_numpy",
    "load_key",
    "max_payload",
    "open_session",
    "put_up",
    "query_hub",
    "read_key_file",
    "reliable_publisher",
    "swarm_key",
    "wait_for_up_key",
]
