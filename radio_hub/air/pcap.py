"""pcap files of the emulated 802.15.4 air, for Wireshark and tshark.

Classic libpcap format (not pcapng): a 24-byte global header, then one record per frame, microsecond
timestamps, written little-endian. The link type is ``LINKTYPE_IEEE802_15_4_WITHFCS`` (195): each
record is a whole PSDU, MAC header to FCS, exactly the bytes the emulated air carried, so Wireshark
checks the FCS itself. Every record is flushed as it is written: a hub that is killed loses at most
the record it was writing (the OS keeps what was flushed; there is no fsync, which only a machine
crash would need and which would cost milliseconds per frame).

No zenoh and no clock here: the caller gives each record its timestamp.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import BinaryIO

PCAP_MAGIC = 0xA1B2C3D4
"""Classic pcap, microsecond timestamps."""
PCAP_MAGIC_NS = 0xA1B23C4D
"""Classic pcap, nanosecond timestamps (read, never written)."""
VERSION = (2, 4)
LINKTYPE_IEEE802_15_4_WITHFCS = 195
"""IEEE 802.15.4 frames with the 2-byte FCS at the end (the PSDU)."""
SNAPLEN = 65535
"""The conventional libpcap snapshot length; every PSDU (at most 127 bytes) is captured whole."""

_HEADER = struct.Struct("<IHHiIII")
_RECORD = struct.Struct("<IIII")


@dataclass(frozen=True, slots=True)
class PcapHeader:
    """The global header's fields."""

    magic: int
    version: tuple[int, int]
    thiszone: int
    sigfigs: int
    snaplen: int
    linktype: int
    nanoseconds: bool = False
    big_endian: bool = False


@dataclass(frozen=True, slots=True)
class PcapRecord:
    """One captured frame: its timestamp in microseconds since the Unix epoch and its bytes."""

    ts_us: int
    data: bytes
    orig_len: int


@dataclass(frozen=True, slots=True)
class PcapFile:
    """What ``read_pcap`` found. ``truncated`` is True when the file ends inside a record."""

    header: PcapHeader
    records: list[PcapRecord]
    truncated: bool = False


class PcapWriter:
    """Writes a pcap file of 802.15.4 PSDUs, one flushed record per ``write``.

    ``target`` is a path (created or truncated; OSError if it cannot be opened) or a binary stream
    the writer does not own. The global header is written and flushed at once, so even a file with no
    frames opens in Wireshark.
    """

    def __init__(
        self, target: str | Path | BinaryIO, linktype: int = LINKTYPE_IEEE802_15_4_WITHFCS, snaplen: int = SNAPLEN
    ) -> None:
        if isinstance(target, str | Path):
            self._file: BinaryIO = open(target, "wb")  # noqa: SIM115 - closed in close()
            self._owned = True
        else:
            self._file, self._owned = target, False
        self.snaplen = snaplen
        self.records = 0
        self._file.write(_HEADER.pack(PCAP_MAGIC, *VERSION, 0, 0, snaplen, linktype))
        self._file.flush()

    def write(self, data: bytes, ts_us: int) -> None:
        """Append one frame captured at ``ts_us`` (microseconds since the Unix epoch) and flush it."""
        if ts_us < 0:
            raise ValueError(f"pcap timestamp {ts_us} us is before 1970")
        captured = data[: self.snaplen]
        sec, usec = divmod(ts_us, 1_000_000)
        self._file.write(_RECORD.pack(sec, usec, len(captured), len(data)) + captured)
        self._file.flush()
        self.records += 1

    @property
    def closed(self) -> bool:
        """True once ``close`` has run (or the stream was closed by its owner)."""
        return self._file.closed

    def close(self) -> None:
        """Close the file if the writer opened it; otherwise just flush the stream."""
        if self._file.closed:
            return
        if self._owned:
            self._file.close()
        else:
            self._file.flush()

    def __enter__(self) -> PcapWriter:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


def parse_pcap(data: bytes) -> PcapFile:
    """Parse a classic pcap file's bytes (either byte order, micro- or nanosecond timestamps).

    Raises ValueError when the global header is missing or its magic is not pcap's. A record cut short
    at the end of the file (a writer killed mid-record) is left out and reported as ``truncated``.
    """
    if len(data) < _HEADER.size:
        raise ValueError(f"a pcap file starts with a {_HEADER.size}-byte header; got {len(data)} bytes")
    for order in "<>":
        (magic,) = struct.unpack_from(order + "I", data)
        if magic in (PCAP_MAGIC, PCAP_MAGIC_NS):
            break
    else:
        raise ValueError(f"not a pcap file (magic {data[:4].hex()})")
    _, major, minor, zone, sigfigs, snaplen, linktype = struct.unpack_from(order + "IHHiIII", data)
    nanoseconds = magic == PCAP_MAGIC_NS
    header = PcapHeader(magic, (major, minor), zone, sigfigs, snaplen, linktype, nanoseconds, order == ">")
    records: list[PcapRecord] = []
    offset = _HEADER.size
    while offset + _RECORD.size <= len(data):
        sec, frac, incl_len, orig_len = struct.unpack_from(order + "IIII", data, offset)
        body_at = offset + _RECORD.size
        if body_at + incl_len > len(data):
            return PcapFile(header, records, truncated=True)
        ts_us = sec * 1_000_000 + (frac // 1000 if nanoseconds else frac)
        records.append(PcapRecord(ts_us, bytes(data[body_at : body_at + incl_len]), orig_len))
        offset = body_at + incl_len
    return PcapFile(header, records, truncated=offset != len(data))


def read_pcap(path: str | Path) -> PcapFile:
    """Read a classic pcap file; see ``parse_pcap``."""
    return parse_pcap(Path(path).read_bytes())
