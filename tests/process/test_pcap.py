"""``petswarm hub --pcap``: a real hub process writes the air's frames to a pcap file Wireshark reads."""

from __future__ import annotations

import shutil
import subprocess
import time
from pathlib import Path
from typing import Any

import pytest

from radio_hub.air.mac import Frame, FrameError, FrameType
from radio_hub.air.pcap import LINKTYPE_IEEE802_15_4_WITHFCS, PcapFile, read_pcap

pytestmark = pytest.mark.process


def _decode(read: PcapFile) -> list[Frame]:
    frames = []
    for record in read.records:
        try:
            frames.append(Frame.decode(record.data))  # checks the FCS
        except FrameError as err:
            raise AssertionError(f"record {record} is not a valid frame: {err}") from err
    return frames


def _pinged_pair(make_air: Any, pcap: Path) -> tuple[Any, list[dict[str, Any]]]:
    air = make_air(hub_args=["--pcap", str(pcap)])
    air.robot(1, (0.0, 0.0))
    air.robot(2, (1.5, 0.0))
    for rid, other in ((1, 2), (2, 1)):
        assert {r["from"] for r in air.cmd(rid, "ping", wait=0.5)["replies"]} == {other}
        unicast = air.cmd(rid, "ping", dst=other, wait=0.5)
        assert unicast["tx"]["status"] == "success"  # acknowledged: an ACK frame was on the air
    return air, air.air_log()


def test_hub_writes_every_frame_on_the_air_to_pcap_and_a_killed_hub_leaves_them_readable(make_air, tmp_path):
    pcap = tmp_path / "air.pcap"
    started_s = time.time()
    air, air_log = _pinged_pair(make_air, pcap)
    # SIGKILL, no clean close: every record was flushed as it was written
    air.sup.stop([n for n in air.sup.children if n != "hub"])
    air.session.close()
    hub = air.sup.children["hub"]
    hub.kill()
    assert hub.wait(5) < 0
    air.sup.stop_all()
    ended_s = time.time()

    read = read_pcap(pcap)
    assert read.header.linktype == LINKTYPE_IEEE802_15_4_WITHFCS
    assert not read.truncated
    frames = _decode(read)
    # the file holds what the hub's air log holds, in the same order (robots stopping may add a few frames)
    assert len(air_log) < 4096 and len(frames) >= len(air_log)
    assert [len(r.data) for r in read.records[: len(air_log)]] == [t["psdu_len"] for t in air_log]
    assert [f.frame_type.name.lower() for f in frames[: len(air_log)]] == [t["type"] for t in air_log]
    data = [f for f in frames if f.frame_type == FrameType.DATA]
    assert {f.src for f in data} >= {1, 2}
    assert sum(f.frame_type == FrameType.ACK for f in frames) >= 2
    assert all(started_s - 1 <= r.ts_us / 1e6 <= ended_s + 1 for r in read.records)  # wall-clock stamps


def test_tshark_reads_the_hubs_pcap_as_802_15_4(make_air, tmp_path):
    tshark = shutil.which("tshark")
    if tshark is None:
        pytest.skip("tshark is not installed (apt-get install tshark); the pcap format itself is tested without it")
    pcap = tmp_path / "air.pcap"
    air, _ = _pinged_pair(make_air, pcap)
    assert set(air.close().values()) == {0}
    frames = _decode(read_pcap(pcap))
    fields = ["-e", "wpan.frame_type", "-e", "wpan.src16", "-e", "wpan.fcs_ok"]
    result = subprocess.run(
        [tshark, "-n", "-r", str(pcap), "-T", "fields", *fields],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    rows = [line.split("\t") for line in result.stdout.splitlines()]
    assert len(rows) == len(frames)
    assert [int(kind, 0) for kind, _, _ in rows] == [int(f.frame_type) for f in frames]
    sources = {int(src, 0) for _, src, _ in rows if src}
    assert sources >= {1, 2}
    assert sources == {f.src for f in frames if f.frame_type == FrameType.DATA}
    assert {ok for _, _, ok in rows} == {"1"}  # Wireshark checked every FCS and found it good
