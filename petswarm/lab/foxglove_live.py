"""A run streamed live to Foxglove: ``petswarm run ... --foxglove [PORT]`` and ``petswarm watch --foxglove``.

A Foxglove WebSocket server (foxglove-sdk, protocol ``foxglove.websocket.v1``) carries the channels of
``petswarm.lab.foxglove_channels``, the ones ``petswarm export --mcap`` writes, while the run goes:

- the world channels from the hub's world frames, taken from ``petswarm watch``'s ``LiveFeed``: it follows the hub
  over zenoh (wall and lockstep clocks), and a model-time run offers it the frames its environment makes (there is
  no hub to follow);
- the events and the air's frames from the run record as its processes write it (``RecordTail``): they are nowhere
  else outside the processes. They are streamed once model time 0 is known, from the first world frame.

Every message goes out at the run's model time, as in the MCAP file.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import struct
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from petswarm.lab.foxglove_channels import MissingExtra, RunChannels, require_sdk

if TYPE_CHECKING:
    from petswarm.lab.watch import WatchOptions

POLL_S = 0.2
"""How often the record is looked at for new events and frames (wall seconds)."""
DEFAULT_PORT = 8765
"""Foxglove's own default port for a WebSocket connection."""
_PCAP_HEADER = 24
_PCAP_RECORD = struct.Struct("<IIII")
"""The capture's record header: the hub writes classic pcap, little-endian, microseconds (radio_hub/air/pcap.py)."""


class StreamUnavailable(RuntimeError):
    """The Foxglove server cannot listen where asked (a port taken, an address not ours)."""


@dataclass
class RecordTail:
    """What a run record gained since the last look: complete event lines per node, complete pcap records.

    A line or record still being written is left for the next look."""

    path: Path
    _offsets: dict[Path, int] = field(default_factory=dict)

    def new_events(self) -> list[tuple[str, dict[str, Any]]]:
        """(node, event) of every event line written since the last call, file by file."""
        found = []
        for file in sorted((self.path / "events").glob("*.jsonl")):
            for line in self._new_bytes(file, b"\n").splitlines():
                with contextlib.suppress(json.JSONDecodeError, UnicodeDecodeError):
                    event = json.loads(line)
                    if isinstance(event, dict):
                        found.append((file.stem, event))
        return found

    def new_frames(self) -> list[tuple[int, bytes]]:
        """(stamp in microseconds, PSDU) of every frame captured since the last call."""
        file = self.path / "air.pcap"
        start = self._offsets.get(file, _PCAP_HEADER)
        try:
            with file.open("rb") as capture:
                capture.seek(start)
                data = capture.read()
        except OSError:
            return []
        frames, at = [], 0
        while at + _PCAP_RECORD.size <= len(data):
            sec, usec, captured, _ = _PCAP_RECORD.unpack_from(data, at)
            end = at + _PCAP_RECORD.size + captured
            if end > len(data):
                break
            frames.append((sec * 1_000_000 + usec, bytes(data[at + _PCAP_RECORD.size : end])))
            at = end
        self._offsets[file] = start + at
        return frames

    def _new_bytes(self, file: Path, end: bytes) -> bytes:
        """The bytes of ``file`` past the last call's, up to its last ``end``."""
        start = self._offsets.get(file, 0)
        try:
            with file.open("rb") as source:
                source.seek(start)
                data = source.read()
        except OSError:
            return b""
        cut = data.rfind(end) + 1
        self._offsets[file] = start + cut
        return data[:cut]


class FoxgloveLive:
    """A Foxglove WebSocket server with a run's channels; ``world_frame`` and ``poll`` feed it (from any thread)."""

    def __init__(self, port: int = DEFAULT_PORT, host: str = "127.0.0.1", record: Path | None = None) -> None:
        """Serve on ``host:port`` (0: any free port, then ``port`` says which); ``record``: the run directory whose
        events and frames ``poll`` streams. StreamUnavailable when the port cannot be had; MissingExtra without
        the SDK."""
        fox = require_sdk()
        from foxglove.websocket import Capability

        self.context = fox.Context()
        try:
            self.server = fox.start_server(
                name="petswarm", host=host, port=port, context=self.context, capabilities=[Capability.Time]
            )
        except RuntimeError as err:  # the SDK says a taken port as a RuntimeError of its own
            raise StreamUnavailable(f"cannot serve on {host}:{port}: {err}") from None
        self.channels = RunChannels(self.context)
        self.tail: RecordTail | None = None
        self.epoch_us: int | None = None
        """The wall stamp of model time 0: the first world frame says it."""
        self.latest_ns = 0
        self._lock = threading.Lock()
        if record is not None:
            self.follow(record)

    @property
    def port(self) -> int:
        """The port the server listens on."""
        return int(self.server.port)

    def follow(self, record: Path) -> None:
        """Stream the events and frames of this run record as they are written; its robots' radio channels are
        made now, from its manifest (``RunChannels.declare_robots``)."""
        try:
            robots = json.loads((record / "manifest.json").read_text())["options"]["robots"]
        except (OSError, ValueError, KeyError, TypeError):
            robots = 0  # not written yet (watch started first): each channel is made when its robot shows
        with self._lock:
            if isinstance(robots, int) and not isinstance(robots, bool):
                self.channels.declare_robots(robots)
            self.tail = RecordTail(record)

    def world_frame(self, frame: dict[str, Any]) -> None:
        """One checked world frame (``LiveFeed``'s listeners get them)."""
        with self._lock:
            if self.epoch_us is None:
                self.epoch_us = round(frame["wall"] * 1e6) - frame["t_us"]
            t_ns = frame["t_us"] * 1000
            self.channels.world_frame(frame, t_ns)
            self._now(t_ns)

    def poll(self) -> None:
        """Stream what the record gained: events and frames (nothing until model time 0 is known)."""
        if self.tail is None or self.epoch_us is None:
            return
        with self._lock:
            epoch_us = self.epoch_us
            for node, event in self.tail.new_events():
                t = event.get("t")
                if isinstance(t, int | float) and not isinstance(t, bool):
                    self.channels.event(node, event, max(round(t * 1e6) - epoch_us, 0) * 1000)
            for stamp_us, psdu in self.tail.new_frames():
                self.channels.air_frame(psdu, max(stamp_us - epoch_us, 0) * 1000)

    def _now(self, t_ns: int) -> None:
        if t_ns > self.latest_ns:
            self.latest_ns = t_ns
            self.server.broadcast_time(t_ns)  # Foxglove's clock follows model time, not the viewer's

    def close(self) -> None:
        """Stream what is left in the record, then stop the server."""
        self.poll()
        self.channels.close()
        self.server.stop()


class RunStream:
    """``petswarm run --foxglove``: the live server of a run in this process, fed on a thread of its own.

    With a hub (``endpoint``), ``LiveFeed`` follows it there; a model-time run calls ``offer`` with each world state
    its environment makes. The record is polled on that thread in both cases."""

    def __init__(self, port: int, world: str, endpoint: str | None = None) -> None:
        from petswarm.lab.watch import LiveFeed

        self.live = FoxgloveLive(port)
        self.feed = LiveFeed(endpoint or "memory", world)
        self.feed.listeners.append(self.live.world_frame)
        self._endpoint = endpoint
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="foxglove-live", daemon=True)
        self._thread.start()

    @property
    def port(self) -> int:
        """The server's port."""
        return self.live.port

    def follow(self, record: Path, say: Callable[[str], None]) -> None:
        """Stream the events and frames of this run record as they are written (``FoxgloveLive.follow``), then
        ``say`` where to connect: by then every channel of the run's robots is there."""
        self.live.follow(record)
        say(f"foxglove: ws://127.0.0.1:{self.port} (open it in Foxglove: Open connection, Foxglove WebSocket)")

    def offer(self, state: dict[str, Any]) -> None:
        """A world state made in this process (a model-time run's environment)."""
        self.feed.offer(state)

    def _serve(self) -> None:
        asyncio.run(self._main())

    async def _main(self) -> None:
        follower = asyncio.create_task(self.feed.run()) if self._endpoint is not None else None
        try:
            while not self._stopping.is_set():
                self.live.poll()
                await asyncio.sleep(POLL_S)
        finally:
            if follower is not None:
                follower.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await follower

    def close(self) -> None:
        """Stop following, stream the rest of the record, stop the server."""
        self._stopping.set()
        self._thread.join(timeout=10)
        self.feed.close()
        self.live.close()


def watch_command(args: WatchOptions) -> int:
    """``petswarm watch --foxglove``: the page of ``petswarm watch`` and a Foxglove server, both live from the hub
    (``--record``: the run's record, whose events and frames are streamed too); 2 on a bad request or port."""
    from petswarm.lab.watch import LiveFeed, serve_page

    if args.replay:
        print("petswarm watch: --foxglove streams a live run; for a record use petswarm export", file=sys.stderr)
        return 2
    try:
        live = FoxgloveLive(args.foxglove, args.bind, Path(args.record) if args.record else None)
    except (MissingExtra, StreamUnavailable) as err:
        print(f"petswarm watch: --foxglove: {err}", file=sys.stderr)
        return 2
    try:
        feed = LiveFeed(args.hub, args.world)
        feed.listeners.append(live.world_frame)
        shown = "127.0.0.1" if args.bind in ("0.0.0.0", "") else args.bind
        print(f"watch: foxglove ws://{shown}:{live.port}", flush=True)
        return serve_page(feed, args.bind, args.port, also=lambda: _poll_forever(live))
    finally:
        live.close()


async def _poll_forever(live: FoxgloveLive) -> None:
    while True:
        live.poll()
        await asyncio.sleep(POLL_S)


def start_stream(port: int | None, world: str, endpoint: str | None) -> RunStream | None:
    """A run's live stream when ``port`` is given (None: none), serving before the run makes its record (then
    ``RunStream.follow`` it). StreamUnavailable when the port cannot be had."""
    return None if port is None else RunStream(port, world, endpoint)
