"""The nodes of ``petswarm bench hub``: the echo node, the load generators and the pinger.

The echo node and the load generators run as child processes (``python -m cli.bench_nodes echo|load``);
the pinger runs in the bench process itself. All are plain asyncio nodes on ``RadioClient``.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import signal
import struct
import sys
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import zenoh

from radio_hub.interface import Keys, RadioClient, open_session, put_up, reliable_publisher, wait_for_up_key
from radio_hub.values import Frame, FrameType, RadioIdentity, RxFrame, TxResult

PAN_ID = 0x1000
EXT_BASE = 0x00124B00BE000000
PINGER_ADDR, ECHO_ADDR = 1, 2
ECHO_NODE = "bench-echo"
ROUND_TIMEOUT_S = 1.0
MAX_MISSES_IN_A_ROW = 5
IN_FLIGHT = 4
"""Sends each load sender keeps in flight, so its MAC queue never runs dry between TxDone and the next send."""
LOAD_PAYLOAD = b"petswarm"
PAIR_SPACING_M = 1000.0
"""Far beyond the default 50 m interference range: every load pair has an air of its own."""


class BenchFailed(RuntimeError):
    """A child process died, never came up, or stopped answering."""


def bench_key(world: str, name: str) -> str:
    """A key of the benchmark's own traffic, inside the world's prefix."""
    return f"{Keys(world).prefix}/bench/{name}"


# == shared layout ==================================================================================


def pinger_identity() -> RadioIdentity:
    """The bench process's own radio, 1 m from the echo node."""
    return RadioIdentity("bench-pinger", EXT_BASE + PINGER_ADDR, PINGER_ADDR, PAN_ID, 11, (0.0, 0.0))


def echo_identity() -> RadioIdentity:
    """The echo child's radio."""
    return RadioIdentity(ECHO_NODE, EXT_BASE + ECHO_ADDR, ECHO_ADDR, PAN_ID, 11, (1.0, 0.0))


@dataclass(frozen=True)
class LoadNode:
    """One node of the load test: senders (even index) send to the next node, 1 m away."""

    identity: RadioIdentity
    partner: int | None


def load_node(index: int, total: int, group: int = 0) -> LoadNode:
    """Pair ``index // 2`` sits alone at x = 1000 m x pair on channel 11 + pair % 16. ``group`` (the first index of
    the node's load generator) begins its id, so one key expression covers one generator's downlinks."""
    pair, role = divmod(index, 2)
    short = index + 1
    identity = RadioIdentity(
        f"{load_prefix(group)}{index}",
        EXT_BASE + 0x1000 + index,
        short,
        PAN_ID,
        11 + pair % 16,
        (pair * PAIR_SPACING_M + role, 0.0),
    )
    sends = role == 0 and index + 1 < total
    return LoadNode(identity, short + 1 if sends else None)


def load_prefix(group: int) -> str:
    """The start of the ids of one load generator's nodes."""
    return f"load{group}-"


class SharedDownlinks:
    """One load generator's ports to the hub: every node's downlink on one subscriber (``down/load<group>-$*``)
    and the hub's liveliness on one, handed to the generator's loop in batches. With a subscriber per node, a
    generator of 25 nodes had 50 zenoh callback threads taking turns at its GIL for every message, and spent
    more CPU per frame than the hub it was measuring; a robot process has one radio, so one of each anyway."""

    def __init__(self, session: zenoh.Session, world: str, group: int) -> None:
        self.session = session
        self.keys = Keys(world)
        self._loop = asyncio.get_running_loop()
        self._nodes: dict[str, Callable[[bytes], None]] = {}
        self._hub_watchers: list[Callable[[bool], None]] = []
        self._waiting: deque[tuple[str, bytes]] = deque()
        self._drain_due = False
        self._decls = [
            session.declare_subscriber(self.keys.down(f"{load_prefix(group)}$*"), self._down),
            session.liveliness().declare_subscriber(self.keys.hub_alive, self._hub),
        ]

    def link(self) -> SharedLink:
        """A node's port (``HubLink``) on the shared subscribers."""
        return SharedLink(self)

    def close(self) -> None:
        """Undeclare the shared subscribers."""
        for decl in self._decls:
            decl.undeclare()

    def _down(self, sample: zenoh.Sample) -> None:  # zenoh's thread: hand over, one loop wake-up per batch
        self._waiting.append((str(sample.key_expr), sample.payload.to_bytes()))
        if not self._drain_due:
            self._drain_due = True
            self._loop.call_soon_threadsafe(self._drain)

    def _drain(self) -> None:
        self._drain_due = False
        while self._waiting:
            key, data = self._waiting.popleft()
            on_down = self._nodes.get(self.keys.node_of(key))
            if on_down is not None:
                on_down(data)

    def _hub(self, sample: zenoh.Sample) -> None:
        present = sample.kind == zenoh.SampleKind.PUT
        for watcher in list(self._hub_watchers):
            self._loop.call_soon_threadsafe(watcher, present)


class SharedLink:
    """One load node's ``HubLink`` on its generator's ``SharedDownlinks``: its own liveliness token and up
    publisher, the shared subscribers."""

    def __init__(self, shared: SharedDownlinks) -> None:
        self.shared = shared
        self.session = shared.session
        self._node_id = ""
        self._decls: list[Any] = []
        self._pub: zenoh.Publisher | None = None

    def open(
        self, node_id: str, instance: str, on_down: Callable[[bytes], None], on_hub: Callable[[bool], None]
    ) -> None:
        """Declare the node's token and publisher; its messages come through the shared subscriber."""
        shared, keys = self.shared, self.shared.keys
        self._node_id = node_id
        shared._nodes[node_id] = on_down
        shared._hub_watchers.append(on_hub)
        self._pub = reliable_publisher(self.session, keys.up(node_id))
        self._decls = [self.session.liveliness().declare_token(keys.alive(node_id, instance)), self._pub]
        wait_for_up_key(self._pub)  # the hub listens on the node's key once it has seen the token

    def put(self, data: bytes) -> None:
        """One message to the hub."""
        put_up(self._pub, data)

    async def close(self) -> None:
        """Leave: undeclare the token and the publisher."""
        self.shared._nodes.pop(self._node_id, None)
        for decl in self._decls:
            with contextlib.suppress(zenoh.ZError):
                decl.undeclare()
        self._decls, self._pub = [], None


def load_slices(nodes: int, processes: int) -> list[tuple[int, int]]:
    """Node index ranges [first, last) per load generator, never splitting a pair."""
    pairs = (nodes + 1) // 2
    processes = max(1, min(processes, pairs))
    bounds = [min(round(i * pairs / processes) * 2, nodes) for i in range(processes + 1)]
    return [(a, b) for a, b in itertools.pairwise(bounds) if a < b]


def load_psdu_len() -> int:
    """Size of one load frame on the air (no-ACK unicast, PAN ID compressed)."""
    return len(Frame(FrameType.DATA, 0, PAN_ID, 2, PAN_ID, 1, LOAD_PAYLOAD).encode())


# == child processes ================================================================================


def _on_loop(loop: asyncio.AbstractEventLoop, handler: Callable[[bytes], Any]) -> Callable[[zenoh.Sample], None]:
    """A zenoh callback that only hands the payload to ``handler`` on the event loop."""
    return lambda sample: loop.call_soon_threadsafe(handler, sample.payload.to_bytes())


def _stop_event() -> asyncio.Event:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    return stop


async def echo_main(endpoint: str, world: str) -> int:
    """The echo child: answers every radio frame to its source, and republishes plain zenoh requests."""
    stop = _stop_event()
    radio = await RadioClient.connect(echo_identity(), endpoint, world)
    loop = asyncio.get_running_loop()
    rep = reliable_publisher(radio.session, bench_key(world, "echo/rep"))
    req = radio.session.declare_subscriber(bench_key(world, "echo/req"), _on_loop(loop, rep.put))
    radio.on_frame = _answer(radio)
    print(f"echo: attached as {ECHO_NODE}", file=sys.stderr, flush=True)
    try:
        await stop.wait()
    finally:
        req.undeclare()
        rep.undeclare()
        await radio.close()
    return 0


def _answer(radio: RadioClient) -> Callable[[RxFrame], None]:
    """The echo's answer to a frame: the same payload back to its source, sent from the frame's own callback
    (``on_frame`` and ``transmit``, no task or future), as the plain echo answers from its subscriber's: the
    round trips compare the hub with the router, not two ways of writing a node."""

    def on_frame(rx: RxFrame) -> None:
        radio.transmit(radio.data_frame(rx.frame.src, rx.frame.payload, ack=False), _no_answer_needed)

    return on_frame


def _no_answer_needed(_: TxResult) -> None:
    """The echo's frames are not retried: a round whose echo is lost is counted lost by the pinger."""


async def load_main(endpoint: str, world: str, first: int, last: int, total: int) -> int:
    """A load generator: nodes ``first..last-1`` on one shared session; senders busy from go to stop."""
    stop, go = _stop_event(), asyncio.Event()
    loop = asyncio.get_running_loop()
    session = await asyncio.to_thread(open_session, "client", endpoint)
    decls = [
        session.declare_subscriber(bench_key(world, "load/go"), _on_loop(loop, lambda _: go.set())),
        session.declare_subscriber(bench_key(world, "load/stop"), _on_loop(loop, lambda _: stop.set())),
    ]
    counts: Counter[str] = Counter()
    radios: list[RadioClient] = []
    shared = SharedDownlinks(session, world, first)
    try:
        nodes = [load_node(i, total, first) for i in range(first, last)]
        radios = list(await asyncio.gather(*(_connect_shared(n, endpoint, world, shared) for n in nodes)))
        print(f"load: {len(radios)} nodes attached", file=sys.stderr, flush=True)
        await _first_set(go, stop)
        if not stop.is_set():
            await _generate(radios, nodes, counts, stop)
    finally:
        for radio in radios:
            await radio.close()
        shared.close()
        for decl in decls:
            decl.undeclare()
        await asyncio.to_thread(session.close)
    print(f"load: {dict(counts)}", file=sys.stderr, flush=True)
    return 0


async def _connect_shared(node: LoadNode, endpoint: str, world: str, shared: SharedDownlinks) -> RadioClient:
    return await RadioClient.connect(node.identity, endpoint, world, link=shared.link())


async def _first_set(*events: asyncio.Event) -> None:
    waits = [asyncio.create_task(e.wait()) for e in events]
    await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
    for task in waits:
        task.cancel()


async def _generate(
    radios: list[RadioClient], nodes: list[LoadNode], counts: Counter[str], stop: asyncio.Event
) -> None:
    """Every sender keeps ``IN_FLIGHT`` frames in flight until ``stop``: each result sends the next frame at once.

    A real high-rate node's path (``RadioClient.transmit`` and ``on_frame``): no task, future or timer per
    frame, so the generators spend their CPU on the wire, not on asyncio. Every frame is still a Transmit
    through the hub's medium, and the next one goes only once its TxDone has come back."""
    stopping = False

    def keep_sending(radio: RadioClient, dst: int) -> Callable[[TxResult], None]:
        frame = radio.data_frame(dst, LOAD_PAYLOAD, ack=False)  # its sequence number is not looked at

        def on_done(result: TxResult) -> None:
            counts[result.status.value] += 1
            if not stopping:
                radio.transmit(frame, on_done)

        return on_done

    def on_frame(_: RxFrame) -> None:
        counts["received"] += 1

    for radio, node in zip(radios, nodes, strict=True):
        if node.partner is None:
            radio.on_frame = on_frame
            continue
        on_done = keep_sending(radio, node.partner)
        for _ in range(IN_FLIGHT):
            radio.transmit(radio.data_frame(node.partner, LOAD_PAYLOAD, ack=False), on_done)
    await stop.wait()
    stopping = True


# == the pinger (runs in the bench process) ==========================================================


@dataclass
class RttSamples:
    """Round trips in microseconds, one entry per kept round on each path."""

    plain_us: list[float] = field(default_factory=list)
    radio_wall_us: list[float] = field(default_factory=list)
    radio_adjusted_us: list[float] = field(default_factory=list)
    radio_model_us: list[float] = field(default_factory=list)
    txdone_excess_us: list[float] = field(default_factory=list)
    """Send -> TxDone at the pinger, wall minus model: one pass through the hub and back."""
    lost_plain: int = 0
    lost_radio: int = 0


@dataclass(frozen=True)
class RadioRound:
    """One radio round trip: wall times and the model's share of them."""

    wall_us: float
    model_us: float
    txdone_excess_us: float


class Pinger:
    """The bench's node: times plain zenoh and radio round trips to the echo child."""

    def __init__(self, radio: RadioClient) -> None:
        self.radio = radio
        self._loop = asyncio.get_running_loop()
        world = radio.world
        self._waiter: asyncio.Future[None] | None = None
        self._expect = b""
        self._req = reliable_publisher(radio.session, bench_key(world, "echo/req"))
        self._rep = radio.session.declare_subscriber(bench_key(world, "echo/rep"), _on_loop(self._loop, self._on_rep))

    def close(self) -> None:
        """Undeclare the plain echo keys."""
        self._rep.undeclare()
        self._req.undeclare()

    def _on_rep(self, data: bytes) -> None:
        waiter = self._waiter
        if waiter is not None and not waiter.done() and data == self._expect:
            waiter.set_result(None)

    async def plain(self, payload: bytes, timeout: float = ROUND_TIMEOUT_S) -> float | None:
        """One plain zenoh round trip in microseconds, or None on timeout."""
        self._waiter, self._expect = self._loop.create_future(), payload
        t0 = time.perf_counter_ns()
        self._req.put(payload)
        try:
            async with asyncio.timeout(timeout):
                await self._waiter
        except TimeoutError:
            return None
        return (time.perf_counter_ns() - t0) / 1000

    async def over_radio(self, payload: bytes) -> RadioRound | None:
        """One radio round trip via the hub, or None when the frame or its echo did not come back."""
        radio = self.radio
        t0 = time.perf_counter_ns()
        tx = await radio.send(radio.data_frame(ECHO_ADDR, payload, ack=False))
        t_done = time.perf_counter_ns()
        if not tx.ok:
            return None
        try:
            async with asyncio.timeout(ROUND_TIMEOUT_S):
                rx = await self._echo_of(payload)
        except TimeoutError:
            return None
        wall = (time.perf_counter_ns() - t0) / 1000
        own = tx.done_us - tx.submitted_us
        model = own + rx.end_us - rx.submitted_us
        return RadioRound(wall, model, (t_done - t0) / 1000 - own)

    async def _echo_of(self, payload: bytes) -> RxFrame:
        while True:  # a late echo of an earlier, timed-out round is skipped
            rx = await self.radio.receive()
            if rx.frame.payload == payload:
                return rx

    async def wait_ready(self, timeout: float) -> None:
        """Until the echo's plain subscriber answers (its radio is attached already)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if await self.plain(b"ready", timeout=0.2) is not None:
                return
        raise BenchFailed(f"the echo node did not answer within {timeout} s")


async def ping_rounds(
    endpoint: str, world: str, rounds: int, warmup: int, on_progress: Callable[[int], None]
) -> RttSamples:
    """``warmup`` rounds, then ``rounds`` kept ones, each timing both paths; ``on_progress`` every 100."""
    radio = await RadioClient.connect(pinger_identity(), endpoint, world)
    pinger = Pinger(radio)
    try:
        await pinger.wait_ready(timeout=10.0)
        samples = RttSamples()
        misses = 0
        for i in range(-warmup, rounds):
            misses = 0 if await _one_round(pinger, i, samples if i >= 0 else RttSamples()) else misses + 1
            if misses >= MAX_MISSES_IN_A_ROW:
                raise BenchFailed(f"{misses} round trips in a row got no answer")
            if i >= 0 and (i + 1) % 100 == 0:
                on_progress(i + 1)
        return samples
    finally:
        pinger.close()
        await radio.close()


async def _one_round(pinger: Pinger, i: int, samples: RttSamples) -> bool:
    """Both paths once, the order alternating so that noise hits both alike; False if either was lost."""
    payload = struct.pack(">q", i)
    if i % 2:
        radio_rt = await pinger.over_radio(payload)
        plain = await pinger.plain(payload)
    else:
        plain = await pinger.plain(payload)
        radio_rt = await pinger.over_radio(payload)
    if plain is None:
        samples.lost_plain += 1
    else:
        samples.plain_us.append(plain)
    if radio_rt is None:
        samples.lost_radio += 1
    else:
        samples.radio_wall_us.append(radio_rt.wall_us)
        samples.radio_adjusted_us.append(radio_rt.wall_us - radio_rt.model_us)
        samples.radio_model_us.append(radio_rt.model_us)
        samples.txdone_excess_us.append(radio_rt.txdone_excess_us)
    return plain is not None and radio_rt is not None
