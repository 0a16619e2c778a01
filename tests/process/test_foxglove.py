"""Foxglove: ``petswarm export --mcap`` of a wall-clock, a model-time and a lockstep record, read back with the
``mcap`` reader; and the live server of ``petswarm run --foxglove`` and ``petswarm watch --foxglove``, with a real
WebSocket client subscribed during the run.

One short scenario (tests/data/foxglove-short.toml: 3 robots organize, follow their user past a post, disperse)
gives every stream a record holds: world log, events (IR fixes among them) and the air's frames. The counts the
MCAP file must hold are taken from the record here, independently of the exporter."""

from __future__ import annotations

import asyncio
import json
import re
import subprocess
import sys
import threading
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader

from petswarm.lab.processes import Supervisor
from radio_hub.air.mac import Frame, FrameType
from radio_hub.air.pcap import read_pcap

from .foxglove_client import SUBPROTOCOLS, Received, listen

pytestmark = [pytest.mark.process, pytest.mark.long]

SCENARIO = Path(__file__).resolve().parents[1] / "data" / "foxglove-short.toml"
DURATION_S = 11
SEED = 3
ROBOTS = ("robot-1", "robot-2", "robot-3")
WORLD_TOPICS = ("/world/scene", "/world/tf", "/world/counters")
LIVE_TOPICS = (*WORLD_TOPICS, "/log", "/counters/air", "/ir/modes", "/ir/fixes", "/ir/fix_scene")


def _petswarm(*args: str) -> list[str]:
    return [sys.executable, "-m", "cli", *args]


class Run:
    """``petswarm run SCENARIO --foxglove 0`` in the background: its record, its live server's URL, its output."""

    def __init__(self, tmp: Path, clock: str) -> None:
        self.record = tmp / f"run-{clock}"
        self.err_file = tmp / f"run-{clock}.err"
        argv = _petswarm("run", str(SCENARIO), "--seed", str(SEED), "--clock", clock, "--record", str(self.record))
        with self.err_file.open("w") as err:
            self.proc = subprocess.Popen([*argv, "--foxglove", "0", "--json"], stdout=subprocess.PIPE, stderr=err)
        self.url = self._wait_for(r"foxglove: (ws://\S+)").group(1)
        self._stdout = b""
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        self._stdout = self.proc.stdout.read()

    def _wait_for(self, pattern: str) -> re.Match[str]:
        for _ in range(600):
            found = re.search(pattern, self.err_file.read_text())
            if found:
                return found
            if self.proc.poll() is not None:
                break
            threading.Event().wait(0.1)
        self.proc.kill()
        raise AssertionError(f"no {pattern!r} from petswarm run:\n{self.err_file.read_text()}")

    def hub(self) -> tuple[str, str]:
        """(world, hub endpoint) from the run's first line."""
        line = self._wait_for(r"world (\S+), seed \d+, hub on (\S+),")
        return line.group(1), line.group(2)

    def ended(self) -> bool:
        """The run's process has exited."""
        return self.proc.poll() is not None

    def finish(self) -> dict[str, Any]:
        """The run's JSON summary once it ends (it must succeed)."""
        code = self.proc.wait(timeout=180)
        self._reader.join(timeout=10)
        assert code == 0, self.err_file.read_text()[-3000:]
        return json.loads(self._stdout)


def _listen_during(run: Run, *urls: str, seconds: float = 120) -> list[Received]:
    """Clients on ``urls`` at once, each until its server closes, ``run`` ends or ``seconds`` pass."""

    async def together() -> list[Received]:
        return list(await asyncio.gather(*(listen(url, seconds, until=run.ended) for url in urls)))

    return asyncio.run(together())


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    """The three runs, each with its live server; clients follow the wall-clock run's (and a ``petswarm watch
    --foxglove`` beside it, on the same hub) and the lockstep run's while they go."""
    tmp = tmp_path_factory.mktemp("foxglove")
    found: dict[str, Any] = {}
    sup = Supervisor(tmp / "logs")
    try:
        wall = Run(tmp, "wall")
        world, endpoint = wall.hub()
        where = ["--hub", endpoint, "--world", world, "--port", "0"]
        sup.spawn("watch", ["watch", *where, "--foxglove", "0", "--record", str(wall.record)])
        watch_url = _watch_url(sup)
        found["wall_live"], found["watch_live"] = _listen_during(wall, wall.url, watch_url)
        found["wall"] = wall.finish()
        sup.stop(["watch"])
        lockstep = Run(tmp, "lockstep")
        (found["lockstep_live"],) = _listen_during(lockstep, lockstep.url)
        found["lockstep"] = lockstep.finish()
        model = Run(tmp, "model")  # done before a client could follow it: its stream is checked by its digest
        found["model"] = model.finish()
        found["records"] = {"wall": wall.record, "lockstep": lockstep.record, "model": model.record}
        found["tmp"] = tmp
        yield found
    finally:
        sup.stop_all()


def _watch_url(sup: Supervisor) -> str:
    for _ in range(300):
        assert not sup.dead(), sup.log_tail("watch")
        found = re.search(r"watch: foxglove (ws://\S+)", sup.log_tail("watch"))
        if found:
            return found.group(1)
        threading.Event().wait(0.1)
    raise AssertionError("petswarm watch --foxglove did not start:\n" + sup.log_tail("watch"))


def expected_counts(record: Path) -> dict[str, int]:
    """What every topic must hold, counted from the record itself: the world log's lines, the events' lines, the
    capture's frames (by the node that sent them: a data frame's source, an ACK's the data frame it answers)."""
    frames = [json.loads(line) for line in (record / "world.jsonl").read_text().splitlines() if line.strip()]
    events = [
        json.loads(line) for file in (record / "events").glob("*.jsonl") for line in file.read_text().splitlines()
    ]
    capture = read_pcap(record / "air.pcap")
    assert not capture.truncated
    fixes = sum(e["kind"] == "ir_fix" for e in events)
    counts = {topic: len(frames) for topic in WORLD_TOPICS}
    counts["/ir/modes"] = sum(any(b["ir"] in ("transmit", "beacon") for b in f["bodies"]) for f in frames)
    counts.update({"/log": len(events), "/ir/fixes": fixes, "/ir/fix_scene": fixes})
    counts["/counters/air"] = len(capture.records)
    senders: Counter[str] = Counter()
    waiting: dict[int, int] = {}
    for rec in capture.records:
        frame = Frame.decode(rec.data)
        if frame.frame_type == FrameType.ACK:
            senders[f"robot-{waiting.pop(frame.seq)}" if frame.seq in waiting else "unknown"] += 1
            continue
        if frame.ack_request and not frame.is_broadcast:
            waiting[frame.seq] = frame.dst
        senders[f"robot-{frame.src}"] += 1
    counts.update({f"/radio/{node}": n for node, n in senders.items()})
    for robot in ROBOTS:
        counts.setdefault(f"/radio/{robot}", 0)
    return counts


def read_mcap(path: Path) -> tuple[dict[str, int], dict[str, dict[str, str]], dict[str, list[Any]]]:
    """(messages per topic, metadata by name, per topic the log times and first JSON messages) as ``mcap`` reads
    the file."""
    with path.open("rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        counts = {
            channel.topic: summary.statistics.channel_message_counts.get(channel.id, 0)
            for channel in summary.channels.values()
        }
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        seen: dict[str, list[Any]] = {}
        for schema, channel, message in reader.iter_messages():
            entry = seen.setdefault(channel.topic, [])
            body = json.loads(message.data) if schema is not None and schema.encoding == "jsonschema" else None
            entry.append((message.log_time, body))
    return counts, metadata, seen


def _export(record: Path, out: Path) -> dict[str, Any]:
    done = subprocess.run(
        _petswarm("export", str(record), "--mcap", str(out), "--json"), capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


@pytest.mark.parametrize("clock", ["wall", "model", "lockstep"])
def test_export_holds_every_channel_with_the_records_counts(runs: dict[str, Any], clock: str) -> None:
    record = runs["records"][clock]
    out = runs["tmp"] / f"{clock}.mcap"
    said = _export(record, out)
    counts, metadata, seen = read_mcap(out)
    expected = expected_counts(record)
    assert counts == expected
    assert said["counts"] == {topic: n for topic, n in expected.items() if n}
    assert expected["/ir/fixes"] > 0 and expected["/radio/robot-1"] > 0 and expected["/ir/modes"] > 0
    # the manifest and summary ride along as metadata, each top-level key a JSON value
    assert json.loads(metadata["manifest"]["seed"]) == SEED
    assert json.loads(metadata["summary"]["ok"]) is True
    assert metadata["manifest"]["world"] == runs[clock]["world"]
    # log times are the run's model time (a world frame's exactly its t_us), not the wall clock's epoch: they end
    # with the world, at the scenario's end in model time and lockstep (a wall-clock hub's time runs from its own
    # start, a second or so before the scenario's)
    frames = [json.loads(line) for line in (record / "world.jsonl").read_text().splitlines() if line.strip()]
    times = [t for entries in seen.values() for t, _ in entries]
    assert min(times) >= 0 and max(times) <= frames[-1]["t_us"] * 1000 + 10**9
    world_times = [t for t, _ in seen["/world/counters"]]
    if clock == "wall":  # model time 0 comes from the world log's wall stamps, rounded to 0.1 ms there
        assert all(abs(t - f["t_us"] * 1000) <= 100_000 for t, f in zip(world_times, frames, strict=True))
    else:
        assert world_times == [f["t_us"] * 1000 for f in frames]
        assert max(times) == DURATION_S * 10**9
    # each node's channel carries its own frames: every data frame's source is that node
    for topic, entries in seen.items():
        if topic.startswith("/radio/robot-"):
            node_id = int(topic.rsplit("-", 1)[1])
            data = [body for _, body in entries if body["mac"]["type"] != "ack"]
            assert all(int(body["mac"]["src"], 16) == node_id for body in data)
            assert [body["sent_so_far"] for _, body in entries] == list(range(1, len(entries) + 1))
    kinds = {body["payload"]["message"] for _, body in seen["/radio/robot-1"] if "payload" in body}
    assert {"Scan", "JoinQuery"} <= kinds, kinds


def test_model_and_lockstep_exports_agree_and_the_stream_leaves_the_run_alone(runs: dict[str, Any]) -> None:
    # both runs served a live stream: their digests are still the same run's
    assert runs["model"]["digest"] == runs["lockstep"]["digest"]
    model = expected_counts(runs["records"]["model"])
    assert model == expected_counts(runs["records"]["lockstep"])
    model_out, lockstep_out = runs["tmp"] / "model.mcap", runs["tmp"] / "lockstep.mcap"
    for clock, out in (("model", model_out), ("lockstep", lockstep_out)):
        if not out.exists():
            _export(runs["records"][clock], out)
    assert read_mcap(model_out)[2].keys() == read_mcap(lockstep_out)[2].keys()


@pytest.mark.parametrize("live", ["wall_live", "watch_live", "lockstep_live"])
def test_live_server_streams_the_advertised_channels_during_the_run(runs: dict[str, Any], live: str) -> None:
    got: Received = runs[live]
    assert got.subprotocol in SUBPROTOCOLS
    advertised = set(got.topics.values())
    assert set(LIVE_TOPICS) | {f"/radio/{r}" for r in ROBOTS} <= advertised
    # messages came on every channel the run has traffic for, each at model time
    received = {topic for topic, n in got.counts.items() if n}
    assert set(LIVE_TOPICS) | {f"/radio/{r}" for r in ROBOTS} <= received, json.dumps(got.counts)
    assert got.schemas["/world/scene"] == "foxglove.SceneUpdate"
    assert got.schemas["/log"] == "foxglove.Log"
    # at the run's model time: within its world log's span (a wall-clock hub's time runs from its own start, before
    # the scenario's, by however long a loaded machine takes to start the robots)
    record = runs["records"]["lockstep" if live == "lockstep_live" else "wall"]
    lines = (record / "world.jsonl").read_text().splitlines()
    end_ns = json.loads(lines[-1])["t_us"] * 1000 + 10**9
    times = [t for ts in got.log_times.values() for t in ts]
    assert min(times) >= 0 and max(times) <= end_ns
    radio = json.loads(got.first["/radio/robot-1"])
    assert radio["node"] == "robot-1" and radio["mac"]["src"] == "0x0001"
    assert "time" in got.server_info["capabilities"]  # type: ignore[operator]
    assert got.server_times and max(got.server_times) <= end_ns
