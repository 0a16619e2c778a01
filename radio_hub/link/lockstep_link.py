"""A node's link to a lockstep hub (``--clock lockstep``): zenoh, with the hub's messages held until the grant
that closes their round. The hub's side of the rounds is ``radio_hub.shell.lockstep``; the loop that runs the
node on the granted instants is ``petswarm.clock.LockstepLoop`` (duck-typed here).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import queue
import threading
from collections import deque
from collections.abc import Callable
from typing import Any

import zenoh

from radio_hub.link import wire
from radio_hub.link.keys import Keys
from radio_hub.link.up_keys import UP_KEYS_MAX, UP_MATCH_WAIT_S, wait_for_up_key
from radio_hub.link.values import HubUnavailable
from radio_hub.link.zenoh_link import UP_BATCH_BYTES, ZenohLink, over_down_bounds, put_batches, reliable_publisher

DOWN_CHANNEL_CAPACITY = 16
"""Transport messages from the hub a lockstep node's channel holds. A round sends a node one (its batch, split
past ``wire.BATCH_MAX_PARTS`` messages or 256 kB) and waits for its idle, so 16 hold 4,096 messages of one round;
more block zenoh's receiving thread until the node takes them. A flood thus costs a node at most 16 x
``wire.MAX_MESSAGE_BYTES`` here whatever its load: at 4,096 a starved node's backlog of 100 kB messages had
grown its memory 20 MB more than an idle one's (62 against 42 MB, tests/process/test_lockstep.py)."""

UP_KEY_WAIT_S = UP_MATCH_WAIT_S
"""Wall seconds a lockstep node waits for the hub to open its up key, then gives up with HubUnavailable: what it
put before would be lost, its first idle too, and the hub would wait for that idle until it took the node as
gone (a wall-clock node sends its first attach again instead; a lockstep node's first words are a round's)."""


class LockstepLink(ZenohLink):
    """A node's port to a lockstep hub: zenoh, with the hub's messages held until their round's grant."""

    def __init__(self, session: zenoh.Session, keys: Keys, owns_session: bool) -> None:
        super().__init__(session, keys, owns_session)
        self._held: deque[tuple[int, bytes]] = deque()
        self._held_bytes = 0
        """Bytes in ``_held``: with its length, bounded as a wall-clock link bounds what waits for its loop."""
        self._release: list[bytes] = []
        self._release_grant: int | None = None
        """The number of the grant that closes ``_release``."""
        self._seen = 0
        self._loop: Any = None
        self._on_down: Callable[[bytes], None] | None = None
        self._down: Any = None
        self._down_key = ""
        self._wake_mark = os.urandom(8)
        """Carried by this link's own wake-ups: an empty message from anyone else is a message, held as any."""
        self._wakes: queue.SimpleQueue[bool] = queue.SimpleQueue()
        self._waker: threading.Thread | None = None
        self._outbox: list[bytes] = []
        """The node's messages of the round so far: they go to the hub with its idle, in one put."""
        self.session_key = 0
        """The node's session key (its radio sets it): an idle carries it like every message of the node."""

    def open(
        self, node_id: str, instance: str, on_down: Callable[[bytes], None], on_hub: Callable[[bool], None]
    ) -> None:
        """Declare the node's keys and start reporting to the hub through the running lockstep loop."""
        loop = asyncio.get_running_loop()
        if not hasattr(loop, "attach_sync"):
            raise RuntimeError("a lockstep link needs a lockstep loop (petswarm.clock.LockstepLoop)")
        self._loop, self._on_down = loop, on_down
        keys = self.keys
        self._down_key = keys.down(node_id)
        # a channel, not a callback: the loop takes the hub's messages itself while it waits for its grant
        # (``wait_grant``), blocked in the channel with the GIL released; a callback would cost a Python thread's
        # wake-up, the loop's self-pipe and one more pass of the loop per round
        self._down = self.session.declare_subscriber(self._down_key, zenoh.handlers.FifoChannel(DOWN_CHANNEL_CAPACITY))
        self._decls = [self.session.liveliness().declare_token(keys.alive(node_id, instance)), self._down]
        self._waker = threading.Thread(target=self._put_wakes, name="lockstep-waker", daemon=True)
        self._waker.start()
        self._pub = reliable_publisher(self.session, keys.up(node_id))
        self._decls.append(self._pub)
        if not wait_for_up_key(self._pub, UP_KEY_WAIT_S):
            raise HubUnavailable(
                f"the hub did not open {node_id}'s up key within {UP_KEY_WAIT_S:g} s (it opens one per id with a "
                f"liveliness token, {UP_KEYS_MAX} at most)"
            )
        loop.on_quiescent = self._release_held
        loop.attach_sync(self)

    def wait_grant(self) -> None:
        """Block until the hub's next grant (the loop's thread, between its idle and the next pass): hold what
        comes before it, and move the loop to the granted instant. Returns early on ``wake`` (a signal or another
        thread has work for the loop)."""
        down = self._down
        while True:
            try:
                sample = down.recv()
            except zenoh.ZError:  # the subscriber is gone (the session closed): out of the world, not a spin
                self._loop.attach_sync(None)
                return
            data = sample.payload.to_bytes()
            if not data and _attachment(sample) == self._wake_mark:  # our own wake-up: nothing to hold
                return
            grant = _grant_of(data)
            # a grant is always held; anything else within a wall-clock link's bounds: a round's messages are far
            # inside them, a flood while the hub withholds the grant (waiting on a slow node, or gone) is not
            if grant is None and over_down_bounds(len(data), len(self._held), self._held_bytes):
                self.dropped += 1
                continue
            self._held.append((0 if grant is None else grant.n, data))
            self._held_bytes += len(data)
            if grant is not None:
                self._granted(grant.at_s, grant.n)
                return

    def wake(self) -> None:
        """End a ``wait_grant`` under way (any thread, or a signal handler): the waker thread puts a marked
        empty message on the node's own down key, for this session only. Never put from here: a signal handler
        runs on the loop's thread, which is the one that empties the channel a put may wait for."""
        self._wakes.put(True)

    def _put_wakes(self) -> None:
        while self._wakes.get():
            with contextlib.suppress(zenoh.ZError):
                self.session.put(
                    self._down_key,
                    b"",
                    attachment=self._wake_mark,
                    allowed_destination=zenoh.Locality.SESSION_LOCAL,
                )

    def _granted(self, at_s: float, n: int) -> None:
        self._loop.grant(at_s)
        while self._held:
            grant_n, data = self._held.popleft()
            self._held_bytes -= len(data)
            self._release.append(data)
            if grant_n == n:
                self._release_grant = n
                break

    def _release_held(self) -> bool:
        """Nothing is ready: hand over the messages of the last grant (the grant last), in order."""
        if not self._release or self._on_down is None:
            return False
        for data in self._release:
            self._loop.call_soon(self._on_down, data)
        if self._release_grant is not None:  # known from the wait: a batch is not unpacked again for it
            self._seen, self._release_grant = self._release_grant, None
        self._release = []
        return True

    def put(self, data: bytes) -> None:
        """One message to the hub, held until the round's idle while the node is in the world (the hub reads
        none of it before that idle anyway); HubUnavailable when the link is not open."""
        if self._pub is None or self._loop is None or self._loop.sync is not self:
            super().put(data)
            return
        self._outbox.append(data)

    def idle(self, next_timer: float | None) -> None:
        """Tell the hub: handled up to the last grant, the next timer is due at ``next_timer``; the round's
        messages go first, in the same put."""
        self._outbox.append(wire.Idle(seen=self._seen, next_s=next_timer, s=self.session_key).encode())
        self._send_outbox()

    def _send_outbox(self) -> None:
        outbox, self._outbox = self._outbox, []
        if not outbox:  # a close with nothing held (a connect that failed): an empty batch is malformed
            return
        with contextlib.suppress(HubUnavailable):
            put_batches(self._pub, outbox, UP_BATCH_BYTES)

    async def close(self) -> None:
        """Leave the world: what is held goes, no more idles; then undeclare and close as a zenoh link does."""
        self._send_outbox()
        if self._loop is not None:
            self._loop.attach_sync(None)
            self._loop.on_quiescent = None
        self._wakes.put(False)  # the waker ends
        await super().close()


_GRANT_TYPE = b"\xa1t\xa5grant"
"""The msgpack bytes of a grant's type field (``"t": "grant"``): a message without them is not a grant."""


def _attachment(sample: zenoh.Sample) -> bytes | None:
    attachment = sample.attachment
    return None if attachment is None else attachment.to_bytes()


def _grant_of(data: bytes) -> wire.Grant | None:
    """The grant that ``data`` is or that closes it (a batch's last message), else None.

    Runs on the node's loop thread, in its wait, for every message it is sent: most are frames and sensor
    readings, which are decoded (and checked) once, later, in the loop's pass; only a message that may hold a
    grant is decoded here."""
    if _GRANT_TYPE not in data:
        return None
    try:
        msg = wire.decode(wire.split_batch(data)[-1] if wire.is_batch(data) else data)
    except wire.WireError:
        return None
    return msg if isinstance(msg, wire.Grant) else None


async def connect_lockstep(endpoint: str, world: str) -> LockstepLink:
    """A lockstep link on a new client session to ``endpoint`` (HubUnavailable if nobody is there)."""
    link = await ZenohLink.connect(endpoint, world)
    return LockstepLink(link.session, link.keys, owns_session=True)
