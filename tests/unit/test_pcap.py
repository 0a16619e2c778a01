"""pcap export: the file format, the medium's hand-over of every PSDU, and the hub's and CLI's option."""

from __future__ import annotations

import io
import struct
from pathlib import Path

import pytest

from radio_hub.air.mac import ACK_PSDU_LEN, Frame, FrameType
from radio_hub.air.medium import Transmission
from radio_hub.air.pcap import (
    LINKTYPE_IEEE802_15_4_WITHFCS,
    PCAP_MAGIC,
    PCAP_MAGIC_NS,
    SNAPLEN,
    PcapWriter,
    parse_pcap,
    read_pcap,
)
from radio_hub.shell.hub import RadioHub

from .helpers import PAN, data, medium, place, run_to_idle

T0_US = 1_700_000_000_123_456


def test_global_header_is_classic_pcap_with_the_802_15_4_fcs_link_type(tmp_path: Path) -> None:
    path = tmp_path / "air.pcap"
    PcapWriter(path).close()
    raw = path.read_bytes()
    assert len(raw) == 24
    assert raw[:4] == bytes.fromhex("d4c3b2a1")  # 0xa1b2c3d4 little-endian: microsecond timestamps
    magic, major, minor, zone, sigfigs, snaplen, linktype = struct.unpack("<IHHiIII", raw)
    assert (magic, major, minor, zone, sigfigs) == (PCAP_MAGIC, 2, 4, 0, 0)
    assert snaplen == SNAPLEN == 65535
    assert linktype == LINKTYPE_IEEE802_15_4_WITHFCS == 195
    header = read_pcap(path).header
    assert (header.magic, header.version, header.snaplen, header.linktype) == (PCAP_MAGIC, (2, 4), 65535, 195)
    assert not header.nanoseconds and not header.big_endian


def test_records_round_trip_with_timestamps_and_valid_fcs(tmp_path: Path) -> None:
    frames = [
        Frame(FrameType.DATA, 1, PAN, 0xFFFF, PAN, 1, b"ping"),
        Frame(FrameType.DATA, 2, PAN, 2, PAN, 1, b"x" * 100, ack_request=True),
        Frame(FrameType.ACK, 2),
        Frame(FrameType.DATA, 3, 0xFFFF, 7, PAN, 2, b""),  # inter-PAN: carries the source PAN
    ]
    stamps = [T0_US, T0_US + 999_999, T0_US + 1_000_000, T0_US + 4_000_001]
    path = tmp_path / "air.pcap"
    with PcapWriter(path) as writer:
        for frame, ts in zip(frames, stamps, strict=True):
            writer.write(frame.encode(), ts)
        assert writer.records == 4
    read = read_pcap(path)
    assert not read.truncated
    assert [r.ts_us for r in read.records] == stamps
    assert [r.data for r in read.records] == [f.encode() for f in frames]
    assert all(r.orig_len == len(r.data) for r in read.records)
    assert [Frame.decode(r.data) for r in read.records] == frames  # decode checks the FCS
    assert len(read.records[2].data) == ACK_PSDU_LEN


def test_every_record_is_on_disk_before_the_writer_closes(tmp_path: Path) -> None:
    # a hub killed outright loses at most the record it was writing
    path = tmp_path / "air.pcap"
    writer = PcapWriter(path)
    psdu = data(1, payload=b"hello")
    writer.write(psdu, T0_US)
    assert [r.data for r in read_pcap(path).records] == [psdu]
    writer.write(psdu, T0_US + 1)
    assert len(read_pcap(path).records) == 2
    writer.close()
    assert writer.closed


def test_a_record_cut_short_is_left_out_and_reported(tmp_path: Path) -> None:
    stream = io.BytesIO()
    writer = PcapWriter(stream)
    for seq in range(3):
        writer.write(data(1, seq=seq), T0_US + seq)
    writer.close()
    whole = stream.getvalue()
    assert len(parse_pcap(whole).records) == 3
    cut = parse_pcap(whole[:-3])
    assert cut.truncated and len(cut.records) == 2
    in_header = parse_pcap(whole[: len(whole) - len(data(1, seq=2)) - 16 + 5])  # 5 bytes of the last header
    assert in_header.truncated and len(in_header.records) == 2


def test_reader_takes_big_endian_and_nanosecond_files() -> None:
    psdu = data(3, payload=b"be")
    header = struct.pack(">IHHiIII", PCAP_MAGIC_NS, 2, 4, 0, 0, 256, 195)
    record = struct.pack(">IIII", 1_700_000_000, 123_456_789, len(psdu), len(psdu)) + psdu
    read = parse_pcap(header + record)
    assert read.header.big_endian and read.header.nanoseconds and read.header.snaplen == 256
    assert read.records[0].ts_us == 1_700_000_000_123_456
    assert read.records[0].data == psdu


def test_reader_refuses_what_is_not_pcap() -> None:
    with pytest.raises(ValueError, match="not a pcap file"):
        parse_pcap(b"\x0a\x0d\x0d\x0a" + bytes(40))  # pcapng's magic
    with pytest.raises(ValueError, match="24-byte header"):
        parse_pcap(b"\xd4\xc3\xb2\xa1")


def test_writer_refuses_a_timestamp_before_the_epoch() -> None:
    with pytest.raises(ValueError, match="before 1970"):
        PcapWriter(io.BytesIO()).write(data(1), -1)


def test_medium_hands_over_every_transmission_with_its_psdu_once_decided() -> None:
    ended: list[tuple[Transmission, dict[str, str]]] = []
    m = medium()
    m.on_air_end = lambda tx: ended.append((tx, {k: v.value for k, v in tx.outcomes.items()}))
    a, b = place(m, 1, 0.0), place(m, 2, 1.0)
    unicast = data(1, dst=2, payload=b"unicast", seq=42)
    broadcast = data(2, payload=b"broadcast", seq=43)
    run_to_idle(m, m.submit(a, unicast, token=1, now_us=0))
    run_to_idle(m, m.submit(b, broadcast, token=2, now_us=m.now_us))
    assert [tx.psdu for tx, _ in ended] == [unicast, Frame(FrameType.ACK, 42).encode(), broadcast]
    assert [tx.frame.frame_type for tx, _ in ended] == [FrameType.DATA, FrameType.ACK, FrameType.DATA]
    assert [tx for tx, _ in ended] == list(m.air_log)
    assert all(tx.psdu_len == len(tx.psdu) for tx, _ in ended)
    # the outcomes are final when the hand-over happens, the ACK's at its sender included
    assert [outcomes for _, outcomes in ended] == [{b: "delivered"}, {a: "delivered"}, {a: "delivered"}]
    assert ended[1][0].sender == b and ended[1][0].start_us > ended[0][0].end_us


def test_hub_writes_each_ended_transmission_stamped_at_wall_start_plus_model_start(tmp_path: Path) -> None:
    path = tmp_path / "hub.pcap"
    hub = RadioHub("tcp/127.0.0.1:0", "w", pcap_path=path)  # never opened: no zenoh needed
    m = hub.medium
    a, _ = place(m, 1, 0.0), place(m, 2, 1.0)
    psdu = data(1, dst=2, payload=b"to two", seq=5)
    run_to_idle(m, m.submit(a, psdu, token=1, now_us=250_000))
    hub.close()
    read = read_pcap(path)
    assert read.header.linktype == 195
    assert [r.data for r in read.records] == [psdu, Frame(FrameType.ACK, 5).encode()]
    assert [r.ts_us for r in read.records] == [hub.env.wall_epoch_us + tx.start_us for tx in m.air_log]
    assert hub.stats()["pcap"] == {"path": str(path), "records": 2, "error": ""}


def test_hub_without_pcap_reports_none_and_sets_no_callback() -> None:
    hub = RadioHub("tcp/127.0.0.1:0", "w")
    assert hub.medium.on_air_end is None
    assert "pcap" not in hub.stats()


def test_hub_refuses_a_pcap_file_it_cannot_open(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from cli.main import main

    missing = tmp_path / "no-such-dir" / "air.pcap"
    with pytest.raises(OSError):
        RadioHub("tcp/127.0.0.1:0", "w", pcap_path=missing)
    assert main(["hub", "--listen", "tcp/127.0.0.1:1", "--pcap", str(missing)]) == 2
    err = capsys.readouterr().err
    assert "cannot open --pcap file" in err and str(missing) in err


def test_run_passes_pcap_to_its_hub() -> None:
    from cli.main import build_parser

    args = build_parser().parse_args(["run", "--pcap", "out.pcap"])
    assert args.pcap == "out.pcap"
    assert build_parser().parse_args(["hub", "--pcap", "h.pcap"]).pcap == "h.pcap"
