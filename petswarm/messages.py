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


@dataclass(frozen=True)
class SwarmMessage:
    """Base of every message; subclasses set TYPE and declare their fields in wire order."""

    TYPE: ClassVar[MessageType]

    def encode(self) -> bytes:
        """The frame payload."""
        return msgpack.packb([MESSAGE_VERSION, int(self.TYPE), *astuple(self)], use_bin_type=True)


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


_BY_TYPE: dict[int, type[SwarmMessage]] = {int(c.TYPE): c for c in (Ping, Pong, Blob)}
_FIELD_TYPES = {"int": int, "bytes": bytes, "str": str, "float": (int, float)}


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
    if len(values) != len(names):
        raise MessageError(f"{cls.__name__} needs {len(names)} fields, got {len(values)}")
    for (name, annotation), value in zip(names, values, strict=True):
        expected = _FIELD_TYPES.get(str(annotation), object)
        if not isinstance(value, expected) or isinstance(value, bool):
            raise MessageError(f"{cls.__name__}.{name} has the wrong type")
    return cls(*values)
