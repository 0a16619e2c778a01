"""The Foxglove export's parts that need no run: frames decoded and put on their sender's channel, model time 0 of
a record, the record followed as it is written, and the one-line errors (no record, no SDK, a taken port)."""

from __future__ import annotations

import json
import socket
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader

from cli.main import main
from petswarm.lab.foxglove_channels import AirState, describe_frame, summarise_payload
from petswarm.lab.foxglove_live import RecordTail
from petswarm.lab.mcap_export import export_mcap, read_record
from petswarm.managers.messages import Ping
from radio_hub.air.mac import Frame, FrameType
from radio_hub.air.pcap import PcapWriter
from radio_hub.values import MODEL_EPOCH_S

PAN = 0x1000


def _data(src: int, dst: int, seq: int, payload: bytes = b"", ack: bool = True) -> bytes:
    return Frame(FrameType.DATA, seq, PAN, dst, PAN, src, payload, ack_request=ack).encode()


def _ack(seq: int) -> bytes:
    return Frame(FrameType.ACK, seq).encode()


def test_an_ack_goes_to_the_node_it_answers_and_a_bad_frame_to_unknown() -> None:
    air = AirState()
    ping = Ping(nonce=1234).encode()
    node, body = describe_frame(_data(2, 0xFFFF, 1, ping, ack=False), air)
    assert node == "robot-2" and body["mac"]["broadcast"] and body["payload"]["message"] == "Ping"
    assert body["payload"]["fields"] == {"nonce": 1234}
    assert describe_frame(_data(1, 3, 5), air)[0] == "robot-1"
    assert describe_frame(_data(2, 4, 6), air)[0] == "robot-2"
    # the ACKs answer robot 3 (seq 5) and robot 4 (seq 6): they are theirs, whatever order they come in
    assert describe_frame(_ack(6), air)[0] == "robot-4"
    node, body = describe_frame(_ack(5), air)
    assert (node, body["mac"]["type"], body["sent_so_far"]) == ("robot-3", "ack", 1)
    assert describe_frame(_ack(5), air)[0] == "unknown"  # answered already: a duplicate ACK has no known sender
    corrupted = bytearray(_data(1, 3, 9))
    corrupted[-1] ^= 0xFF
    node, body = describe_frame(bytes(corrupted), air)
    assert node == "unknown" and not body["valid"] and "FCS" in body["error"]
    assert (air.frames, air.acks, air.broadcasts, air.undecodable) == (7, 3, 1, 1)
    assert air.sent == {"robot-2": 2, "robot-1": 1, "robot-4": 1, "robot-3": 1, "unknown": 2}


def test_a_payload_that_is_no_swarm_message_is_said_so() -> None:
    assert summarise_payload(b"\xc1garbage") == {"bytes": 8, "message": "undecoded"}


def _record(tmp: Path, clock: str, events: list[dict[str, object]], frames: list[tuple[bytes, int]]) -> Path:
    (tmp / "events").mkdir(parents=True)
    (tmp / "manifest.json").write_text(json.dumps({"seed": 1, "world": "w", "options": {"clock": clock}}))
    (tmp / "events" / "robot-1.jsonl").write_text("".join(json.dumps(e) + "\n" for e in events) + '{"t": 1')
    with PcapWriter(tmp / "air.pcap") as pcap:
        for data, ts_us in frames:
            pcap.write(data, ts_us)
    return tmp


def test_model_time_0_is_the_epoch_of_model_clocks_and_the_earliest_stamp_of_a_wall_run_without_world(
    tmp_path: Path,
) -> None:
    epoch_us = round(MODEL_EPOCH_S * 1e6)
    events = [{"t": MODEL_EPOCH_S + 0.5, "kind": "start"}, {"t": MODEL_EPOCH_S + 2.25, "kind": "stop"}]
    model = read_record(_record(tmp_path / "model", "lockstep", events, [(_data(1, 2, 1), epoch_us + 1_000_000)]))
    assert [t for t, _, _ in model.events] == [500_000_000, 2_250_000_000]
    assert [t for t, _ in model.air] == [1_000_000_000]
    assert model.dropped == {"air": 0}  # the line cut short by a kill is no event
    wall_events = [{"t": 1_795_000_010.25, "kind": "start"}, {"t": 1_795_000_013.0, "kind": "stop"}]
    wall = read_record(_record(tmp_path / "wall", "wall", wall_events, [(_data(1, 2, 1), 1_795_000_010_000_000)]))
    assert [t for t, _, _ in wall.events] == [250_000_000, 3_000_000_000]
    assert [t for t, _ in wall.air] == [0]
    assert "earliest stamp" in wall.time_origin


def test_export_writes_the_record_streams_and_metadata(tmp_path: Path) -> None:
    epoch_us = round(MODEL_EPOCH_S * 1e6)
    events = [{"t": MODEL_EPOCH_S + 0.5, "kind": "start"}, {"t": MODEL_EPOCH_S + 1.5, "kind": "retry", "step": "x"}]
    frames = [(_data(1, 2, 1), epoch_us + 1_000_000), (_ack(1), epoch_us + 1_001_000)]
    record = _record(tmp_path / "run", "model", events, frames)
    result = export_mcap(record, tmp_path / "run.mcap")
    assert result.counts == {"/log": 2, "/radio/robot-1": 1, "/radio/robot-2": 1, "/counters/air": 2}
    with (tmp_path / "run.mcap").open("rb") as stream:
        reader = make_reader(stream)
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        times = [(channel.topic, message.log_time) for _, channel, message in reader.iter_messages(log_time_order=True)]
    assert metadata["manifest"]["world"] == "w" and json.loads(metadata["manifest"]["seed"]) == 1
    assert "summary" not in metadata  # the record has none (a run killed outright before its first)
    assert times[0] == ("/log", 500_000_000) and times[-1] == ("/log", 1_500_000_000)


def test_the_tail_of_a_record_holds_back_what_is_still_being_written(tmp_path: Path) -> None:
    (tmp_path / "events").mkdir()
    events = tmp_path / "events" / "robot-1.jsonl"
    events.write_text('{"t": 1, "kind": "a"}\n{"t": 2, "ki')
    pcap_path = tmp_path / "air.pcap"
    writer = PcapWriter(pcap_path)
    writer.write(_data(1, 2, 1), 10)
    tail = RecordTail(tmp_path)
    assert tail.new_events() == [("robot-1", {"t": 1, "kind": "a"})]
    assert tail.new_events() == []
    with events.open("a") as more:
        more.write('nd": "b"}\n')
    assert tail.new_events() == [("robot-1", {"t": 2, "kind": "b"})]
    frame = _data(2, 1, 2)
    with pcap_path.open("ab") as raw:  # a record whose bytes have not all reached the file yet
        raw.write((0).to_bytes(4, "little") + (20).to_bytes(4, "little") + len(frame).to_bytes(4, "little") * 2)
        raw.write(frame[:5])
    assert tail.new_frames() == [(10, _data(1, 2, 1))]
    with pcap_path.open("ab") as raw:
        raw.write(frame[5:])
    assert tail.new_frames() == [(20, frame)]
    writer.close()


def test_bad_input_gets_one_line_and_status_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["export", str(tmp_path), "--mcap", str(tmp_path / "x.mcap")]) == 2
    assert capsys.readouterr().err == f"petswarm export: {tmp_path} is not a run record (no manifest.json)\n"
    record = _record(tmp_path / "run", "model", [], [])
    (tmp_path / "taken.mcap").write_text("")
    assert main(["export", str(record), "--mcap", str(tmp_path / "taken.mcap")]) == 2
    assert "exists (--force replaces it)" in capsys.readouterr().err
    assert main(["export", str(record), "--mcap", str(tmp_path / "taken.mcap"), "--force"]) == 0


def test_without_the_sdk_the_error_names_the_extra(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(sys.modules, "foxglove", None)  # as if foxglove-sdk were not installed
    record = _record(tmp_path / "run", "model", [], [])
    assert main(["export", str(record), "--mcap", str(tmp_path / "x.mcap")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pip install 'petswarm[foxglove]'" in err
    assert main(["run", "--robots", "1", "--duration", "1", "--clock", "model", "--foxglove"]) == 2
    assert "pip install 'petswarm[foxglove]'" in capsys.readouterr().err
    assert main(["watch", "--foxglove", "--port", "0"]) == 2
    assert "pip install 'petswarm[foxglove]'" in capsys.readouterr().err


def test_a_taken_port_gets_one_line_and_status_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = str(taken.getsockname()[1])
        assert main(["watch", "--foxglove", port, "--port", "0"]) == 2
        assert capsys.readouterr().err.startswith(f"petswarm watch: --foxglove: cannot serve on 127.0.0.1:{port}")


LAYOUT = Path(__file__).resolve().parents[2] / "docs" / "foxglove" / "petswarm-layout.json"


def test_the_layout_opens_channels_and_fields_the_export_has() -> None:
    from petswarm.lab import foxglove_channels as fc

    layout = json.loads(LAYOUT.read_text())
    panels = layout["configById"]
    schemas = {
        fc.TOPIC_COUNTERS: fc.COUNTERS_SCHEMA,
        fc.TOPIC_AIR_COUNTERS: fc.AIR_COUNTERS_SCHEMA,
        fc.TOPIC_IR_FIXES: fc.IR_FIX_SCHEMA,
        fc.TOPIC_IR_MODES: fc.IR_MODES_SCHEMA,
    }
    kinds = {name.split("!")[0] for name in panels}
    assert {"3D", "Plot", "RosOut", "RawMessages"} <= kinds
    shown = [t for name, c in panels.items() if name.startswith("3D!") for t in c["topics"]]
    assert set(shown) <= set(fc.FIXED_TOPICS) and fc.TOPIC_SCENE in shown
    for config in panels.values():
        for path in config.get("paths", []):
            topic, field = path["value"].split(".", 1)
            assert field in schemas[topic]["properties"], path
        if "topicToRender" in config:
            assert config["topicToRender"] == fc.TOPIC_LOG
        if "topicPath" in config:
            assert config["topicPath"] == fc.radio_topic("robot-1")

    def leaves(node: object) -> list[str]:
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(node["second"])  # type: ignore[index]

    assert sorted(leaves(layout["layout"])) == sorted(panels)
