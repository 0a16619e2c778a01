"""``petswarm watch``: a local web page that draws the world as it moves, live from a hub or from a record.

One port serves both the page (plain HTTP GET ``/``) and its updates (a WebSocket on ``/ws``). Live, the
watcher subscribes to the hub's world frames (``petswarm/<world>/hub/world``) and passes every one on to
every open page; replaying, each page gets its own clock (play, pause, seek, speed) over the frames of a
run record's ``world.jsonl``. Frames are checked on the way in (petswarm/lab/watch_frames.py), so the page can
trust every field; a malformed one is counted and dropped.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import signal
import sys
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import msgpack
from websockets.asyncio.server import Server, ServerConnection, broadcast, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

from petswarm.lab.watch_frames import Replay, ReplayClock, check_frame, parse_replay, with_events_since
from radio_hub.interface import Keys, open_session
from radio_hub.values import HubUnavailable

PAGE = "watch_page.html"
REPLAY_TICK_S = 1 / 30
"""The replay clock is looked at 30 times a second: smoother than the hub's 10 frames/s, cheap for a page."""
HUB_RETRY_S = 1.0
"""How often a live watcher tries again to reach a hub that is not up yet."""


@dataclass
class WatchOptions:
    """What ``petswarm watch`` takes: a hub to watch live, or a record to replay; where to serve the page."""

    hub: str = "tcp/127.0.0.1:7447"
    world: str = "default"
    replay: str | None = None
    """A run record (its directory, or its world.jsonl) to replay instead of watching a hub."""
    port: int = 8047
    """Port of the page (0: any free one)."""
    bind: str = "127.0.0.1"
    foxglove: int | None = None
    """Also serve the hub's world to Foxglove on this port (0: any free one); None: no Foxglove server."""
    record: str | None = None
    """With ``foxglove``: also stream this run record's events and frames as its processes write them."""


def watch_command(args: WatchOptions) -> int:
    """Serve the page until Ctrl-C or SIGTERM; 2 when the replay cannot be read or the port is taken."""
    if args.replay:
        try:
            feed: LiveFeed | ReplayFeed = ReplayFeed(args.replay, load_replay(Path(args.replay)))
        except (OSError, ValueError) as err:
            print(f"petswarm watch: cannot replay {args.replay}: {err}", file=sys.stderr)
            return 2
    else:
        feed = LiveFeed(args.hub, args.world)
    return serve_page(feed, args.bind, args.port)


def serve_page(
    feed: LiveFeed | ReplayFeed, bind: str, port: int, also: Callable[[], Awaitable[None]] | None = None
) -> int:
    """Serve the page on ``bind:port`` with ``feed`` until Ctrl-C or SIGTERM (``also``: a coroutine to run beside
    the feed meanwhile); 2 when the port cannot be had."""
    try:
        return asyncio.run(_serve(feed, bind, port, also))
    except OSError as err:
        print(f"petswarm watch: cannot serve on {bind}:{port}: {err}", file=sys.stderr)
        return 2


def load_replay(path: Path) -> Replay:
    """The frames of a run record (its directory or its ``world.jsonl``); ValueError when it holds none."""
    file = path / "world.jsonl" if path.is_dir() else path
    if path.is_dir() and not file.exists() and (path / "manifest.json").exists():
        # a run without a world (the default run: robots pinging where they stand) writes no world log
        raise ValueError(
            f"{path} is a run record without a world log: only scenario runs (petswarm run SCENARIO) have one"
        )
    with file.open() as lines:
        replay = parse_replay(lines)
    if not replay.frames:
        raise ValueError(f"{file} holds no world frames ({replay.dropped} lines dropped)")
    return replay


def page_html() -> bytes:
    """The page, shipped as package data beside this module."""
    return resources.files("petswarm.lab").joinpath(PAGE).read_bytes()


async def _serve(
    feed: LiveFeed | ReplayFeed, bind: str, port: int, also: Callable[[], Awaitable[None]] | None = None
) -> int:
    page = page_html()

    def http(connection: ServerConnection, request: Request) -> Response | None:
        if request.path == "/ws":
            return None  # the WebSocket handshake goes on
        if request.path.split("?")[0] in ("/", "/index.html"):
            headers = Headers([("Content-Type", "text/html; charset=utf-8"), ("Cache-Control", "no-store")])
            headers["Content-Length"] = str(len(page))
            return Response(200, "OK", headers, page)
        return connection.respond(404, "petswarm watch serves / and /ws only\n")

    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        async with serve(feed.handle, bind, port, process_request=http) as server:
            feed.server = server
            print(f"watch: http://{_shown(bind)}:{_port_of(server)}/  ({feed.describe()})", flush=True)
            runner = asyncio.create_task(feed.run())
            beside = asyncio.create_task(also()) if also is not None else None
            await stop.wait()
            for task in (runner, beside):
                if task is not None:
                    task.cancel()
                    with contextlib.suppress(asyncio.CancelledError):
                        await task
    finally:
        feed.close()
    return 0


def _port_of(server: Server) -> int:
    return int(next(iter(server.sockets)).getsockname()[1])


def _shown(bind: str) -> str:
    return "127.0.0.1" if bind in ("0.0.0.0", "") else bind


def _message(kind: str, **body: Any) -> str:
    return json.dumps({"type": kind, **body}, separators=(",", ":"))


class LiveFeed:
    """The hub's world frames, passed on to every open page as they come."""

    def __init__(self, endpoint: str, world: str) -> None:
        self.endpoint = endpoint
        self.keys = Keys(world)
        self.server: Server | None = None
        self.latest: dict[str, Any] | None = None
        self.malformed = 0
        self.status = f"waiting for the hub at {endpoint}"
        self.listeners: list[Callable[[dict[str, Any]], None]] = []
        """Who else gets every checked frame (a Foxglove server, petswarm/lab/foxglove_live.py)."""
        self._session: Any = None
        self._loop: asyncio.AbstractEventLoop | None = None

    def describe(self) -> str:
        """One line for the terminal."""
        return f"live: world {self.keys.world!r} from the hub at {self.endpoint}"

    async def run(self) -> None:
        """Reach the hub (retrying until it is up) and subscribe to its world frames."""
        self._loop = asyncio.get_running_loop()
        while self._session is None:
            try:
                self._session = await asyncio.to_thread(open_session, "client", self.endpoint)
            except HubUnavailable as err:
                self._set_status(f"waiting for the hub: {err}")
                await asyncio.sleep(HUB_RETRY_S)
        self._subscriber = self._session.declare_subscriber(self.keys.world_state, self._from_zenoh)
        self._set_status(f"connected to {self.endpoint}; waiting for world frames of {self.keys.world!r}")
        await asyncio.Event().wait()  # frames arrive through the subscriber until the watcher stops

    def _from_zenoh(self, sample: Any) -> None:
        # zenoh calls this on its own thread; the frame is handled on the event loop
        if self._loop is not None:
            self._loop.call_soon_threadsafe(self._publish, sample.payload.to_bytes())

    def _publish(self, payload: bytes) -> None:
        try:
            raw = msgpack.unpackb(payload, raw=False, strict_map_key=False)
        except (ValueError, TypeError, msgpack.UnpackException) as err:
            self._malformed(err)
            return
        self.offer(raw)

    def offer(self, raw: Any) -> None:
        """One world frame as the hub publishes it (unpacked), or as a model-time run's environment makes it."""
        try:
            frame = check_frame(raw)
        except ValueError as err:
            self._malformed(err)
            return
        if self.latest is None:
            self._set_status(f"following world {self.keys.world!r} from the hub at {self.endpoint}")
        self.latest = frame
        if self.server is not None:
            broadcast(self.server.connections, _message("frame", frame=frame, playing=True))
        for listener in self.listeners:
            listener(frame)

    def _malformed(self, err: Exception) -> None:
        self.malformed += 1
        self._set_status(f"dropped a malformed world frame ({self.malformed} so far): {err}")

    def _set_status(self, text: str) -> None:
        self.status = text
        if self.server is not None:
            broadcast(self.server.connections, _message("status", text=text, malformed=self.malformed))

    async def handle(self, ws: ServerConnection) -> None:
        """A page: the mode, the status, the latest frame; then whatever comes. The page pauses by itself."""
        await ws.send(_message("hello", mode="live", world=self.keys.world, source=self.endpoint))
        await ws.send(_message("status", text=self.status, malformed=self.malformed))
        if self.latest is not None:
            await ws.send(_message("frame", frame=self.latest, playing=True))
        with contextlib.suppress(ConnectionClosed):
            async for _ in ws:
                pass  # live pages have nothing to ask: pause and zoom are theirs alone

    def close(self) -> None:
        """Leave the hub."""
        if self._session is not None:
            self._session.close()


class ReplayFeed:
    """A recorded run, played for each page on its own clock."""

    def __init__(self, source: str, replay: Replay) -> None:
        self.source = source
        self.replay = replay
        self.server: Server | None = None

    def describe(self) -> str:
        """One line for the terminal."""
        frames = self.replay.frames
        span = (frames[-1]["t_us"] - frames[0]["t_us"]) / 1e6
        return f"replay: {len(frames)} frames, {span:.1f} s of {self.source}"

    async def run(self) -> None:
        """Nothing to do between pages: each page's clock runs in its handler."""
        await asyncio.Event().wait()

    def close(self) -> None:
        """Nothing to release: the record was read whole at the start (``_serve`` closes either feed)."""

    async def handle(self, ws: ServerConnection) -> None:
        """One page: hello, then frames on its clock while it asks to play, pause, seek or change speed."""
        frames = self.replay.frames
        clock = ReplayClock(self.replay.times_us)
        clock.start(time.monotonic())
        await ws.send(
            _message(
                "hello",
                mode="replay",
                source=self.source,
                frames=len(frames),
                start_us=clock.start_us,
                end_us=clock.end_us,
                dropped=self.replay.dropped,
            )
        )
        sender = asyncio.create_task(self._play(ws, clock))
        try:
            async for text in ws:
                answer = _control(clock, text, time.monotonic())
                if answer:
                    await ws.send(answer)
        except ConnectionClosed:
            pass
        finally:
            sender.cancel()

    async def _play(self, ws: ServerConnection, clock: ReplayClock) -> None:
        frames = self.replay.frames
        shown, was_playing, seeks = -1, None, clock.seeks
        with contextlib.suppress(ConnectionClosed):
            while True:
                now = time.monotonic()
                index = clock.index(now)
                playing = clock.playing and not clock.finished(now)
                if index != shown or playing != was_playing:
                    played_through = seeks == clock.seeks and index > shown
                    frame = with_events_since(frames, shown, index) if played_through else frames[index]
                    await ws.send(_message("frame", frame=frame, index=index, playing=playing, speed=clock.speed))
                    shown, was_playing, seeks = index, playing, clock.seeks
                await asyncio.sleep(REPLAY_TICK_S)


def _control(clock: ReplayClock, text: str | bytes, wall: float) -> str | None:
    """Apply a page's request to its replay clock; an error message for the page when it makes no sense."""
    try:
        request = json.loads(text)
        action = request["type"]
        if action == "pause":
            clock.pause(wall)
        elif action == "play":
            clock.play(wall)
        elif action == "seek":
            clock.seek(float(request["t_us"]), wall)
        elif action == "speed":
            clock.set_speed(float(request["x"]), wall)
        else:
            raise ValueError(f"type must be pause, play, seek or speed, got {action!r}")
    except (ValueError, KeyError, TypeError) as err:
        return _message("error", text=f"request refused: {err}")
    return None
