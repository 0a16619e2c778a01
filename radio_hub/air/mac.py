"""IEEE 802.15.4 MAC frames: the bytes that go on the emulated air.

Frames are real MAC frames (frame control, sequence number, addressing with short addresses, payload,
FCS), so their size on air is exact and a frame log can later be written as pcap. Pure code, no I/O.
"""

from __future__ import annotations

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


def _crc_table() -> list[int]:
    # ITU-T CRC-16 (poly x^16 + x^12 + x^5 + 1), reflected, as 802.15.4 specifies for the FCS.
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0x8408 if crc & 1 else crc >> 1
        table.append(crc)
    return table


_CRC_TABLE = _crc_table()


def fcs(data: bytes) -> int:
    """The 802.15.4 frame check sequence (CRC-16/KERMIT) of ``data``."""
    crc = 0
    for byte in data:
        crc = (crc >> 8) ^ _CRC_TABLE[(crc ^ byte) & 0xFF]
    return crc


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

    @property
    def is_broadcast(self) -> bool:
        """True when addressed to every node (0xFFFF)."""
        return self.dst == BROADCAST

    @property
    def pan_compressed(self) -> bool:
        """Intra-PAN frames omit the source PAN ID (PAN ID compression)."""
        return self.dst_pan == self.src_pan

    def encode(self) -> bytes:
        """The PSDU: MAC header, payload and FCS. Raises FrameError when over 127 bytes."""
        if self.frame_type == FrameType.ACK:
            body = struct.pack("<HB", int(FrameType.ACK), self.seq & 0xFF)
        else:
            fc = int(self.frame_type) | _FC_ADDR_SHORT << 10 | _FC_ADDR_SHORT << 14
            fc |= (1 << 5) if self.ack_request else 0
            fc |= (1 << 6) if self.pan_compressed else 0
            header = struct.pack("<HBHH", fc, self.seq & 0xFF, self.dst_pan, self.dst)
            if not self.pan_compressed:
                header += struct.pack("<H", self.src_pan)
            body = header + struct.pack("<H", self.src) + self.payload
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
        body, (crc,) = psdu[:-FCS_LEN], struct.unpack("<H", psdu[-FCS_LEN:])
        if fcs(body) != crc:
            raise FrameError("bad FCS")
        fc, seq = struct.unpack_from("<HB", body)
        try:
            frame_type = FrameType(fc & 0x7)
        except ValueError:
            raise FrameError(f"reserved frame type {fc & 0x7}") from None
        if frame_type == FrameType.ACK:
            return cls(FrameType.ACK, seq)
        if (fc >> 10) & 3 != _FC_ADDR_SHORT or (fc >> 14) & 3 != _FC_ADDR_SHORT:
            raise FrameError("only short addressing is supported")
        compressed = bool(fc & (1 << 6))
        header_len = 9 if compressed else 11
        if len(body) < header_len:
            raise FrameError("truncated MAC header")
        dst_pan, dst = struct.unpack_from("<HH", body, 3)
        src_pan = dst_pan if compressed else struct.unpack_from("<H", body, 7)[0]
        (src,) = struct.unpack_from("<H", body, header_len - 2)
        return cls(frame_type, seq, dst_pan, dst, src_pan, src, bytes(body[header_len:]), bool(fc & (1 << 5)))


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
