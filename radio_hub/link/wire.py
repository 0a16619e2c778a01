"""Messages between a node and the hub, encoded with msgpack.

Every message is a map with the envelope version ``v``, a type ``t`` and a per-sender sequence number
``n`` (so either side can count messages the transport lost: it should lose none). A node's messages also
carry its session key ``s``: a random number the node picks once and sends with its ``Attach`` and every
message after it; the hub binds the node id to it and refuses the id's messages with any other key (another
zenoh session speaking for the node). Decoding is strict: anything malformed raises ``WireError``, which the
receiver counts and drops; that includes a message longer than ``MAX_MESSAGE_BYTES`` (checked before any
parsing), an integer msgpack cannot carry, a sequence number or session key outside 0 to 2**63-1, and a float that
is not finite.
"""

from __future__ import annotations

import functools
import math
import operator
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar

import msgpack

WIRE_VERSION = 1
MAX_MESSAGE_BYTES = 1 << 20
"""No message of this protocol is longer (the largest, a hub's stats relayed to a run, is tens of kB)."""
MAX_UP_BYTES = 64 << 10
"""No node-to-hub message is longer (a frame is at most 127 bytes; a relayed control command is small)."""
INT_MIN, INT_MAX = -(1 << 63), (1 << 64) - 1
"""What msgpack carries (an extended address is a 64-bit unsigned number); sequence numbers and session keys
must also be at most ``SEQ_MAX``."""
SEQ_MAX = (1 << 63) - 1
NOT_ATTACHED = "node is not attached"
"""The hub's error for a node it does not know; after a hub restart the node attaches again on it."""


class WireError(ValueError):
    """Input that is not a valid message of this protocol version."""


@dataclass
class Message:
    """Base of all node/hub messages; subclasses set TYPE and their fields."""

    TYPE: ClassVar[str] = ""
    n: int = field(default=0, kw_only=True)
    s: int = field(default=0, kw_only=True)
    """The sending node's session key (0: none, as on every hub-to-node message)."""

    def encode(self) -> bytes:
        """msgpack bytes with the envelope."""
        names, values = _layout(type(self))
        body = dict(zip(names, values(self), strict=True))
        if not self.s:
            del body["s"]
        body["v"], body["t"] = WIRE_VERSION, self.TYPE
        return msgpack.packb(body, use_bin_type=True)


@functools.cache
def _layout(cls: type[Message]) -> tuple[tuple[str, ...], operator.attrgetter[Any]]:
    """A message type's field names and a getter of their values in that order (every type has at least ``n``
    and ``s``, so the getter returns a tuple): dataclasses.fields() costs microseconds per call, and the hub
    encodes two messages per frame."""
    names = tuple(f.name for f in fields(cls))
    return names, operator.attrgetter(*names)


@dataclass
class Attach(Message):
    """Node -> hub: put me on the air."""

    TYPE: ClassVar[str] = "attach"
    ext_addr: int = 0
    short_addr: int = 0
    pan_id: int = 0
    channel: int = 11
    position: list[float] = field(default_factory=lambda: [0.0, 0.0])
    heading_deg: float = 0.0
    instance: str = ""
    """The node's liveliness instance: only that token's disappearance detaches this attachment."""
    exclusive: bool = False
    """Refuse (instead of replacing) when a live node already has this id: how ``--id auto`` claims one."""
    kind: str = "robot"
    """``robot`` (a body with an 802.15.4 radio, IR module and own sensors) or ``user`` (a person: a body,
    BLE wearables, an LF receiver on the belt and an IR beacon; no 802.15.4 radio)."""


@dataclass
class Configure(Message):
    """Node -> hub: change PAN, short address, channel or position; None leaves a field as it is."""

    TYPE: ClassVar[str] = "configure"
    token: int = 0
    pan_id: int | None = None
    short_addr: int | None = None
    channel: int | None = None
    position: list[float] | None = None
    heading_deg: float | None = None


@dataclass
class Transmit(Message):
    """Node -> hub: a MAC data request carrying a complete PSDU."""

    TYPE: ClassVar[str] = "transmit"
    token: int = 0
    psdu: bytes = b""


@dataclass
class Detach(Message):
    """Node -> hub: I am leaving."""

    TYPE: ClassVar[str] = "detach"


@dataclass
class Attached(Message):
    """Hub -> node: the node's radio as the hub now has it (answer to Attach and Configure)."""

    TYPE: ClassVar[str] = "attached"
    token: int = 0
    ext_addr: int = 0
    short_addr: int = 0
    pan_id: int = 0
    channel: int = 11
    position: list[float] = field(default_factory=lambda: [0.0, 0.0])
    heading_deg: float = 0.0
    now_us: int = 0
    ultrasonic_deg: list[float] = field(default_factory=list)
    """Where the robot's ultrasonic sensors look (degrees from its heading), in ``Sensors.ranges`` order."""
    instance: str = ""
    """The attached node's liveliness instance: two processes claiming one id hear each other's answers on
    the id's key, and only the named one may take this as its own."""


@dataclass
class Received(Message):
    """Hub -> node: a frame the node's MAC received."""

    TYPE: ClassVar[str] = "received"
    psdu: bytes = b""
    rssi_dbm: float = 0.0
    lqi: int = 0
    start_us: int = 0
    end_us: int = 0
    submitted_us: int = 0


@dataclass
class TxDone(Message):
    """Hub -> node: the MAC result of a Transmit."""

    TYPE: ClassVar[str] = "tx_done"
    token: int = 0
    status: str = ""
    retries: int = 0
    backoffs: int = 0
    submitted_us: int = 0
    done_us: int = 0
    reason: str = ""


@dataclass
class Error(Message):
    """Hub -> node: a request the hub could not take, and why."""

    TYPE: ClassVar[str] = "error"
    token: int = 0
    reason: str = ""
    instance: str = ""
    """For a refused claim: the claimant's instance (the id's holder hears the refusal too, and ignores it)."""


@dataclass
class SetIrMode(Message):
    """Node -> hub: switch the IR module to ``idle``, ``receive`` or ``transmit`` (answered by Attached)."""

    TYPE: ClassVar[str] = "set_ir_mode"
    token: int = 0
    mode: str = "idle"


@dataclass
class IrSample(Message):
    """Hub -> node: one sweep of the 12 phototransistors, ADC counts as little-endian float32."""

    TYPE: ClassVar[str] = "ir_sample"
    readings: bytes = b""
    t_us: int = 0


@dataclass
class IrBeacons(Message):
    """Hub -> node in beacon mode: one sweep per coded beacon in sight, ``sources[i]`` lit ``readings[i]``
    (len(sources) x 12 little-endian float32 counts) read at its channel's AGC gain ``gains[i]`` (none: 1)."""

    TYPE: ClassVar[str] = "ir_beacons"
    sources: list[str] = field(default_factory=list)
    readings: bytes = b""
    t_us: int = 0
    gains: list[float] = field(default_factory=list)


@dataclass
class Drive(Message):
    """Robot -> hub: the motor command, in the robot's own frame (m/s, m/s, rad/s); not answered."""

    TYPE: ClassVar[str] = "drive"
    vx: float = 0.0
    vy: float = 0.0
    omega: float = 0.0


@dataclass
class Place(Message):
    """User -> hub: where the person is now and how they move (world frame); not answered."""

    TYPE: ClassVar[str] = "place"
    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0
    vx: float = 0.0
    vy: float = 0.0
    omega: float = 0.0


@dataclass
class Sensors(Message):
    """Hub -> robot: its own body's sensors: ultrasonic ranges (float32, NaN = no echo; sensor angles
    in ``Attached.ultrasonic_deg``), AHRS yaw (rad) and wheel odometry (vx, vy, omega in its frame)."""

    TYPE: ClassVar[str] = "sensors"
    t_us: int = 0
    ranges: bytes = b""
    yaw: float = 0.0
    odometry: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])


@dataclass
class LfBurst(Message):
    """Robot -> hub: fire one LF burst from the ``left`` or ``right`` antenna with a wake-up pattern and
    up to 4 bytes of user data; not answered (LF is one-way)."""

    TYPE: ClassVar[str] = "lf_burst"
    antenna: str = "left"
    pattern: int = 0
    data: bytes = b""


@dataclass
class LfHeard(Message):
    """Hub -> user: the belt's LF front end heard a burst (the belt decides whether its pattern wakes it)."""

    TYPE: ClassVar[str] = "lf_heard"
    antenna: str = "left"
    pattern: int = 0
    data: bytes = b""
    rssi_dbm: float = 0.0
    t_us: int = 0


@dataclass
class BleSend(Message):
    """Node -> hub: a BLE message to another node (robot <-> user wearables); not answered."""

    TYPE: ClassVar[str] = "ble_send"
    to: str = ""
    payload: bytes = b""


@dataclass
class BleReceived(Message):
    """Hub -> node: a BLE message from ``src``, after the link's latency."""

    TYPE: ClassVar[str] = "ble_received"
    src: str = ""
    payload: bytes = b""
    t_us: int = 0


@dataclass
class Telemetry(Message):
    """Robot -> hub: what the robot believes about its role, for viewers and run metrics (never for
    other robots: they learn only through the air). ``slot`` is its formation reference in the
    master's frame; not answered."""

    TYPE: ClassVar[str] = "telemetry"
    state: str = ""
    role: str = ""
    master: str = ""
    slot: list[float] | None = None
    mode: str = ""


@dataclass
class Relay(Message):
    """Node -> hub: carry ``body`` (msgpack) to node ``to``, or to the hub itself when ``to`` is ``hub``
    (``{"op": "stats"}``, ``{"op": "chaos", "request": {...}}``). The control channel of model and lockstep
    runs: it takes no model time and is not part of the emulated air."""

    TYPE: ClassVar[str] = "relay"
    to: str = ""
    body: bytes = b""


@dataclass
class Relayed(Message):
    """Hub -> node: a ``Relay`` body from node ``frm`` (``hub`` for the hub's own answers)."""

    TYPE: ClassVar[str] = "relayed"
    frm: str = ""
    body: bytes = b""
    bounced: bool = False
    """True when node ``frm`` does not exist: ``body`` is the sender's own, returned."""


@dataclass
class Idle(Message):
    """Node -> hub (lockstep): everything the hub sent up to message ``seen`` is handled and nothing is ready;
    the node's next timer is due at ``next_s`` (model seconds; None: no timer)."""

    TYPE: ClassVar[str] = "idle"
    seen: int = 0
    next_s: float | None = None


@dataclass
class Grant(Message):
    """Hub -> node (lockstep): model time is now ``at_s``: run what is due, then the messages that came with
    this grant (those sent before it), then say ``Idle``."""

    TYPE: ClassVar[str] = "grant"
    at_s: float = 0.0


_TYPES: dict[str, type[Message]] = {
    cls.TYPE: cls
    for cls in (
        Attach,
        Configure,
        Transmit,
        Detach,
        SetIrMode,
        Attached,
        Received,
        TxDone,
        Error,
        IrSample,
        IrBeacons,
        Drive,
        Place,
        Sensors,
        LfBurst,
        LfHeard,
        BleSend,
        BleReceived,
        Telemetry,
        Relay,
        Relayed,
        Idle,
        Grant,
    )
}


def encode_received(
    n: int, psdu: bytes, rssi_dbm: float, lqi: int, start_us: int, end_us: int, submitted_us: int
) -> bytes:
    """The bytes of ``Received(psdu=..., ..., n=n).encode()``, without building the message first: the hub sends
    one for every delivery (``test_wire`` holds the two equal)."""
    body = {
        "n": n,
        "psdu": psdu,
        "rssi_dbm": rssi_dbm,
        "lqi": lqi,
        "start_us": start_us,
        "end_us": end_us,
        "submitted_us": submitted_us,
        "v": WIRE_VERSION,
        "t": Received.TYPE,
    }
    return msgpack.packb(body, use_bin_type=True)


def encode_tx_done(
    n: int, token: int, status: str, retries: int, backoffs: int, submitted_us: int, done_us: int, reason: str
) -> bytes:
    """The bytes of ``TxDone(token=..., ..., n=n).encode()``, without building the message first (one per frame)."""
    body = {
        "n": n,
        "token": token,
        "status": status,
        "retries": retries,
        "backoffs": backoffs,
        "submitted_us": submitted_us,
        "done_us": done_us,
        "reason": reason,
        "v": WIRE_VERSION,
        "t": TxDone.TYPE,
    }
    return msgpack.packb(body, use_bin_type=True)


BATCH_MAX_PARTS = 256
"""Messages one batch carries at most (a sender splits a longer run)."""
_ARRAY_HEADS = frozenset((*range(0x90, 0xA0), 0xDC, 0xDD))
"""First bytes of a msgpack array: a batch (a message is a map)."""


def encode_batch(parts: list[bytes]) -> bytes:
    """Several encoded messages to one receiver in one transport message: a msgpack array of their bytes, in
    order. Each part stays a whole message with its own sequence number."""
    return msgpack.packb(parts, use_bin_type=True)


def is_batch(data: bytes) -> bool:
    """Whether ``data`` is a batch (``encode_batch``) rather than one message."""
    return bool(data) and data[0] in _ARRAY_HEADS


def split_batch(data: bytes, max_bytes: int = MAX_MESSAGE_BYTES) -> list[bytes]:
    """The encoded messages of a batch, in order; raises WireError unless ``data`` is an array of 1 to
    ``BATCH_MAX_PARTS`` byte strings, at most ``max_bytes`` long in all (each part is then decoded on its own)."""
    parts = _unpack(data, max_bytes, "batch")
    if not isinstance(parts, list) or not 0 < len(parts) <= BATCH_MAX_PARTS:
        raise WireError(f"a batch is a list of 1 to {BATCH_MAX_PARTS} messages")
    if not all(type(part) is bytes for part in parts):
        raise WireError("a batch holds encoded messages (bytes)")
    return parts


def decode_all(data: bytes) -> list[Message]:
    """The messages of one transport message, a batch's parts or the one message; raises WireError as
    ``split_batch`` and ``decode`` do (one bad part spoils the lot: for tools and tests, not a node)."""
    return [decode(part) for part in split_batch(data)] if is_batch(data) else [decode(data)]


def _unpack(data: bytes, max_bytes: int, what: str) -> Any:
    """msgpack's value of ``data``, its length checked before any parsing; WireError on anything else."""
    if len(data) > max_bytes:
        raise WireError(f"{what} of {len(data)} bytes exceeds {max_bytes}")
    try:
        return msgpack.unpackb(data, raw=False)
    except Exception as err:  # msgpack raises several unrelated types on garbage
        raise WireError(f"not msgpack ({type(err).__name__})") from None


def decode(data: bytes, max_bytes: int = MAX_MESSAGE_BYTES) -> Message:
    """Parse one message; raises WireError on anything but a well-formed, known, current message of at most
    ``max_bytes`` bytes."""
    body = _unpack(data, max_bytes, "message")
    if not isinstance(body, dict):
        raise WireError("message is not a map")
    if body.pop("v", None) != WIRE_VERSION:
        raise WireError(f"unsupported wire version (want {WIRE_VERSION})")
    kind = body.pop("t", None)
    cls = _TYPES.get(kind) if isinstance(kind, str) else None
    if cls is None:
        raise WireError("unknown message type")
    try:
        msg = cls(**body)
    except TypeError as err:
        raise WireError(f"bad {cls.TYPE} fields: {err}") from None
    return check(msg)


def check(msg: Message) -> Message:
    """``msg`` if its fields pass the checks ``decode`` makes (types, ranges, finite floats, sequence number
    and session key), else WireError: for a message handed over in memory without its bytes."""
    _check_types(msg)
    if not (0 <= msg.n <= SEQ_MAX and 0 <= msg.s <= SEQ_MAX):
        raise WireError(f"sequence number and session key are 0 to {SEQ_MAX}")
    return msg


_SCALARS: dict[str, tuple[type, ...]] = {
    "int": (int,),
    "str": (str,),
    "bytes": (bytes,),
    "float": (float, int),
    "bool": (bool,),
}


_LIST_LENGTHS = {"position": (2,), "slot": (2,), "odometry": (3,), "gains": range(1025)}
"""Lengths of the fixed-size number lists, and of the gains (one per beacon in sight); any other number list
holds at most 64 values."""


def _check_types(msg: Message) -> None:
    for name, ok in _field_checks(type(msg)):
        value: Any = getattr(msg, name)
        if not ok(value):
            raise WireError(f"{msg.TYPE}.{name} has the wrong type ({type(value).__name__})")


@functools.cache
def _field_checks(cls: type[Message]) -> tuple[tuple[str, Callable[[Any], bool]], ...]:
    """Per field of a message type, a test of its value made once from ``_checks``: every message a node or
    the hub receives is checked, field by field."""
    return tuple(
        (name, _value_check(nullable, kind, accepted, lengths))
        for name, nullable, kind, accepted, lengths in _checks(cls)
    )


def _value_check(nullable: bool, kind: int, accepted: tuple[type, ...], lengths: Any) -> Callable[[Any], bool]:
    """The test of one field: the type rules of ``_checks``, with the plain types msgpack decodes to tried first."""
    if kind == _STRINGS:

        def ok(value: Any) -> bool:
            return isinstance(value, list) and (
                _STR.issuperset(map(type, value)) or all(isinstance(v, str) for v in value)
            )

    elif kind == _NUMBERS:

        def ok(value: Any) -> bool:
            return isinstance(value, list) and len(value) in lengths and _numbers(value)

    else:
        want_bool = kind == _BOOL
        plain = {t for t in (int, float, str, bytes) if t in accepted and not want_bool}
        if want_bool:
            plain.add(bool)

        def ok(value: Any) -> bool:
            kind_of = type(value)
            if kind_of in plain:  # an exact type the field takes: only its range is left to check
                return _in_range(value)
            return isinstance(value, accepted) and want_bool == isinstance(value, bool) and _in_range(value)

    if not nullable:
        return ok
    return lambda value: value is None or ok(value)


_STRINGS, _NUMBERS, _BOOL, _SCALAR = range(4)
_PLAIN_NUMBERS = frozenset((int, float))
_STR = frozenset((str,))
_FLOAT = frozenset((float,))


@functools.cache
def _checks(cls: type[Message]) -> tuple[tuple[str, bool, int, tuple[type, ...], Any], ...]:
    """Per field of a message type: its name, whether None is allowed, what kind of value it takes, the
    scalar types accepted and the lengths a number list may have (worked out once, not per message)."""
    checks = []
    for f in fields(cls):
        annotation = str(f.type)
        base = annotation.split(" |")[0]
        if base == "list[str]":
            kind = _STRINGS
        elif base.startswith("list"):
            kind = _NUMBERS
        else:
            kind = _BOOL if base == "bool" else _SCALAR
        lengths = _LIST_LENGTHS.get(f.name, range(65))
        checks.append((f.name, "None" in annotation, kind, _SCALARS.get(base, (object,)), lengths))
    return tuple(checks)


def _numbers(values: list[Any]) -> bool:
    """Every value an int or a float in range, and none a bool."""
    kinds = set(map(type, values))
    if not _PLAIN_NUMBERS.issuperset(kinds):  # msgpack decodes to these two: anything else is wrong
        return False
    if kinds == _FLOAT:  # the common case (odometry, gains): one C-level pass instead of a call per value
        return all(map(math.isfinite, values))
    return all(map(_in_range, values))


def _in_range(value: Any) -> bool:
    """A float is finite, an int fits msgpack's range; anything else passes (its type was checked)."""
    if type(value) is float:
        return math.isfinite(value)
    if type(value) is int:
        return INT_MIN <= value <= INT_MAX
    return True
