"""IEEE 802.15.4 MAC frames: the bytes that go on the emulated air.

Frames are real MAC frames (frame control, sequence number, addressing with short addresses, payload,
FCS), so their size on air is exact and a frame log can later be written as pcap. Pure code, no I/O.
"""

from __future__ import annotations

import binascii
import enum
import struct
from dataclasses import dataclass

MAX_PSDU = 127
"""aMaxPHYPacketSize: the largest PSDU (MAC header + payload + FCS) a PHY carries."""
BROADCAST = 0xFFFF
"""Broadcast short address and broadcast PAN ID."""
FCS_LEN = 2
_FC_ADDR_SHORT = 2


class FrameType(enum.IntEnum):
    """The frame-type field of the frame control word."""

    BEACON = 0
    DATA = 1
    ACK = 2
    COMMAND = 3


class FrameError(ValueError):
    """A PSDU that is not a valid frame, or a frame that cannot be sent."""


_BIT_REVERSED = bytes(int(f"{byte:08b}"[::-1], 2) for byte in range(256))
"""Each byte with its bits in reverse order."""


def fcs(data: bytes) -> int:
    """The 802.15.4 frame check sequence (CRC-16/KERMIT) of ``data``.

    KERMIT is CRC-CCITT (polynomial 0x1021, initial value 0) with every byte fed least significant bit first
    and the result reflected; ``binascii.crc_hqx`` is the same CRC fed most significant bit first. So the
    bytes are reversed bitwise, run through ``crc_hqx`` in C, and its result reversed: a per-byte loop in
    Python cost the hub more than the rest of a frame's decoding (``test_mac`` holds it to the bitwise
    definition)."""
    if not isinstance(data, bytes | bytearray):
        data = bytes(data)
    crc = binascii.crc_hqx(data.translate(_BIT_REVERSED), 0)
    return _BIT_REVERSED[crc & 0xFF] << 8 | _BIT_REVERSED[crc >> 8]


@dataclass(frozen=True, slots=True)
class Frame:
    """One MAC frame. Data frames use short addresses; ACK frames carry only the sequence number."""

    frame_type: FrameType
    seq: int
    dst_pan: int = BROADCAST
    dst: int = BROADCAST
    src_pan: int = BROADCAST
    src: int = BROADCAST
    payload: bytes = b""
    ack_request: bool = False
    secured: bool = False
    """Security Enabled (802.15.4-2011 clause 9): the payload field starts with the auxiliary security header and
    ends with the MIC (``radio_hub.air.security``); such a frame is frame version 1."""

    @property
    def is_broadcast(self) -> bool:
        """True when addressed to every node (0xFFFF)."""
        return self.dst == BROADCAST

    @property
    def pan_compressed(self) -> bool:
        """Intra-PAN frames omit the source PAN ID (PAN ID compression)."""
        return self.dst_pan == self.src_pan

    def header(self) -> bytes:
        """The MAC header (MHR) as it goes on the air, without the payload field (of a secured frame: without the
        auxiliary security header, which leads the payload field)."""
        if self.frame_type == FrameType.ACK:
            return struct.pack("<HB", int(FrameType.ACK), self.seq & 0xFF)
        fc = int(self.frame_type) | _FC_ADDR_SHORT << 10 | _FC_ADDR_SHORT << 14
        fc |= (1 << 5) if self.ack_request else 0
        fc |= (1 << 6) if self.pan_compressed else 0
        fc |= (1 << 3 | 1 << 12) if self.secured else 0  # Security Enabled; frame version 1 (2006 and later)
        header = struct.pack("<HBHH", fc, self.seq & 0xFF, self.dst_pan, self.dst)
        if not self.pan_compressed:
            header += struct.pack("<H", self.src_pan)
        return header + struct.pack("<H", self.src)

    def encode(self) -> bytes:
        """The PSDU: MAC header, payload and FCS. Raises FrameError when over 127 bytes."""
        body = self.header() if self.frame_type == FrameType.ACK else self.header() + self.payload
        if len(body) + FCS_LEN > MAX_PSDU:
            raise FrameError(
                f"PSDU of {len(body) + FCS_LEN} bytes exceeds the 802.15.4 limit of {MAX_PSDU} "
                f"(payload {len(self.payload)} bytes; at most {max_payload(self.pan_compressed)})"
            )
        return body + struct.pack("<H", fcs(body))

    @classmethod
    def decode(cls, psdu: bytes) -> Frame:
        """Parse a PSDU; raises FrameError on a bad length, FCS or addressing mode."""
        if len(psdu) > MAX_PSDU:
            raise FrameError(f"PSDU of {len(psdu)} bytes exceeds the 802.15.4 limit of {MAX_PSDU}")
        if len(psdu) < 5:
            raise FrameError(f"PSDU of {len(psdu)} bytes is shorter than any frame")
        body = psdu[:-FCS_LEN]
        if fcs(body) != _U16.unpack_from(psdu, len(psdu) - FCS_LEN)[0]:
            raise FrameError("bad FCS")
        fc, seq = _FC_SEQ.unpack_from(body)
        frame_type = _FRAME_TYPES[fc & 0x7]
        if frame_type is None:
            raise FrameError(f"reserved frame type {fc & 0x7}")
        if frame_type is FrameType.ACK:
            return cls(FrameType.ACK, seq)
        if (fc >> 10) & 3 != _FC_ADDR_SHORT or (fc >> 14) & 3 != _FC_ADDR_SHORT:
            raise FrameError("only short addressing is supported")
        compressed = bool(fc & (1 << 6))
        header_len = 9 if compressed else 11
        if len(body) < header_len:
            raise FrameError("truncated MAC header")
        dst_pan, dst = _TWO_U16.unpack_from(body, 3)
        src_pan = dst_pan if compressed else _U16.unpack_from(body, 7)[0]
        (src,) = _U16.unpack_from(body, header_len - 2)
        payload = bytes(body[header_len:])
        return cls(frame_type, seq, dst_pan, dst, src_pan, src, payload, bool(fc & (1 << 5)), bool(fc & (1 << 3)))


_U16, _TWO_U16, _FC_SEQ = struct.Struct("<H"), struct.Struct("<HH"), struct.Struct("<HB")
_FRAME_TYPES: tuple[FrameType | None, ...] = (*FrameType, None, None, None, None)
"""Frame types by the frame control's low three bits (4-7 are reserved)."""


def max_payload(pan_compressed: bool = True) -> int:
    """The largest payload a short-addressed data frame can carry."""
    return MAX_PSDU - FCS_LEN - (9 if pan_compressed else 11)


ACK_PSDU_LEN = 5
"""Frame control (2), sequence number (1), FCS (2)."""


class TxStatus(enum.StrEnum):
    """The MAC's answer to a data request (MCPS-DATA.confirm); here, not in ``medium``, so a robot process
    that only reads the answer does not load the medium (numpy, propagation, chaos)."""

    SUCCESS = "success"
    NO_ACK = "no_ack"
    CHANNEL_ACCESS_FAILURE = "channel_access_failure"
    REFUSED = "refused"
