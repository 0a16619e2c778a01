"""The zenoh side of the radio port: sessions, the reliable publishers, and ``ZenohLink`` for node processes.

A node process's ``RadioClient`` talks to the hub through a ``ZenohLink``: its messages go up on the node's
``up`` key, the hub's come back on its ``down`` key and are handed to the node's event loop (zenoh-python
calls back on its own threads, so a callback only hands over), and liveliness tokens tell the hub the node
is there and the node whether the hub is.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Collection
from typing import Any

import msgpack
import zenoh

from radio_hub.guard import Faults
from radio_hub.link import wire
from radio_hub.link.keys import Keys
from radio_hub.link.trust import TransportSecurity, access_control, tls_settings
from radio_hub.link.up_keys import UpKeys, wait_for_up_key
from radio_hub.link.values import HubUnavailable

DOWN_PENDING_LIMIT = 2000
"""Messages from the hub a node's event loop may have waiting; more are dropped and counted (``dropped``):
a flood on a node's downlink key costs it those messages, never unbounded memory."""
DOWN_PENDING_BYTES = 2 << 20
"""Bytes of such messages waiting at most (the hub's own are a few hundred bytes each)."""
STRANGER_ANSWERS_PER_S = 200
"""Answers (errors) a hub sends per second to ids that are not attached; more are dropped and counted."""

_ENDPOINT = re.compile(r"^(tcp|udp|tls|quic)/(\[[0-9a-fA-F:.]+\]|[A-Za-z0-9_.-]+):\d{1,5}$")
_security = TransportSecurity()


def use_security(security: TransportSecurity) -> None:
    """Every session this process opens from now on uses ``security`` (the command line's TLS options):
    one process, one identity, so the setting is process-wide rather than threaded through every caller."""
    global _security
    _security = security


MAX_TRANSPORT_BYTES = 4 << 20
"""The longest message a petswarm process takes from zenoh at all (anything longer ends the sender's link)."""


def session_config(mode: str, endpoint: str) -> zenoh.Config:
    """A zenoh config: ``router`` listens on ``endpoint``, ``client`` connects to it; no multicast. The
    process's TransportSecurity adds TLS (and, on a router asking for client certificates, access control)
    on top of its zenoh config file, if it gave one."""
    if mode not in ("router", "client"):
        raise ValueError("mode must be router or client")
    security = _security
    config = zenoh.Config.from_file(security.zenoh_config) if security.zenoh_config else zenoh.Config()
    config.insert_json5("mode", f'"{mode}"')
    for name, value in tls_settings(security, mode).items():
        config.insert_json5(f"transport/link/tls/{name}", json.dumps(value))
    if mode == "router" and security.mutual:
        config.insert_json5("access_control", json.dumps(access_control(security.acl_ids)))
    where = "listen/endpoints" if mode == "router" else "connect/endpoints"
    config.insert_json5(where, f'["{endpoint}"]')
    config.insert_json5("scouting/multicast/enabled", "false")
    # Zenoh hands large payloads between processes of one host in shared memory, and a session's segments stayed
    # mapped in its peer after it closed: 26 sessions sending 300 x 60 kB took the hub from 54 to 170-300 MB for
    # good (a bare zenoh router: 23 -> 173 MB; 23 -> 25 MB without). Nothing of ours is large enough to gain by it.
    config.insert_json5("transport/shared_memory/enabled", "false")
    # Zenoh reassembles a message of up to 1 GB by default, and the buffers of a session's large messages stayed
    # with the process after it closed (8 sessions of 20 x 10 MB: hub 60 -> 249 MB, robot 56 -> 240 MB). Nothing of
    # ours is longer than a robot's events answer (20,000 events, a few MB) or ``wire.MAX_MESSAGE_BYTES``.
    config.insert_json5("transport/link/rx/max_message_size", str(MAX_TRANSPORT_BYTES))
    if mode == "client":
        # A restarted hub must get its nodes back at once. Zenoh's default backoff retries 1 s, then 2, then
        # 4 s after the router went away: a client unlucky with a hub down 1.5 s came back 5 s late, missed
        # the re-organize that followed, and failed test_the_hub_restarts about 1 run in 15 on a busy machine.
        # A constant 0.2-0.5 s costs a connect attempt per node twice a second while the hub is away.
        retry = "{ period_init_ms: 200, period_max_ms: 500, period_increase_factor: 1.5 }"
        config.insert_json5("connect/retry", retry)
    return config


def reliable_publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    """Emulated frames must never vanish in the transport: reliable, and block rather than drop."""
    return session.declare_publisher(
        key, congestion_control=zenoh.CongestionControl.BLOCK, reliability=zenoh.Reliability.RELIABLE
    )


def over_down_bounds(size: int, waiting: int, waiting_bytes: int) -> bool:
    """Whether a node drops (and counts) a message from the hub of ``size`` bytes, with ``waiting`` messages of
    ``waiting_bytes`` already waiting for it: longer than ``wire.MAX_MESSAGE_BYTES``, or past
    ``DOWN_PENDING_LIMIT`` messages or ``DOWN_PENDING_BYTES`` in all (what waits for a wall-clock node's loop,
    what a lockstep node holds for its next grant)."""
    return size > wire.MAX_MESSAGE_BYTES or waiting >= DOWN_PENDING_LIMIT or waiting_bytes + size > DOWN_PENDING_BYTES


def put_up(pub: zenoh.Publisher | None, data: bytes) -> None:
    """One message of a node to the hub on its up publisher; HubUnavailable when it is not open or the session
    is gone (every node link puts this way)."""
    if pub is None:
        raise HubUnavailable("the link is not open")
    try:
        pub.put(data)
    except zenoh.ZError as err:
        raise HubUnavailable(f"cannot reach the hub: {err}") from None


def open_session(mode: str, endpoint: str) -> zenoh.Session:
    """Open a zenoh session, turning zenoh's error into HubUnavailable with the endpoint in it."""
    if not _ENDPOINT.match(endpoint):
        raise HubUnavailable(f"{endpoint!r} is not a zenoh endpoint such as tcp/127.0.0.1:7447")
    try:
        return zenoh.open(session_config(mode, endpoint))
    except zenoh.ZError as err:
        reason = str(err).split(" at /")[0].strip()  # zenoh appends the Rust source location
        hint = " (is `petswarm hub` running there?)" if mode == "client" else ""
        raise HubUnavailable(f"cannot reach {endpoint}{hint}: {reason}") from None


def query_hub(session: zenoh.Session, key: str, timeout: float = 2.0, payload: bytes | None = None) -> dict[str, Any]:
    """Ask one of the hub's queryables (blocking); raises HubUnavailable when nobody answers."""
    for reply in session.get(key, timeout=timeout, payload=payload):
        if reply.ok is not None:
            return msgpack.unpackb(reply.ok.payload.to_bytes(), raw=False, strict_map_key=False)
    raise HubUnavailable(f"no hub answered {key} within {timeout} s")


class HubDownlink:
    """A hub shell's ``Downlink``: the environment's messages to nodes on one reliable publisher per node,
    declared when first needed, and the world's state on ``world_pub``; nothing while ``session`` is None.

    With ``batching`` a member's messages wait in a buffer until ``flush``, which puts each node's in one
    ``wire.encode_batch`` (a lone message as it is): the hub flushes once per pass of each of its threads, so a
    node hears one put per pass instead of one per message (a zenoh put costs about 14 us of CPU)."""

    def __init__(self, keys: Keys, is_member: Callable[[str], bool] | None = None, *, batching: bool = False) -> None:
        """``is_member(node_id)``: whether the id is attached. Non-members (an id that sent something without
        attaching, or has left) get no publisher of their own and at most ``STRANGER_ANSWERS_PER_S``
        answers a second, so a stream of made-up ids costs the hub neither memory nor much time."""
        self.keys = keys
        self.session: zenoh.Session | None = None
        self.world_pub: zenoh.Publisher | None = None
        self.is_member = is_member
        self.stranger_answers_dropped = 0
        self.batching = batching
        self.puts = 0
        """Transport messages put on nodes' publishers (a batch counts once)."""
        self.messages = 0
        """Messages sent to members (each part of a batch counts)."""
        self._pubs: dict[str, zenoh.Publisher] = {}
        self._window_s = 0.0
        self._window_answers = 0
        self._pending: dict[str, list[bytes]] = {}
        self._lock = threading.Lock()
        """Over the buffer and the strangers' answer budget (two threads send)."""
        self._flushing = threading.Lock()
        """Held by the one thread putting the buffer's contents: a node's messages leave in the order they were
        numbered, and a thread that finds it held leaves its messages to the holder instead of waiting."""

    def send(self, node_id: str, data: bytes) -> None:
        if self.session is None:
            return
        if self.batching and (node_id in self._pubs or self.is_member is None or self.is_member(node_id)):
            with self._lock:
                pending = self._pending.get(node_id)
                if pending is None:
                    self._pending[node_id] = [data]
                else:
                    pending.append(data)
            return
        self._put(node_id, data, 1)

    def flush(self) -> None:
        """Put every buffered message, one put per node (``wire.BATCH_MAX_PARTS`` messages and
        ``DOWN_BATCH_BYTES`` at most each). Never waits for the other thread's flush: that one takes these
        messages too before it stops (it looks again after letting go)."""
        while self._pending:
            if not self._flushing.acquire(blocking=False):
                return
            try:
                while True:
                    with self._lock:
                        pending, self._pending = self._pending, {}
                    if not pending:
                        break
                    self._put_all(pending)
            finally:
                self._flushing.release()

    def _put_all(self, pending: dict[str, list[bytes]]) -> None:
        for node_id, parts in pending.items():
            for data, count in transport_messages(parts, DOWN_BATCH_BYTES):
                self._put(node_id, data, count)

    def _put(self, node_id: str, data: bytes, count: int) -> None:
        if self.session is None:
            return
        try:
            pub = self._pubs.get(node_id)
            if pub is None and self.is_member is not None and not self.is_member(node_id):
                with self._lock:
                    self._answer_stranger(node_id, data)
                return
            if pub is None:
                pub = self._pubs[node_id] = reliable_publisher(self.session, self.keys.down(node_id))
            pub.put(data)
            self.puts += 1
            self.messages += count
        except zenoh.ZError as err:
            print(f"hub: cannot reach {node_id}: {err}", file=sys.stderr)

    def _answer_stranger(self, node_id: str, data: bytes) -> None:
        now = time.monotonic()
        if now - self._window_s >= 1.0:
            self._window_s, self._window_answers = now, 0
        if self._window_answers >= STRANGER_ANSWERS_PER_S:
            self.stranger_answers_dropped += 1
            return
        self._window_answers += 1
        assert self.session is not None
        self.session.put(self.keys.down(node_id), data)

    def forget(self, node_id: str) -> None:
        # waits for a flush under way: a put on the publisher while it is undeclared raises (zenoh's objects
        # are borrowed across threads); what was sent before the node left still goes
        with self._flushing:
            with self._lock:
                pending, self._pending = self._pending, {}
            self._put_all(pending)
            pub = self._pubs.pop(node_id, None)
            if pub is not None:
                with contextlib.suppress(zenoh.ZError):
                    pub.undeclare()

    def publish_world(self, state: dict[str, Any]) -> None:
        if self.world_pub is not None:
            with contextlib.suppress(zenoh.ZError):
                self.world_pub.put(msgpack.packb(state, use_bin_type=True))

    def close(self) -> None:
        """Undeclare every node's publisher and stop sending."""
        for node_id in list(self._pubs):
            self.forget(node_id)
        self.session = None


DOWN_BATCH_BYTES = 256 << 10
"""A batch's parts together at most (a lone longer message goes on its own): well under what a node takes."""
UP_BATCH_BYTES = wire.MAX_UP_BYTES - 5 * (wire.BATCH_MAX_PARTS + 1)
"""The same for a lockstep node's batch to the hub: with msgpack's headers (5 bytes at most per part and for the
array) a batch stays within what the hub takes from a node."""


def put_batches(pub: zenoh.Publisher | None, parts: list[bytes], max_bytes: int) -> int:
    """``parts`` on ``pub`` in as few puts as ``transport_messages`` allows; the number of puts. Raises
    HubUnavailable as ``put_up`` does."""
    puts = 0
    for data, _ in transport_messages(parts, max_bytes):
        put_up(pub, data)
        puts += 1
    return puts


def transport_messages(parts: list[bytes], max_bytes: int) -> list[tuple[bytes, int]]:
    """``parts`` in order as transport messages and how many each carries: runs of ``_batches``, a run of one
    message as it is, a longer one as ``wire.encode_batch``; nothing for no parts."""
    if len(parts) == 1:
        return [(parts[0], 1)]
    runs = _batches(parts, max_bytes) if parts else []
    return [(run[0], 1) if len(run) == 1 else (wire.encode_batch(run), len(run)) for run in runs]


def _batches(parts: list[bytes], max_bytes: int = DOWN_BATCH_BYTES) -> list[list[bytes]]:
    """``parts`` in order, cut into runs of at most ``wire.BATCH_MAX_PARTS`` messages and ``max_bytes``."""
    batches: list[list[bytes]] = [[]]
    size = 0
    for part in parts:
        last = batches[-1]
        if last and (len(last) >= wire.BATCH_MAX_PARTS or size + len(part) > max_bytes):
            batches.append(last := [])
            size = 0
        last.append(part)
        size += len(part)
    return batches


def declare_hub_keys(
    session: zenoh.Session,
    keys: Keys,
    put: Callable[[tuple[Any, ...]], None],
    *,
    chaos: bool = True,
    oversized: Callable[[], None] | None = None,
    faults: Faults | None = None,
    roster: Collection[str] = (),
) -> tuple[UpKeys, list[Any]]:
    """What a hub shell serves on its router session, every callback a hand-off to ``put`` (its inbox): nodes'
    messages (``("up", key, bytes)``) on the up keys of the nodes that are there (the ``UpKeys``, returned on its
    own for its counters and in the list of everything to undeclare),
    their liveliness (``("alive", key, kind)``), the queryables (``("stats", query)``...; the chaos queryable only
    with ``chaos``) and the hub's own liveliness token. A node's message longer than ``wire.MAX_UP_BYTES`` is
    dropped before it is copied out of zenoh (``oversized`` counts it). ``faults``: the hub's count of unexpected
    exceptions, here those of the thread that keeps the up keys. ``roster``: the node ids whose up keys open outside
    the cap (``UpKeys``)."""

    def up(sample: zenoh.Sample) -> None:
        if len(sample.payload) > wire.MAX_UP_BYTES:
            if oversized is not None:
                oversized()
            return
        put(("up", str(sample.key_expr), sample.payload.to_bytes()))

    up_keys = UpKeys(session, keys, up, put, faults=faults, roster=roster)
    decls = [
        up_keys,
        session.declare_queryable(keys.stats, lambda q: put(("stats", q))),
        session.declare_queryable(keys.air, lambda q: put(("air", q))),
        session.declare_queryable(keys.world_query, lambda q: put(("world", q))),
        session.liveliness().declare_token(keys.hub_alive),
    ]
    if chaos:
        decls.append(session.declare_queryable(keys.chaos, lambda q: put(("chaos", q))))
    return up_keys, decls


def reply(query: zenoh.Query, body: dict[str, Any]) -> None:
    """Answer a query with a msgpack map (an error map if it cannot be packed), and let it go."""
    try:
        try:
            data = msgpack.packb(body, use_bin_type=True)
        except (TypeError, ValueError, OverflowError) as err:
            data = msgpack.packb({"error": f"cannot encode the answer: {type(err).__name__}: {err}"})
        query.reply(query.key_expr, data)
    finally:
        query.drop()


class ZenohLink:
    """A node's port to the hub over a zenoh client session."""

    def __init__(self, session: zenoh.Session, keys: Keys, owns_session: bool) -> None:
        self.session = session
        self.keys = keys
        self.owns_session = owns_session
        """Close the session with the link (True when the link opened it)."""
        self._decls: list[Any] = []
        self._pub: zenoh.Publisher | None = None
        self.dropped = 0
        """Messages from the hub dropped: longer than ``wire.MAX_MESSAGE_BYTES``, or ``DOWN_PENDING_LIMIT``
        already waiting for the node's event loop."""
        self._waiting: deque[bytes] = deque()
        """Messages from the hub that zenoh's thread handed over and the node's loop has not taken yet."""
        self._bytes_in = 0
        """Bytes ever put in ``_waiting`` (written by zenoh's thread only)."""
        self._bytes_out = 0
        """Bytes ever taken from it (written by the node's loop only): waiting = in - out, without a lock."""
        self._drain_due = False
        """A drain of ``_waiting`` is scheduled on the node's loop and has not started yet."""
        self.unheard = False
        """The hub had not opened the node's up key when ``open`` stopped waiting for it: the first attach goes
        again until answered (``RadioClient.connect``)."""

    @classmethod
    async def connect(cls, endpoint: str, world: str, session: zenoh.Session | None = None) -> ZenohLink:
        """A link on ``session``, or on a new client session to ``endpoint`` (HubUnavailable if it fails)."""
        owns = session is None
        if session is None:
            session = await asyncio.to_thread(open_session, "client", endpoint)
        return cls(session, Keys(world), owns)

    def open(
        self, node_id: str, instance: str, on_down: Callable[[bytes], None], on_hub: Callable[[bool], None]
    ) -> None:
        """Declare the node's liveliness, its down subscription, the hub watch and its up publisher."""
        loop = asyncio.get_running_loop()
        session, keys = self.session, self.keys

        waiting = self._waiting

        def down(sample: zenoh.Sample) -> None:  # zenoh's thread (one per subscriber): hand over, return at once
            size = len(sample.payload)
            if over_down_bounds(size, len(waiting), self._bytes_in - self._bytes_out):
                self.dropped += 1
                return
            waiting.append(sample.payload.to_bytes())
            self._bytes_in += size
            if not self._drain_due:
                # one wake-up of the loop for whatever arrives until it drains: a wake-up per message (a
                # Handle, a write to the loop's self-pipe, a select) cost a node three times the message itself
                self._drain_due = True
                try:
                    loop.call_soon_threadsafe(drain)
                except RuntimeError:  # the node's loop has closed (the process is ending): nobody to hand it to
                    waiting.clear()

        def drain() -> None:  # the node's loop: every message waiting, in arrival order
            self._drain_due = False  # first: what arrives from now on schedules another drain
            while waiting:
                data = waiting.popleft()
                self._bytes_out += len(data)
                try:
                    on_down(data)
                except BaseException:  # the rest must not wait for the next message: they get a drain of their own
                    if waiting and not self._drain_due:
                        self._drain_due = True
                        loop.call_soon(drain)
                    raise

        def hub(sample: zenoh.Sample) -> None:  # a hub appeared (again: it knows nothing of us) or went away
            with contextlib.suppress(RuntimeError):  # the node's loop has closed
                loop.call_soon_threadsafe(on_hub, sample.kind == zenoh.SampleKind.PUT)

        self._decls = [
            session.liveliness().declare_token(keys.alive(node_id, instance)),
            session.declare_subscriber(keys.down(node_id), down),
            session.liveliness().declare_subscriber(keys.hub_alive, hub),
        ]
        self._pub = reliable_publisher(session, keys.up(node_id))
        self._decls.append(self._pub)
        self.unheard = not wait_for_up_key(self._pub)  # until the hub has seen our token, what we put goes nowhere

    def put(self, data: bytes) -> None:
        """One message to the hub; HubUnavailable when the session is gone."""
        put_up(self._pub, data)

    async def close(self) -> None:
        """Undeclare everything; close the session if the link opened it."""
        for decl in self._decls:
            with contextlib.suppress(zenoh.ZError):
                decl.undeclare()
        self._decls, self._pub = [], None
        if self.owns_session:
            await asyncio.to_thread(self.session.close)
