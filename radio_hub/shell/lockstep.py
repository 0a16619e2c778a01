"""``--clock lockstep``: node processes over zenoh on model time that the hub owns.

The rules are the coordinator's (``radio_hub.coordinator``); this module carries them between processes.

- A node's ``LockstepLink`` (``radio_hub.link.lockstep_link``) holds every message from the hub until the
  ``Grant`` that closes its round. On the grant its loop (``petswarm.clock.LockstepLoop``) moves to the
  granted instant and runs what is due; once nothing is ready the held messages are released in order; once
  nothing is ready again it reports ``Idle`` with the number of the grant it has handled and its next timer, and blocks.
- ``LockstepHub`` waits until every node has reported idle for the last grant it was sent. Then it settles
  what nodes sent in this instant, or, when there is nothing, moves model time to the earliest next timer or
  environment event; it sends each node concerned its messages, then a ``Grant``.

Why a message in flight can never be overtaken: each direction of a node's link is one reliable zenoh
publisher, so order holds per direction. A node's ``Idle`` goes on the same publisher after its messages, so
the hub has them all when it sees the idle; the hub's ``Grant`` goes after the round's messages to that
node, and the node's ``Idle`` names the grant, so an idle that predates messages in flight never counts.
A node that stops answering (killed, paused, cut off) is taken as gone after ``dead_after_s`` of wall time
waiting for it, or at once when its liveliness token goes; the world goes on without it.
"""

from __future__ import annotations

import contextlib
import queue
import sys
import threading
import time
from collections.abc import Collection
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import zenoh

from radio_hub.link import wire
from radio_hub.link.keys import Keys
from radio_hub.link.zenoh_link import (
    HubDownlink,
    declare_hub_keys,
    reply,
    session_config,
)

if TYPE_CHECKING:
    from radio_hub.environment import EnvironmentConfig

DEAD_AFTER_S = 10.0
"""Wall seconds the hub waits for a granted node's idle before it takes the node as gone."""
CLOCK_RESOLUTION_S = time.get_clock_info("monotonic").resolution
"""asyncio runs every timer due within this of the loop's time in one go; the hub grants the same way."""
START_WITHIN_BASE_S = 60.0
START_WITHIN_PER_NODE_S = 1.0
"""Model time starts when every expected node is there, or, if some never come (a process that died at start),
after START_WITHIN_BASE_S + START_WITHIN_PER_NODE_S x expected nodes of wall time, without them (recorded)."""
LOOK_EVERY_S = 0.05
"""How often (wall seconds) the hub looks for silent or leaving nodes: a round takes about a millisecond."""
LEAVING_GRACE_S = 1.0
"""Wall seconds a busy node whose liveliness ended has for its last messages (and Detach) to arrive: zenoh
orders a node's messages but not its liveliness against them."""


@dataclass
class _Node:
    """The hub's view of one node's clock."""

    granted: int = 0
    """The number of the last grant sent to it (0: none yet)."""
    idle: bool = False
    next_s: float | None = None
    waiting_since: float = field(default_factory=time.monotonic)
    dying_since: float | None = None
    """Wall time its liveliness ended while it was busy (it may be leaving cleanly)."""
    key: int = 0
    """The session key of its Attach: an idle with another is an earlier process's of the same id."""


class LockstepHub:
    """The environment served over zenoh on model time: nodes are granted instants, never the wall clock."""

    def __init__(
        self,
        endpoint: str,
        world: str,
        environment: EnvironmentConfig,
        seed: int = 0,
        *,
        expect: int = 1,
        dead_after_s: float = DEAD_AFTER_S,
        start_within_s: float | None = None,
        pcap_path: str | Path | None = None,
        world_log: str | Path | None = None,
        roster: Collection[str] = (),
    ) -> None:
        """``roster``: the node ids the run starts, whose up keys open outside the cap (``UpKeys``). ``expect``: model
        time starts once this many nodes have reported idle (a run's robots, its user and
        its orchestrator), so every node attaches in the first instant whatever order processes start in; if some
        have not come within ``start_within_s`` of wall time (default: 60 s + 1 s per expected node), it starts
        without them and records how many were missing, rather than wait forever."""
        # the hub's side is imported here: a lockstep node process (a robot) needs only LockstepLink
        from radio_hub.coordinator import MODEL_EPOCH_US, Coordinator

        self.endpoint = endpoint
        self.keys = Keys(world)
        self.seed = seed
        self.roster = tuple(roster)
        self.expect = expect
        self.dead_after_s = dead_after_s
        self.start_within_s = (
            START_WITHIN_BASE_S + START_WITHIN_PER_NODE_S * expect if start_within_s is None else start_within_s
        )
        self._opened_at = time.monotonic()
        self.coordinator = Coordinator(
            environment, seed, wall_epoch_us=MODEL_EPOCH_US, pcap_path=pcap_path, world_log=world_log
        )
        self.env = self.coordinator.env
        # a node's messages of a round and its grant leave in one put (one batch): a zenoh put and its
        # delivery cost the hub and the node more than the messages' own work, and a round ends with the grant
        self._downlink = HubDownlink(self.keys, batching=True)
        self.coordinator.on_world = self._downlink.publish_world
        self.nodes: dict[str, _Node] = {}
        self.dead: list[dict[str, Any]] = []
        self.rounds = 0
        self.stale_idles = 0
        """Idles of nodes already taken as gone, that were only slow (counted and dropped)."""
        self.up_puts = 0
        """Transport messages nodes put to the hub (a batch counts once)."""
        self.grants = 0
        self.now_s = 0.0
        self._looked_at = 0.0
        """Wall time the hub last looked for nodes that are silent too long."""
        self._started = False
        self._inbox: queue.SimpleQueue[tuple[Any, ...]] = queue.SimpleQueue()
        self._stop = threading.Event()
        self._session: zenoh.Session | None = None
        self._decls: list[Any] = []

    def open(self) -> None:
        """Open the router session and declare the hub's keys. Raises zenoh.ZError if it cannot listen."""
        session = zenoh.open(session_config("router", self.endpoint))
        self._session = session
        self._opened_at = time.monotonic()
        _, self._decls = declare_hub_keys(
            session, self.keys, self._inbox.put, chaos=False, faults=self.env.faults, roster=self.roster
        )
        self._downlink.world_pub = session.declare_publisher(self.keys.world_state)
        self._decls.append(self._downlink.world_pub)
        self._downlink.session = session

    def stop(self) -> None:
        """Ask the job loop to end (from any thread)."""
        self._stop.set()
        self._inbox.put(("wake",))

    def close(self) -> None:
        """Undeclare everything, close the session and the environment's files."""
        self.coordinator.close()
        self._downlink.close()
        for decl in self._decls:
            with contextlib.suppress(zenoh.ZError):
                decl.undeclare()
        self._decls = []
        if self._session is not None:
            self._session.close()
            self._session = None

    def serve(self) -> None:
        """Run rounds until ``stop``."""
        while not self._stop.is_set():
            try:
                self._handle_safely(self._inbox.get(timeout=0.5))
                while True:
                    self._handle_safely(self._inbox.get_nowait())
            except queue.Empty:
                pass
            try:
                self._bury_the_silent()
                self._run_rounds()
            except Exception as err:  # counted in stats; the rounds go on with the next input
                self.env.faults.record("rounds", err)

    def _handle_safely(self, item: tuple[Any, ...]) -> None:
        try:
            self._handle(item)
        except Exception as err:  # nothing a client sends ends the hub
            self.env.faults.record(f"handle {item[0]}", err)

    def stats(self) -> dict[str, Any]:
        """The environment's counters, with the lockstep clock's."""
        stats = {"world": self.keys.world, **self.env.stats()}
        stats["lockstep"] = {
            "model_time_s": self.now_s,
            "rounds": self.rounds,
            "nodes": len(self.nodes),
            "stale_idles": self.stale_idles,
            "dead": self.dead,
            "down_puts": self._downlink.puts,
            "down_messages": self._downlink.messages,
            "up_puts": self.up_puts,
            "grants": self.grants,
        }
        from radio_hub.environment import process_usage

        stats["process"] = process_usage()
        return stats

    # -- inputs ---------------------------------------------------------------------------------------------

    def _handle(self, item: tuple[Any, ...]) -> None:
        kind = item[0]
        if kind == "up":
            self.up_puts += 1
            self._on_up(self.keys.node_of(item[1]), item[2])
        elif kind == "alive" and item[2] == zenoh.SampleKind.DELETE:
            node_id, instance = self.keys.alive_of(item[1])
            node = self.nodes.get(node_id)
            if node is not None and self.env.instance_of(node_id) in (instance, None):
                if node.idle:  # it died waiting: nothing of it can still be in flight
                    self._gone(node_id, instance, "its liveliness ended")
                else:  # it may be leaving cleanly: its last messages and Detach may still be on the way
                    node.dying_since = time.monotonic()
        elif kind == "stats":
            reply(item[1], self.stats())
        elif kind == "air":
            reply(item[1], self.env.air())
        elif kind == "world":
            reply(item[1], self.env.world_state())

    def _on_up(self, node_id: str, data: bytes) -> None:
        if wire.is_batch(data):  # a node's messages of a round and its idle, in order
            try:
                parts = wire.split_batch(data, wire.MAX_UP_BYTES)
            except wire.WireError:
                self.env.counters.malformed += 1
                return
            for part in parts:
                self._on_message_up(node_id, part)
        else:
            self._on_message_up(node_id, data)

    def _on_message_up(self, node_id: str, data: bytes) -> None:
        try:
            msg = wire.decode(data, wire.MAX_UP_BYTES)
        except wire.WireError:
            msg = None  # the environment gets the bytes, and counts them as it counts every malformed message
        node = self.nodes.get(node_id)
        # the key of the node's own Attach (held until its round settles, so the world may not have it yet),
        # else the world's: another session's idle (an earlier process of the id) must not move this node's rounds
        key = node.key if node is not None and node.key else self.env.session_key_of(node_id)
        if isinstance(msg, wire.Idle) and key is not None and msg.s != key:
            self.env.counters.foreign += 1
            return
        if node is None:
            if isinstance(msg, wire.Idle) and msg.seen:
                # a node taken as gone that was only slow: it was granted before, so brought back it would
                # wait for a grant the hub never sends it, and the hub for its idle: the world would stall
                self.stale_idles += 1
                return
            if not isinstance(msg, (wire.Attach, wire.Idle)):  # the last words of a node that has left
                self.coordinator.up(node_id, data if msg is None else msg)
                return
            node = self.nodes[node_id] = _Node()
        if isinstance(msg, wire.Idle):
            node.next_s = msg.next_s
            node.idle = msg.seen == node.granted
            return
        node.idle = False  # it sent something: it is busy until it says idle again
        if isinstance(msg, wire.Attach):
            node.key = msg.s
        self.coordinator.up(node_id, data if msg is None else msg)  # decoded once: the environment re-checks only
        if isinstance(msg, wire.Detach):
            self.nodes.pop(node_id, None)  # it leaves: no idle will come

    def _gone(self, node_id: str, instance: str, why: str) -> None:
        self.nodes.pop(node_id, None)
        self.coordinator.leave(node_id, instance)
        self.dead.append({"node": node_id, "model_time_s": self.now_s, "why": why})
        print(f"hub: {node_id} is gone at model time {self.now_s:.6f} s: {why}", file=sys.stderr, flush=True)

    def _bury_the_silent(self) -> None:
        wall = time.monotonic()
        if wall - self._looked_at < LOOK_EVERY_S:  # patience is seconds: no need to look every round
            return
        self._looked_at = wall
        for node_id, node in list(self.nodes.items()):
            instance = self.env.instance_of(node_id) or ""
            if node.dying_since is not None and wall - node.dying_since > LEAVING_GRACE_S:
                self._gone(node_id, instance, "its liveliness ended")
            elif not node.idle and wall - node.waiting_since > self._patience(node):
                self._gone(node_id, instance, f"no idle within {self._patience(node):g} s of wall time")

    def _patience(self, node: _Node) -> float:
        """Wall seconds a busy node has for its idle: ``dead_after_s`` once it was granted or model time runs;
        before that, a node that attached and never said idle has the start's window (a slow start is normal),
        and then goes, so that neither the start nor the world waits on it for good."""
        return self.dead_after_s if node.granted or self._started else self.start_within_s

    # -- the rounds ---------------------------------------------------------------------------------------

    def _run_rounds(self) -> None:
        while self.nodes and all(node.idle for node in self.nodes.values()):
            if not self._started:
                if len(self.nodes) < self.expect:
                    if time.monotonic() - self._opened_at < self.start_within_s:
                        return
                    self._record_missing()
                self._started = True
                # instant 0 opens like any other, with the environment's events (the first world tick) before
                # what nodes sent: in model time the environment's timer at 0 runs before the nodes' attaches
                self.coordinator.advance(0)
            now_us = round(self.now_s * 1e6)
            if self.coordinator.settle(now_us):
                self._deliver(set())
                continue
            timers = [node.next_s for node in self.nodes.values() if node.next_s is not None]
            self.now_s = max(self.now_s, min([self.coordinator.next_event_us() / 1e6, *timers]))
            self.coordinator.advance(round(self.now_s * 1e6))
            # due as an asyncio loop counts it (within its clock resolution), which is what model time does
            horizon = self.now_s + CLOCK_RESOLUTION_S
            due = {nid for nid, node in self.nodes.items() if node.next_s is not None and node.next_s < horizon}
            self._deliver(due)

    def _record_missing(self) -> None:
        """The start's wait is over: the nodes that never came are recorded as gone before model time begins."""
        missing = self.expect - len(self.nodes)
        why = f"{missing} of {self.expect} expected nodes did not come within {self.start_within_s:g} s of wall time"
        self.dead.append({"node": "missing", "model_time_s": 0.0, "why": why})
        print(f"hub: model time starts without them: {why}", file=sys.stderr, flush=True)

    def _deliver(self, due: set[str]) -> None:
        """The round's messages to every node concerned, each followed by its grant."""
        self.rounds += 1
        downs = self.coordinator.take_downs()
        wall = time.monotonic()
        for node_id in [*downs, *sorted(due - downs.keys())]:
            node = self.nodes.get(node_id)
            if node is None:
                continue
            grant = wire.Grant(at_s=self.now_s)
            self.env.send_to(node_id, grant)
            self.grants += 1
            node.granted, node.idle, node.waiting_since = grant.n, False, wall
        for node_id, messages in self.coordinator.take_downs().items():
            for data in [*downs.pop(node_id, []), *messages]:
                self._downlink.send(node_id, data)
        for node_id, messages in downs.items():  # messages for nodes not in the round (gone meanwhile)
            for data in messages:
                self._downlink.send(node_id, data)
        self._downlink.flush()
