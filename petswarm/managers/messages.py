"""Robot-to-robot messages carried in 802.15.4 frame payloads.

Each message is a compact msgpack array ``[version, type, ...fields]`` that fits one frame. Unknown
types and malformed payloads raise ``MessageError``; the receiver counts and ignores them.
"""

from __future__ import annotations

import enum
from dataclasses import astuple, dataclass
from typing import ClassVar

import msgpack

MESSAGE_VERSION = 1


class MessageError(ValueError):
    """A payload that is not a valid swarm message."""


class MessageType(enum.IntEnum):
    """Type codes on the wire (one byte in msgpack)."""

    PING = 1
    PONG = 2
    BLOB = 3
    SCAN = 10
    SCAN_REPLY = 11
    JOIN_QUERY = 12
    JOIN_AVAILABLE = 13
    JOIN_UNAVAILABLE = 14
    JOIN_NOTICE = 15
    NOT_PARTICIPATING = 16
    JOINED = 17
    ROSTER = 18
    DISPERSE = 19
    DISPERSED = 20
    IR_START = 30
    IR_START_ACK = 31
    TOKEN = 32
    TOKEN_ACK = 33
    SYNC = 34
    HEADING = 35
    DRIVE_STATE = 40
    MASTER_HANDOVER = 41
    HANDOVER_ACCEPTED = 42


@dataclass(frozen=True)
class SwarmMessage:
    """Base of every message; subclasses set TYPE and declare their fields in wire order."""

    TYPE: ClassVar[MessageType]

    def encode(self) -> bytes:
        """The frame payload."""
        return msgpack.packb([MESSAGE_VERSION, int(self.TYPE), *astuple(self)], use_bin_type=True)

    @property
    def session_id(self) -> int | None:
        """The organizing session a message belongs to (None for messages outside any session)."""
        return getattr(self, "session", None)


@dataclass(frozen=True)
class Ping(SwarmMessage):
    """Are you there? Answered by a unicast Pong with the same nonce."""

    TYPE: ClassVar[MessageType] = MessageType.PING
    nonce: int


@dataclass(frozen=True)
class Pong(SwarmMessage):
    """Answer to a Ping."""

    TYPE: ClassVar[MessageType] = MessageType.PONG
    nonce: int


@dataclass(frozen=True)
class Blob(SwarmMessage):
    """Filler of a chosen size, for exercising the air (collisions, long frames)."""

    TYPE: ClassVar[MessageType] = MessageType.BLOB
    tag: int
    filler: bytes


class Refusal(enum.IntEnum):
    """Why a waiting robot answers joining-unavailable (Table 1, plus being taken by another master)."""

    CONNECTED_TO_USER = 1
    OUTSIDE_REGION = 2
    BUSY = 3


@dataclass(frozen=True)
class Scan(SwarmMessage):
    """Master -> everyone on the channel (broadcast PAN): who is around, and on which PAN?"""

    TYPE: ClassVar[MessageType] = MessageType.SCAN
    session: int
    user: int
    slot_ms: int
    """0: answer at once (the paper's protocol); otherwise answer in the slot of your address."""


@dataclass(frozen=True)
class ScanReply(SwarmMessage):
    """Robot -> master: my state (a ``RobotState`` code), my PAN and my user (0: none)."""

    TYPE: ClassVar[MessageType] = MessageType.SCAN_REPLY
    session: int
    state: int
    pan_id: int
    user: int


@dataclass(frozen=True)
class JoinQuery(SwarmMessage):
    """Master -> waiting robots: may you join? ``pending`` lists who should answer (empty: all)."""

    TYPE: ClassVar[MessageType] = MessageType.JOIN_QUERY
    session: int
    user: int
    min_rssi_dbm: int
    """The available region: a robot is inside when it hears the master at least this strongly."""
    slot_ms: int
    """0: answer at once (the paper's protocol); otherwise answer in your slot of ``pending``."""
    pending: tuple[int, ...]


@dataclass(frozen=True)
class JoinAvailable(SwarmMessage):
    """Robot -> master: I can join; how strongly I hear you (dBm)."""

    TYPE: ClassVar[MessageType] = MessageType.JOIN_AVAILABLE
    session: int
    rssi_dbm: int


@dataclass(frozen=True)
class JoinUnavailable(SwarmMessage):
    """Robot -> master: I cannot join, and why (a ``Refusal`` code)."""

    TYPE: ClassVar[MessageType] = MessageType.JOIN_UNAVAILABLE
    session: int
    reason: int


@dataclass(frozen=True)
class JoinNotice(SwarmMessage):
    """Master -> selected robot: switch to ``pan_id``; the swarm has ``members`` robots, you are ``number``."""

    TYPE: ClassVar[MessageType] = MessageType.JOIN_NOTICE
    session: int
    pan_id: int
    members: int
    number: int
    slot_ms: int
    key: bytes = b""
    """With link security: the swarm's key (802.15.4 key index 2), handed over in the join handshake inside a
    frame secured with the network key. Left out of the payload when empty, so a plain notice is as before."""

    def encode(self) -> bytes:
        """The frame payload (without the key field when there is no key)."""
        fields = astuple(self)
        return msgpack.packb(
            [MESSAGE_VERSION, int(self.TYPE), *(fields if self.key else fields[:-1])], use_bin_type=True
        )


@dataclass(frozen=True)
class NotParticipating(SwarmMessage):
    """Master -> robot: you are not (or no longer) part of this swarm; return to waiting."""

    TYPE: ClassVar[MessageType] = MessageType.NOT_PARTICIPATING
    session: int


@dataclass(frozen=True)
class Joined(SwarmMessage):
    """Member -> master, sent on the new PAN: I have switched."""

    TYPE: ClassVar[MessageType] = MessageType.JOINED
    session: int
    number: int


@dataclass(frozen=True)
class Roster(SwarmMessage):
    """Master -> swarm PAN, periodically: the members (short addresses, by member number from 1)."""

    TYPE: ClassVar[MessageType] = MessageType.ROSTER
    session: int
    members: tuple[int, ...]


@dataclass(frozen=True)
class Disperse(SwarmMessage):
    """Master -> members: the swarm is over; return to waiting on your original PAN."""

    TYPE: ClassVar[MessageType] = MessageType.DISPERSE
    session: int
    slot_ms: int


@dataclass(frozen=True)
class Dispersed(SwarmMessage):
    """Member -> master: I am leaving the swarm."""

    TYPE: ClassVar[MessageType] = MessageType.DISPERSED
    session: int


@dataclass(frozen=True)
class IrStart(SwarmMessage):
    """Token holder -> swarm: the transmission-start sign of round ``round``; switch to receive."""

    TYPE: ClassVar[MessageType] = MessageType.IR_START
    session: int
    round: int


@dataclass(frozen=True)
class IrStartAck(SwarmMessage):
    """Member -> holder: receiving."""

    TYPE: ClassVar[MessageType] = MessageType.IR_START_ACK
    session: int
    round: int


@dataclass(frozen=True)
class Token(SwarmMessage):
    """Holder -> swarm at its deadline: I have stopped transmitting; ``next`` transmits in the next round."""

    TYPE: ClassVar[MessageType] = MessageType.TOKEN
    session: int
    round: int
    next: int


@dataclass(frozen=True)
class TokenAck(SwarmMessage):
    """Member -> holder: token heard (and my measurement of you is done)."""

    TYPE: ClassVar[MessageType] = MessageType.TOKEN_ACK
    session: int
    round: int


@dataclass(frozen=True)
class Sync(SwarmMessage):
    """Holder -> swarm after the token exchange: round ``round`` belongs to ``holder`` from now."""

    TYPE: ClassVar[MessageType] = MessageType.SYNC
    session: int
    round: int
    holder: int


@dataclass(frozen=True)
class Heading(SwarmMessage):
    """Neighbour -> transmitting robot: my heading, in hundredths of a degree."""

    TYPE: ClassVar[MessageType] = MessageType.HEADING
    session: int
    centideg: int


@dataclass(frozen=True)
class DriveState(SwarmMessage):
    """Master -> all members, every 100 ms while driving (paper 3.5): the master's speed and the user's
    activity, so slaves react to the user at once; plus what the formation needs (mode, shape, spacing,
    the master's AHRS yaw and where the user is in the master's frame). Speeds in m/s and rad/s."""

    TYPE: ClassVar[MessageType] = MessageType.DRIVE_STATE
    session: int
    seq: int
    vx: float
    vy: float
    omega: float
    yaw: float
    movement: int
    user_rate: float
    """The belt's yaw rate while the user rotates, else 0."""
    mode: str
    shape: str
    spacing: float
    user_x: float
    user_y: float
    mirrored: int
    """1 when Table 3's No-change column put the slots on the master's other side."""
    kept: int
    """1 after a master handover (Table 3's Change column): every robot keeps the place it had, so the
    references are each robot's own kept slots (``formation_shapes.kept_slots``), not the shape's list."""


@dataclass(frozen=True)
class MasterHandover(SwarmMessage):
    """Old master -> new master (unicast, answered by ``HandoverAccepted``), then -> swarm (broadcast): from
    now on ``chain[0]`` is the master and ``chain[1:]`` the members by number. What the new master needs to
    drive: the new ``mode``, the formation (``shape``, ``spacing``, the old layout's ``mirrored`` and ``kept``
    flags, from which every robot turns its slot into the new master's frame) and the user's node id
    (``owner``), whose belt the old master re-pairs with the new one."""

    TYPE: ClassVar[MessageType] = MessageType.MASTER_HANDOVER
    session: int
    pan_id: int
    chain: tuple[int, ...]
    mode: str
    shape: str
    spacing: float
    mirrored: int
    kept: int
    owner: str


@dataclass(frozen=True)
class HandoverAccepted(SwarmMessage):
    """New master -> old master: I have taken the master's role."""

    TYPE: ClassVar[MessageType] = MessageType.HANDOVER_ACCEPTED
    session: int


_BY_TYPE: dict[int, type[SwarmMessage]] = {
    int(c.TYPE): c
    for c in (
        Ping,
        Pong,
        Blob,
        Scan,
        ScanReply,
        JoinQuery,
        JoinAvailable,
        JoinUnavailable,
        JoinNotice,
        NotParticipating,
        Joined,
        Roster,
        Disperse,
        Dispersed,
        IrStart,
        IrStartAck,
        Token,
        TokenAck,
        Sync,
        Heading,
        DriveState,
        MasterHandover,
        HandoverAccepted,
    )
}
_FIELD_TYPES: dict[str, type | tuple[type, ...]] = {"int": int, "bytes": bytes, "str": str, "float": (int, float)}


def decode(payload: bytes) -> SwarmMessage:
    """Parse a payload; raises MessageError on anything but a known message of this version."""
    try:
        items = msgpack.unpackb(payload, raw=False)
    except Exception as err:  # msgpack raises several unrelated types on garbage
        raise MessageError(f"not msgpack ({type(err).__name__})") from None
    if not isinstance(items, list) or len(items) < 2:
        raise MessageError("not a message array")
    version, code, *values = items
    if version != MESSAGE_VERSION:
        raise MessageError(f"unsupported message version {version!r}")
    cls = _BY_TYPE.get(code) if isinstance(code, int) else None
    if cls is None:
        raise MessageError(f"unknown message type {code!r}")
    names = [(f, t) for f, t in cls.__annotations__.items() if f != "TYPE"]
    if cls is JoinNotice and len(values) == len(names) - 1:
        names = names[:-1]  # a notice without a key (no link security)
    if len(values) != len(names):
        raise MessageError(f"{cls.__name__} needs {len(names)} fields, got {len(values)}")
    checked = []
    for (name, annotation), value in zip(names, values, strict=True):
        if str(annotation) == "tuple[int, ...]":
            ok = isinstance(value, list) and all(_is_int(v) for v in value)
            value = tuple(value) if ok else value
        else:
            ok = isinstance(value, _FIELD_TYPES.get(str(annotation), object)) and not isinstance(value, bool)
        if not ok:
            raise MessageError(f"{cls.__name__}.{name} has the wrong type")
        checked.append(value)
    return cls(*checked)


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)
