"""The hub's ears: one subscription per node id that is there, never one on every up key.

A node is there while a liveliness token of its id is (``Keys.alive``). The hub subscribes to that node's up
key when the first token of the id shows and lets the subscription go ``UP_KEY_GRACE_S`` after the last one
went. Why not a single subscriber on ``up/*``: zenoh calls the hub's Python back for every message on it, a
made-up id's too, and a flood of 50,000 messages a second for made-up ids took 0.75-0.9 of a core in the hub
on its own and starved the robots beside it on a loaded two-core machine. A zenoh publisher sends only while it
knows of a matching subscriber, so a message for an id that has no token now stops in the process that sends it
and costs the hub nothing. The other side of the bargain: a node waits until its key is open before it says anything
(``wait_for_up_key``).

Room is kept for a run's own nodes. Zenoh does not tell the hub which session declared a token (a liveliness
sample carries no source; a put's ``source_info`` is whatever the sender writes), so without TLS a bound per session
cannot be enforced, and one session's tokens could take every key of the cap. A hub started with a roster (the node
ids its run starts: ``petswarm run`` gives its own) opens the key of a roster id whenever a token of it comes, outside
the cap, and handles roster ids' tokens ahead of the others: whatever any session does with other names, the run's
nodes are heard. Only a token under a roster id's own name touches that id (without TLS anyone can use any name;
with TLS a certificate holds one id).
"""

from __future__ import annotations

import itertools
import queue
import threading
import time
from collections.abc import Callable, Collection
from typing import Any

import zenoh

from radio_hub.guard import Faults
from radio_hub.link.keys import Keys, check_name

UP_KEY_GRACE_S = 2.0
"""Wall seconds a node's up key stays open after its last token went: zenoh sends a declaration's end ahead of
data still queued, so a node's last messages (its Detach) can arrive after its token's end."""
UP_KEYS_MAX = 1024
"""Node ids outside the roster with an open up key at once; a token of a further id opens none (counted in
``refused``); a roster id's key is opened whatever this count (``UpKeys``'s ``roster``). Five times
the largest swarm a bench runs (200 nodes), and no more: a router's declare_subscriber takes time in proportion
to the subscriptions it has (0.27 ms of CPU at 512, 4.4 ms at 4,096), and each subscription with a Python
callback had a Python thread of its own in zenoh-python (about 17 kB resident), so a rogue's tokens at a cap of
4,096 added 88-93 MB and 4,096 threads to the hub. The up keys' callbacks now run in zenoh's own receiving thread
(``indirect=False``; the callback is a hand-off to the inbox and never calls zenoh): 1,088 tokens added 1,024
threads and 22 MB before, no thread and 5 MB since (tests/process/test_up_keys_bound.py)."""
UP_KEYS_WAITING_MAX = UP_KEYS_MAX
"""Node ids refused for want of room whose tokens the hub remembers, oldest first, to open their keys as room
frees (a node whose key the cap withheld while a rogue held it is heard once the rogue goes); ids past this are
refused for good, as each costs the hub a set of its tokens."""
UP_MATCH_WAIT_S = 5.0
"""Wall seconds a node waits for the hub to open its up key. Then a wall-clock node speaks anyway and sends its
first attach again until answered (``RadioClient.connect``); a lockstep node gives up (``LockstepLink.open``)."""

_WAKE = ("wake", None)
"""Put by ``undeclare`` so that the thread, blocked on an empty queue, sees ``_ended``."""
_FIRST, _ROSTER, _OTHER = 0, 1, 2
"""Ranks in the thread's queue: ``_WAKE`` first, then roster ids' tokens, then all others (each in arrival order)."""


class UpKeys:
    """The hub's per-node subscriptions (see the module), kept by a thread of their own that watches tokens.

    ``on_up`` gets each sample on an open up key (zenoh's thread); ``on_alive`` gets ``("alive", key, kind)``
    for every token that comes or goes, after the key it opens is open; a key closes ``grace_s`` after the last
    token of its id went. ``roster``: node ids whose keys open outside ``UP_KEYS_MAX`` and whose tokens are
    handled before any other id's (see the module). What the thread cannot handle is counted in ``faults``.
    ``undeclare`` ends it all. Raises ValueError when a roster id is not a node name."""

    def __init__(
        self,
        session: zenoh.Session,
        keys: Keys,
        on_up: Callable[[zenoh.Sample], None],
        on_alive: Callable[[tuple[Any, ...]], None],
        grace_s: float = UP_KEY_GRACE_S,
        faults: Faults | None = None,
        roster: Collection[str] = (),
    ) -> None:
        self.roster = frozenset(check_name("node", node_id) for node_id in roster)
        """The run's own node ids: their keys are not counted in ``UP_KEYS_MAX`` and open whenever a token comes."""
        self._session, self._keys, self._on_up, self._on_alive = session, keys, on_up, on_alive
        self._grace_s = grace_s
        self.faults = faults or Faults("hub")
        """Where an event the thread could not handle is counted (a token is network input): the thread goes on."""
        self._instances: dict[str, set[str]] = {}
        """The tokens (instances) present of each node id with an open key."""
        self._open: dict[str, Any] = {}
        self._others_open = 0
        """Open keys of ids outside the roster: what ``UP_KEYS_MAX`` bounds."""
        self._closing: dict[str, float] = {}
        """Node ids whose last token went, and when (monotonic seconds) their key closes."""
        self._waiting: dict[str, set[str]] = {}
        """The tokens (instances) present of node ids refused for want of room, oldest id first: each gets its
        key when one closes (``_close_due``), as long as a token of it is there."""
        self.refused = 0
        """Tokens that opened no key when they came: a bad node id, or ``UP_KEYS_MAX`` open already."""
        self._events: queue.PriorityQueue[tuple[int, int, tuple[Any, Any]]] = queue.PriorityQueue()
        """(rank, arrival number, event): a storm of other ids' tokens never holds up a roster id's key."""
        self._arrivals = itertools.count()
        self._ended = False
        """Set by ``undeclare``: the thread ends before its next event, however many wait (a rogue's tokens)."""
        self._thread = threading.Thread(target=self._run, name="hub-up-keys", daemon=True)
        self._thread.start()
        self._watch = session.liveliness().declare_subscriber(keys.alive_all, self._token_event, history=True)

    @property
    def open_count(self) -> int:
        """Node ids whose up key is open now."""
        return len(self._open)

    @property
    def others_open(self) -> int:
        """Node ids outside the roster whose up key is open now (at most ``UP_KEYS_MAX``)."""
        return self._others_open

    @property
    def waiting_count(self) -> int:
        """Node ids with a token that wait for room to open their key."""
        return len(self._waiting)

    def undeclare(self) -> None:
        """Stop watching, end the thread, let every subscription go."""
        self._watch.undeclare()
        self._ended = True
        self._events.put((_FIRST, next(self._arrivals), _WAKE))
        self._thread.join(timeout=5.0)
        for sub in list(self._open.values()):
            sub.undeclare()
        self._open.clear()

    def _token_event(self, sample: zenoh.Sample) -> None:
        """Zenoh's thread: a token came or went; queued by its id's rank (a roster id's first)."""
        key = str(sample.key_expr)
        rank = _ROSTER if self.roster and self._keys.alive_of(key)[0] in self.roster else _OTHER
        self._events.put((rank, next(self._arrivals), (key, sample.kind)))

    def _run(self) -> None:
        while True:
            try:
                event: tuple[Any, Any] | None = self._events.get(timeout=self._until_next_close())[2]
            except queue.Empty:
                event = None
            if self._ended:
                return
            try:
                if event is not None and event is not _WAKE:
                    self._on_token(*event)
                self._close_due(time.monotonic())
            except Exception as err:  # an ended thread would leave every later node unheard
                self.faults.record("up keys", err, repr(event))

    def _until_next_close(self) -> float | None:
        if not self._closing:
            return None
        return max(min(self._closing.values()) - time.monotonic(), 0.0)

    def _on_token(self, key: str, kind: zenoh.SampleKind) -> None:
        node_id, instance = self._keys.alive_of(key)
        if kind == zenoh.SampleKind.PUT:
            self._token_came(node_id, instance)
        else:
            self._token_went(node_id, instance)
        self._on_alive(("alive", key, kind))

    def _token_came(self, node_id: str, instance: str) -> None:
        if node_id in self._open:
            self._instances[node_id].add(instance)
            self._closing.pop(node_id, None)
            return
        try:
            check_name("node", node_id)  # a wildcard in a token's key must not open every node's key
        except ValueError:
            self.refused += 1
            return
        if node_id in self.roster or self._others_open < UP_KEYS_MAX:
            self._open_key(node_id, {instance})
            return
        self.refused += 1
        if node_id in self._waiting or len(self._waiting) < UP_KEYS_WAITING_MAX:
            self._waiting.setdefault(node_id, set()).add(instance)

    def _token_went(self, node_id: str, instance: str) -> None:
        waiting = self._waiting.get(node_id)
        if waiting is not None:
            waiting.discard(instance)
            if not waiting:
                del self._waiting[node_id]
            return
        instances = self._instances.get(node_id)
        if instances is not None:
            instances.discard(instance)
            if not instances:
                self._closing[node_id] = time.monotonic() + self._grace_s

    def _open_key(self, node_id: str, instances: set[str]) -> None:
        # in zenoh's receiving thread, not a Python thread per subscription (see UP_KEYS_MAX)
        self._open[node_id] = self._session.declare_subscriber(
            self._keys.up(node_id), zenoh.handlers.Callback(self._on_up, indirect=False)
        )
        self._instances[node_id] = instances
        if node_id not in self.roster:
            self._others_open += 1

    def _close_due(self, now: float) -> None:
        for node_id in [n for n, at in self._closing.items() if at <= now]:
            del self._closing[node_id]
            self._instances.pop(node_id, None)
            sub = self._open.pop(node_id, None)
            if sub is not None:
                sub.undeclare()
                if node_id not in self.roster:
                    self._others_open -= 1
        while self._waiting and self._others_open < UP_KEYS_MAX:  # room freed: the longest waiting id first
            node_id = next(iter(self._waiting))
            self._open_key(node_id, self._waiting.pop(node_id))


def wait_for_up_key(publisher: zenoh.Publisher, within_s: float = UP_MATCH_WAIT_S) -> bool:
    """Block until the hub subscribes to ``publisher``'s key (True), or ``within_s`` wall seconds (False).

    A node calls it after declaring its token and its publisher, before its first message: until the hub has
    seen the token, zenoh drops what the node puts (see the module), its attach with it. Blocking, not async:
    a lockstep node's model time has not begun, and a wall-clock node has nothing else to do yet."""
    deadline = time.monotonic() + within_s
    while not publisher.matching_status.matching:
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.001)
    return True
