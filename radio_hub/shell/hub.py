"""The radio hub process: a zenoh router whose job thread drives the ``Environment``'s medium on the wall
clock, and whose world thread runs the world's periodic work beside it.

Zenoh callbacks only hand samples to an inbox queue. The job thread takes them in arrival order,
stamps each with the model clock (microseconds since the hub started), feeds the environment, and sleeps
until the medium's next event with a timed wait. A plain thread is used rather than asyncio because
epoll's millisecond timeouts would add up to a millisecond of lag to every delivery; a timed queue
wait overshoots by tens of microseconds.

The world thread carries out the world ticks (with the body sensors, beacons and the world log), the IR
sweeps and the BLE deliveries (``Environment.advance_world``) under the environment's ``world_lock``, so a
tick of milliseconds never holds up a frame's delivery (docs/DESIGN.md, "The hub's two threads"). The job
thread needs that lock only for what is not a robot's frame: such an item that finds the lock taken is held,
with everything that came after it, until the tick is done (arrival order stays), while the medium goes on.

Nothing a client sends can end the job loop or grow the hub without bound (see README, "Bad input and
bounds"): the hub hears only ids with a liveliness token (``radio_hub.link.up_keys``); the inbox holds at most
``INBOX_PER_NODE`` messages per attached node and ``INBOX_STRANGERS`` from all other ids together (more are
dropped and counted in ``stats()["inbox"]``); an attach whose liveliness token does not show within
``ATTACH_TOKEN_TIMEOUT_S`` is detached; at most ``MAX_UNPROVEN`` such attaches wait at once; any exception in
a handler is counted in ``stats()["hub"]["faults"]`` and the loop goes on. A hub given its run's roster keeps room
for those ids everywhere a flood of other ids could take it: their up keys, their first messages (a bucket per id,
not the strangers'), their tokens' arrivals (a bucket per id) and the tokens remembered; and the job thread takes
their items ahead of the others at each pass.

With ``pcap_path`` the hub also writes every transmission that leaves the air, data frames and ACKs,
to a pcap file (``radio_hub.air.pcap``), stamped with the wall-clock time at which it started on the air.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import os
import queue
import sys
import threading
import time
from collections import Counter, deque
from collections.abc import Collection
from pathlib import Path
from typing import Any

import msgpack
import zenoh

from radio_hub.config import MediumConfig
from radio_hub.environment import (
    Environment,
    EnvironmentConfig,
    environment_from_dict,
    load_config,
    process_usage,
)
from radio_hub.link import wire
from radio_hub.link.keys import WORLD_THREAD, Keys, check_name
from radio_hub.link.up_keys import UpKeys
from radio_hub.link.zenoh_link import HubDownlink, declare_hub_keys, reply, session_config
from radio_hub.physics.light import IrConfig

__all__ = ["Environment", "EnvironmentConfig", "RadioHub", "environment_from_dict", "load_config", "ready_line"]

_IDLE_WAKE_US = 200_000
_HELD_POLL_US = 200
_NEVER = 1 << 62
"""While items wait for a world tick to end, the job thread looks again this often."""
SWITCH_INTERVAL_S = 0.001
"""The interpreter's thread switch interval in the hub: the job thread waits at most about this long for the
world thread to give up the interpreter (Python's default, 5 ms, could add up to 5 ms to a delivery). At 0.2 ms
the forced switches cost more CPU: bench hub at 50 nodes, two runs each, hub 277/300 us per frame against
232/212 at 1 ms and 273/244 at 5 ms (load 8.6-9.6, so only the order is to be trusted)."""
_SPIN_US = 100
"""Sleep until this close to the next model event, then spin: deliveries land within a few us of model time."""

_PR_SET_TIMERSLACK = 29
_PR_SET_NAME = 15

INBOX_PER_NODE = 1000
"""Messages of one attached node waiting in the inbox; a node past it loses its newest (counted)."""
INBOX_STRANGERS = 1000
"""Messages of every id that is not attached (first attaches included) waiting in the inbox, together."""
STRANGERS_PER_S = 2000
"""Messages of ids that are not attached taken into the inbox per second, together (attaches included: a
swarm of 50 attaches in well under a second); the rest are dropped in zenoh's thread at once. Such ids have a
liveliness token (the hub hears no other), so this bounds a rogue that declares tokens, not a flood of
made-up ids, which never reaches the hub."""
INBOX_OTHER = 1000
"""Queries and liveliness changes waiting in the inbox."""
INBOX_BUCKET_BYTES = 4 << 20
"""Bytes of node messages one bucket (an attached node, or all strangers) may have waiting: with the counts,
the inbox never holds more than (attached nodes + 1) x 4 MB."""
BATCH = 256
"""Inbox items taken at most before the environment advances (a flood never holds up the air)."""
ATTACH_TOKEN_TIMEOUT_S = 5.0
"""An attached node whose liveliness token has not shown (or has gone) this long is detached."""
MAX_UNPROVEN = 64
"""Attached nodes without a liveliness token at once; a further attach without one is refused (counted)."""
TOKENS_KEPT = 4096
"""Liveliness tokens remembered; past it, tokens of ids that are not attached are forgotten first (never a roster
id's)."""
ROSTER_TOKENS_PER_ID = 8
"""Tokens of one roster id remembered at once (a node and the restarts of it that overlap): outside
``TOKENS_KEPT``, so that others' tokens cannot push a roster id's out, and bounded, as anyone may use the name."""
ROSTER_ALIVE_WAITING = 64
"""A roster id's token arrivals and departures waiting in the inbox (a bucket per id, outside ``INBOX_OTHER``)."""
_EXPIRY_EVERY_US = 500_000
_S_FIELD = msgpack.packb("s")
_WAKE_ITEM = ("wake",)
MAX_CHAOS_REQUEST_BYTES = 32 << 10
"""A chaos request's bytes at most: a fault with a partition of ``MAX_GROUP`` ids of 64 characters fits."""


class RadioHub:
    """The emulated environment of one world, served over zenoh on the wall clock."""

    def __init__(
        self,
        endpoint: str,
        world: str,
        config: MediumConfig | None = None,
        seed: int = 0,
        ir_config: IrConfig | None = None,
        pcap_path: str | Path | None = None,
        environment: EnvironmentConfig | None = None,
        world_log: str | Path | None = None,
        roster: Collection[str] = (),
    ) -> None:
        """Raises OSError when ``pcap_path`` or ``world_log`` is given and cannot be opened for writing, ValueError
        when a roster id is not a node name.

        ``environment`` gives every table at once (``config`` and ``ir_config`` override its medium and IR);
        ``world_log`` receives one JSON line per world tick (the ground truth a run's metrics come from);
        ``roster``: the node ids the run starts, for which room is kept whatever other ids do (see the module).
        """
        env = environment or EnvironmentConfig()
        tables = EnvironmentConfig(config or env.medium, ir_config or env.ir, env.world, env.ble, env.lf, env.obstacles)
        self.endpoint = endpoint
        self.keys = Keys(world)
        self.seed = seed
        self.roster = frozenset(check_name("node", node_id) for node_id in roster)
        self._downlink = HubDownlink(self.keys, is_member=lambda node_id: node_id in self.env.kinds, batching=True)
        self._t0_ns = time.perf_counter_ns()
        self.env = Environment(
            tables,
            seed,
            self._downlink,
            wall_epoch_us=time.time_ns() // 1000,
            pcap_path=pcap_path,
            world_log=world_log,
        )
        self.env.holder_alive = self._token_present
        self._inbox: queue.SimpleQueue[tuple[Any, ...]] = queue.SimpleQueue()
        self._stop = threading.Event()
        self._world_wake = threading.Event()
        """Set when the job thread made the world thread's next work due sooner than it sleeps (a BLE send...)."""
        self._world_due = _NEVER
        """When the world thread means to wake (``_NEVER`` while it is working out when)."""
        self._first: deque[tuple[Any, ...]] = deque()
        """Inbox items of roster ids (their messages, token events and departures), taken before the inbox's
        other items at each pass (a ``("wake",)`` in the inbox wakes the job thread for them): a backlog of other
        nodes' traffic delays a roster id's attach by one batch at most."""
        self._held: deque[tuple[Any, ...]] = deque()
        """Inbox items taken that wait for the world lock, in arrival order (nothing more is taken meanwhile)."""
        self._session: zenoh.Session | None = None
        self._decls: list[Any] = []
        self._up_keys: UpKeys | None = None
        self._waiting: dict[str, list[int]] = {}
        """Inbox items and their bytes per bucket: an attached node's id, ``""`` for every other id, ``"?"`` for
        the rest (a bucket that empties goes, so no key per departed node stays behind)."""
        self._waiting_lock = threading.Lock()
        self.inbox_dropped: Counter[str] = Counter()
        """Items refused at the inbox: ``node`` (an attached node past its limit), ``stranger``, ``other``,
        ``oversized`` (longer than ``wire.MAX_UP_BYTES``)."""
        self._stranger_window = (0.0, 0)
        """(start of the current second, strangers admitted in it)."""
        self._tokens: dict[tuple[str, str], None] = {}
        """Liveliness tokens present, (node id, instance)."""
        self._roster_tokens: Counter[str] = Counter()
        """Of those, how many each roster id has (``ROSTER_TOKENS_PER_ID`` at most)."""
        self._tokenless: dict[str, int] = {}
        """Attached nodes without a token, and since when (model us)."""
        self.expired = 0
        self.refused_unproven = 0
        self.tokens_dropped = 0
        self._next_expiry_us = 0

    @property
    def medium(self) -> Any:
        """The environment's 802.15.4 medium."""
        return self.env.medium

    @property
    def environment(self) -> EnvironmentConfig:
        """The environment's tables."""
        return self.env.config

    def now_us(self) -> int:
        """The model clock: microseconds of wall time since the hub opened."""
        return (time.perf_counter_ns() - self._t0_ns) // 1000

    def open(self) -> None:
        """Open the router session and declare the hub's keys. Raises zenoh.ZError if it cannot listen."""
        session = zenoh.open(session_config("router", self.endpoint))
        self._session = session
        self._up_keys, self._decls = declare_hub_keys(
            session, self.keys, self._admit, oversized=self._oversized, faults=self.env.faults, roster=self.roster
        )
        self._downlink.world_pub = session.declare_publisher(self.keys.world_state)
        self._decls.append(self._downlink.world_pub)
        self._downlink.session = session
        self._t0_ns = time.perf_counter_ns()
        self.env.wall_epoch_us = time.time_ns() // 1000

    def stop(self) -> None:
        """Ask the job loop to end (from any thread)."""
        self._stop.set()
        self._world_wake.set()
        self._inbox.put(("wake",))

    def close(self) -> None:
        """Undeclare everything, close the session, the pcap file and the world log."""
        self.env.close()
        self._downlink.session = None
        for decl in self._decls:
            decl.undeclare()
        self._decls, self._up_keys = [], None
        if self._session is not None:
            self._session.close()
            self._session = None

    def serve(self) -> None:
        """Run the job loop, and the world thread beside it, until ``stop``. Nothing a client sends ends them: a
        handler's exception is counted (``stats()["hub"]["faults"]``) and the loop goes on."""
        _tight_timer_slack()
        switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        world = threading.Thread(target=self._serve_world, name=WORLD_THREAD, daemon=True)
        world.start()
        try:
            self._serve_medium()
        finally:
            self._stop.set()
            self._world_wake.set()
            world.join()
            sys.setswitchinterval(switch_interval)

    def _serve_medium(self) -> None:
        inbox, now_us = self._inbox, self.now_us
        while not self._stop.is_set():
            due = self._next_due_us()
            until_due = min(due - now_us(), _IDLE_WAKE_US)
            item: tuple[Any, ...] | None = None
            if self._held:
                # items wait for the world thread's tick: the inbox waits behind them, the medium goes on
                if until_due > _SPIN_US:
                    time.sleep(min(until_due - _SPIN_US, _HELD_POLL_US) / 1e6)
                self._take_held()
            elif until_due > _SPIN_US:
                with contextlib.suppress(queue.Empty):
                    item = inbox.get(timeout=(until_due - _SPIN_US) / 1e6)
            else:
                # a timed wait wakes tens of microseconds late: yield-spin the last stretch, watching only the
                # clock and the inbox (no environment work until something is due or has come)
                while inbox.empty() and now_us() < due:
                    os.sched_yield()
                if not inbox.empty():
                    item = inbox.get_nowait()
            if item is not None:
                self._take(item)
            # what the items scheduled may be due already; with nothing due, advancing would only cost time
            if now_us() >= self._next_due_us():
                self._advance_safely()
            self._flush_safely()  # one put per node per pass

    def _next_due_us(self) -> int:
        due = self.env.medium.next_event_us()
        return self._next_expiry_us if due is None else min(due, self._next_expiry_us)

    def _serve_world(self) -> None:
        """The world thread: the world's ticks, IR sweeps and BLE deliveries as they fall due."""
        _name_os_thread(WORLD_THREAD)
        env, wake, now_us = self.env, self._world_wake, self.now_us
        while not self._stop.is_set():
            wake.clear()
            self._world_due = _NEVER  # whatever the job thread changes from here on wakes this thread
            self._world_due = due = env.next_world_event_us()
            until_due = due - now_us()
            if until_due > 0:
                wake.wait(min(until_due, _IDLE_WAKE_US) / 1e6)
                continue
            try:
                env.advance_world(now_us())
            except Exception as err:
                self.env.faults.record("advance world", err)
            self._flush_safely()
            while self._held and not self._stop.is_set():
                # the job thread's turn: a world that falls behind (ticks back to back) must not starve it
                time.sleep(_HELD_POLL_US / 1e6)

    def _take(self, item: tuple[Any, ...]) -> None:
        """``item`` and whatever arrived meanwhile, ``BATCH`` at most, before time advances (a flood never holds up
        the air); from an item that must wait for the world lock on, they are held (``_take_held``)."""
        inbox, first = self._inbox, self._first
        self._take_first()
        if self._held or not self._handle_safely(item):
            self._held.append(item)
        for _ in range(min(inbox.qsize(), BATCH - 1)):
            if first:
                self._take_first()
            item = inbox.get_nowait()
            if self._held or not self._handle_safely(item):
                self._held.append(item)

    def _take_first(self) -> None:
        """The roster ids' items waiting (``_first``), in their order, held as the others are."""
        first, held = self._first, self._held
        while first:
            item = first.popleft()
            if held or not self._handle_safely(item):
                held.append(item)

    def _take_held(self) -> None:
        """The held items, in order, as far as the world lock lets them in."""
        held = self._held
        while held and self._handle_safely(held[0]):
            held.popleft()

    def _admit(self, item: tuple[Any, ...]) -> None:
        """Zenoh's threads: into the inbox if its bucket has room, else dropped and counted. A node's message
        goes in as ``("up", node id, bytes, bucket)``: its key is read here, once."""
        size, first = 0, False
        if item[0] == "up":
            node_id, size = self.keys.node_of(item[1]), len(item[2])
            # a roster id's first messages wait in its own bucket: no flood of strangers crowds out its attach
            own = self._own_marker(node_id) in item[2] if node_id in self.env.kinds else node_id in self.roster
            bucket, limit = (node_id, INBOX_PER_NODE) if own else ("", INBOX_STRANGERS)
            first = own and node_id in self.roster
            if not bucket and not self._stranger_admitted():
                return
            item = ("up", node_id, item[2])
        elif item[0] == "alive" and item[2] == zenoh.SampleKind.DELETE and self._departure_of_attached(item[1]):
            # a departure is never dropped, whatever the load: a dropped one left its body in the world for good
            # (at most one per attached node per token, so this is bounded by the attached nodes)
            bucket, limit = "!", 1 << 62
            first = self._roster_id_of(item[1]) is not None
        elif item[0] == "alive" and (roster_id := self._roster_id_of(item[1])) is not None:
            # a roster id's token must reach the job thread however many other tokens come and go
            bucket, limit, first = f"?{roster_id}", ROSTER_ALIVE_WAITING, True
        else:
            bucket, limit = "?", INBOX_OTHER
        with self._waiting_lock:
            waiting = self._waiting.get(bucket)
            if waiting is None:
                waiting = self._waiting[bucket] = [0, 0]
            full = waiting[0] >= limit or waiting[1] + size > INBOX_BUCKET_BYTES
            if full:
                self.inbox_dropped["other" if bucket[:1] == "?" else "stranger" if bucket == "" else "node"] += 1
                if not waiting[0]:
                    del self._waiting[bucket]
            else:
                waiting[0] += 1
                waiting[1] += size
        if full:
            if item[0] in ("stats", "air", "world", "chaos"):
                item[1].drop()  # the query ends unanswered
            return
        if first:
            self._first.append((*item, bucket))
            self._inbox.put(_WAKE_ITEM)
        else:
            self._inbox.put((*item, bucket))

    def _own_marker(self, node_id: str) -> bytes:
        """The bytes every message of ``node_id``'s own session carries (its session key ``s`` in the envelope).
        Traffic on a member's key without them goes with strangers' (their bucket and rate), so a flood from
        another session on that key cannot crowd out the member's own messages (it silenced robot-1). The test is
        a byte search, cheap in zenoh's thread; a message that carries the bytes but not as its key is still
        refused by the environment (``foreign``)."""
        key = self.env.session_key_of(node_id)
        return _S_FIELD + msgpack.packb(key) if key else b""  # a key of 0 is left out of the envelope

    def _roster_id_of(self, key: str) -> str | None:
        """The node id of a liveliness key when it is a roster id's (zenoh's thread)."""
        if not self.roster:
            return None
        node_id = self.keys.alive_of(key)[0]
        return node_id if node_id in self.roster else None

    def _departure_of_attached(self, key: str) -> bool:
        """Whether a token that went is one of an attached node's (zenoh's thread: a read of the kinds only)."""
        try:
            node_id, _ = self.keys.alive_of(key)
        except ValueError:
            return False
        return node_id in self.env.kinds

    def _stranger_admitted(self) -> bool:
        """Within ``STRANGERS_PER_S`` (else counted as dropped)."""
        now = time.monotonic()
        with self._waiting_lock:
            start, admitted = self._stranger_window
            if now - start >= 1.0:
                start, admitted = now, 0
            if admitted >= STRANGERS_PER_S:
                self.inbox_dropped["stranger"] += 1
                return False
            self._stranger_window = (start, admitted + 1)
            return True

    def _oversized(self) -> None:
        with self._waiting_lock:
            self.inbox_dropped["oversized"] += 1

    def _handle_safely(self, item: tuple[Any, ...]) -> bool:
        """False: the item needs the world lock, which the world thread holds; nothing was done (offer it again)."""
        if item[0] == "wake":
            return True
        try:
            done = self._handle(item[:-1])
        except Exception as err:
            self.env.faults.record(f"handle {item[0]}", err)
            done = True
        if not done:
            return False
        bucket, size = item[-1], len(item[2]) if item[0] == "up" else 0
        with self._waiting_lock:
            waiting = self._waiting[bucket]
            if waiting[0] > 1:
                waiting[0] -= 1
                waiting[1] -= size
            else:  # no key per departed node stays behind
                del self._waiting[bucket]
        return True

    def _advance_safely(self) -> None:
        now = self.now_us()
        try:
            if now >= self._next_expiry_us:
                self._expire_when_free(now)
            self.env.advance_medium(now)
        except Exception as err:
            self.env.faults.record("advance", err)

    def _flush_safely(self) -> None:
        try:
            self._downlink.flush()
        except Exception as err:
            self.env.faults.record("flush", err)

    def _expire_when_free(self, now: int) -> None:
        lock = self.env.world_lock
        if not lock.acquire(blocking=False):
            self._next_expiry_us = now + _HELD_POLL_US  # the world thread is busy: soon again
            return
        try:
            self._next_expiry_us = now + _EXPIRY_EVERY_US
            self._expire_tokenless(now)
        finally:
            lock.release()

    def _handle(self, item: tuple[Any, ...]) -> bool:
        """False when the item needs the world lock and the world thread has it (nothing done)."""
        if item[0] == "up" and item[1] in self.env.kinds:
            # a known node's frame needs no world lock; any other message takes it in the environment
            done = self.env.receive(item[1], item[2], self.now_us(), wait=False)
        elif self.env.world_lock.acquire(blocking=False):
            try:
                self._handle_locked(item)
            finally:
                self.env.world_lock.release()
            done = True
        else:
            return False
        if self.env.next_world_event_us() < self._world_due:
            self._world_wake.set()
        return done

    def _handle_locked(self, item: tuple[Any, ...]) -> None:
        kind = item[0]
        if kind == "up":
            node_id = item[1]
            known = node_id in self.env.kinds
            if not known and self._refuse_unproven(node_id, item[2]):
                return
            self.env.receive(node_id, item[2], self.now_us())
            instance = self.env.instance_of(node_id)
            if not known and instance is not None and (node_id, instance) not in self._tokens:
                self._tokenless.setdefault(node_id, self.now_us())  # counts towards MAX_UNPROVEN at once
        elif kind == "alive":
            node_id, instance = self.keys.alive_of(item[1])
            if item[2] == zenoh.SampleKind.DELETE:
                present = self._tokens.pop((node_id, instance), False) is None
                if present and node_id in self.roster:
                    self._roster_tokens[node_id] -= 1
                    if not self._roster_tokens[node_id]:
                        del self._roster_tokens[node_id]
                self.env.node_gone(node_id, instance, self.now_us())
            else:
                self._token_seen(node_id, instance)
        elif kind == "stats":
            reply(item[1], self.stats())
        elif kind == "air":
            reply(item[1], self.env.air())
        elif kind == "chaos":
            query = item[1]
            if query.payload is not None and len(query.payload) > MAX_CHAOS_REQUEST_BYTES:
                self.env.counters.chaos_refused += 1
                reply(query, {"error": f"a chaos request is at most {MAX_CHAOS_REQUEST_BYTES} bytes"})
                return
            try:
                request = msgpack.unpackb(query.payload.to_bytes(), raw=False) if query.payload else {}
            except Exception as err:  # a bad request must not hurt the hub
                self.env.counters.chaos_refused += 1
                reply(query, {"error": f"{type(err).__name__}: {str(err)[:300]}"})
                return
            reply(query, self.env.chaos_request(request, self.now_us(), time.time()))
        elif kind == "world":
            reply(item[1], self.env.world_state(self.now_us()))

    # -- liveliness: an attach is only kept while its process's token is there -------------------------------

    def _token_present(self, node_id: str, instance: str) -> bool:
        return (node_id, instance) in self._tokens

    def _token_seen(self, node_id: str, instance: str) -> None:
        tokens, roster = self._tokens, self.roster
        if (node_id, instance) in tokens:
            return
        if node_id in roster:  # outside TOKENS_KEPT: others' tokens cannot push it out
            if self._roster_tokens[node_id] >= ROSTER_TOKENS_PER_ID:
                self.tokens_dropped += 1
                return
            self._roster_tokens[node_id] += 1
            tokens[(node_id, instance)] = None
            return
        if len(tokens) - self._roster_tokens.total() >= TOKENS_KEPT:
            kinds = self.env.kinds
            for key in [k for k in tokens if k[0] not in kinds and k[0] not in roster]:
                del tokens[key]
        if len(tokens) - self._roster_tokens.total() >= TOKENS_KEPT:
            self.tokens_dropped += 1
            return
        tokens[(node_id, instance)] = None

    def _refuse_unproven(self, node_id: str, data: bytes) -> bool:
        """An attach from an id that is not attached, without a token, when ``MAX_UNPROVEN`` wait already."""
        if len(self._tokenless) < MAX_UNPROVEN:
            return False
        try:
            msg = wire.decode(data, wire.MAX_UP_BYTES)
        except wire.WireError:
            return False  # the environment counts it
        if not isinstance(msg, wire.Attach) or (node_id, msg.instance) in self._tokens:
            return False
        self.refused_unproven += 1
        return True

    def _expire_tokenless(self, now_us: int) -> None:
        """Detach nodes whose liveliness token has been missing for ``ATTACH_TOKEN_TIMEOUT_S``."""
        env, tokenless = self.env, self._tokenless
        for node_id in list(tokenless):
            if node_id not in env.kinds:
                del tokenless[node_id]
        for node_id in env.kinds:
            instance = env.instance_of(node_id) or ""
            if (node_id, instance) in self._tokens:
                tokenless.pop(node_id, None)
            else:
                tokenless.setdefault(node_id, now_us)
        for node_id, since in list(tokenless.items()):
            if now_us - since >= ATTACH_TOKEN_TIMEOUT_S * 1e6:
                del tokenless[node_id]
                self.expired += 1
                env.node_gone(node_id, env.instance_of(node_id) or "", now_us)

    def stats(self) -> dict[str, Any]:
        """The environment's counters, with this hub's world name and model clock."""
        stats = {"world": self.keys.world, **self.env.stats(self.now_us()), "process": process_usage()}
        with self._waiting_lock:
            waiting, dropped = sum(count for count, _ in self._waiting.values()), dict(self.inbox_dropped)
        stats["inbox"] = {
            "waiting": waiting,
            "dropped": dropped,
            "limits": {
                "per_node": INBOX_PER_NODE,
                "strangers": INBOX_STRANGERS,
                "strangers_per_s": STRANGERS_PER_S,
                "other": INBOX_OTHER,
                "bucket_bytes": INBOX_BUCKET_BYTES,
            },
        }
        stats["liveliness"] = {
            "tokens": len(self._tokens),
            "tokenless": len(self._tokenless),
            "expired": self.expired,
            "refused_unproven": self.refused_unproven,
            "tokens_dropped": self.tokens_dropped,
            "timeout_s": ATTACH_TOKEN_TIMEOUT_S,
            "up_keys_open": self._up_keys.open_count if self._up_keys is not None else 0,
            "up_keys_refused": self._up_keys.refused if self._up_keys is not None else 0,
            "up_keys_waiting": self._up_keys.waiting_count if self._up_keys is not None else 0,
            "up_keys_others_open": self._up_keys.others_open if self._up_keys is not None else 0,
            "roster": len(self.roster),
        }
        stats["hub"]["stranger_answers_dropped"] = self._downlink.stranger_answers_dropped
        stats["hub"]["down_messages"] = self._downlink.messages
        stats["hub"]["down_puts"] = self._downlink.puts
        return stats


def _tight_timer_slack() -> None:
    # Linux lets a sleeping thread wake up to 50 us late by default (timer slack); deliveries are
    # timed to the microsecond, so ask for 1 us. Best effort: other kernels keep their default.
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_TIMERSLACK, 1000)


def _name_os_thread(name: str) -> None:
    # best effort, Linux only: so the thread can be told apart in /proc and top
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_NAME, name.encode()[:15])


def ready_line(hub: RadioHub) -> str:
    """The one JSON line a hub prints on stdout once it serves, for supervisors to wait on."""
    return json.dumps({"event": "hub_ready", "endpoint": hub.endpoint, "world": hub.keys.world, "seed": hub.seed})
