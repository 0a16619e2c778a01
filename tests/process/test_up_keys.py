"""The hub listens on a node's up key while the node has a liveliness token, and only then.

A router session stands in for the hub's and a client session for a node's, on loopback: what opens and closes
the keys is zenoh's liveliness, which a mock could not show.
"""

from __future__ import annotations

import io
import queue
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
import zenoh

from petswarm.lab.processes import free_tcp_port
from radio_hub.guard import Faults
from radio_hub.link import up_keys as up_keys_module
from radio_hub.link.keys import Keys
from radio_hub.link.up_keys import UpKeys, wait_for_up_key
from radio_hub.link.zenoh_link import session_config

GRACE_S = 0.3


@contextmanager
def _hub_and_node_sessions() -> Iterator[tuple[zenoh.Session, zenoh.Session]]:
    """A router session (the hub's) and a client session (a node's) on a free loopback port."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    hub = zenoh.open(session_config("router", endpoint))
    node = zenoh.open(session_config("client", endpoint))
    try:
        yield hub, node
    finally:
        node.close()
        hub.close()


@pytest.fixture
def hub_and_node() -> Iterator[tuple[UpKeys, zenoh.Session, queue.SimpleQueue[Any], Keys]]:
    keys = Keys("up-keys")
    heard: queue.SimpleQueue[Any] = queue.SimpleQueue()
    with _hub_and_node_sessions() as (hub, node):
        up_keys = UpKeys(hub, keys, lambda s: heard.put(s.payload.to_bytes()), heard.put, grace_s=GRACE_S)
        try:
            yield up_keys, node, heard, keys
        finally:
            up_keys.undeclare()


def _wait(condition: Any, within_s: float = 5.0) -> None:
    deadline = time.monotonic() + within_s
    while not condition():
        assert time.monotonic() < deadline, "not within the deadline"
        time.sleep(0.01)


def test_a_token_opens_its_node_key_and_the_key_closes_a_grace_after_the_token_went(hub_and_node) -> None:
    up_keys, node, heard, keys = hub_and_node
    pub = node.declare_publisher(keys.up("robot-1"))
    assert not wait_for_up_key(pub, within_s=0.3)  # no token, no key: what the node puts goes nowhere
    token = node.liveliness().declare_token(keys.alive("robot-1", "i1"))
    assert wait_for_up_key(pub)
    assert heard.get(timeout=5)[0] == "alive"  # the token reaches the hub after its key opened
    pub.put(b"hello")
    assert heard.get(timeout=5) == b"hello"
    assert up_keys.open_count == 1

    token.undeclare()
    assert heard.get(timeout=5)[0] == "alive"
    pub.put(b"last words")  # inside the grace: a Detach that travels behind the token's end
    assert heard.get(timeout=5) == b"last words"
    _wait(lambda: up_keys.open_count == 0)
    _wait(lambda: not pub.matching_status.matching)


def test_a_second_instance_keeps_the_key_open_when_the_first_goes(hub_and_node) -> None:
    up_keys, node, _heard, keys = hub_and_node
    first = node.liveliness().declare_token(keys.alive("robot-1", "old"))
    second = node.liveliness().declare_token(keys.alive("robot-1", "new"))
    _wait(lambda: up_keys.open_count == 1)
    first.undeclare()
    time.sleep(3 * GRACE_S)
    assert up_keys.open_count == 1
    second.undeclare()
    _wait(lambda: up_keys.open_count == 0)


def test_a_token_whose_id_is_no_node_name_opens_nothing(hub_and_node) -> None:
    up_keys, node, heard, keys = hub_and_node
    token = node.liveliness().declare_token(keys.alive("x" * 65, "i1"))  # a valid key, not a valid node id
    assert heard.get(timeout=5)[0] == "alive"  # the hub still hears of it, and refuses it as it always did
    assert up_keys.refused == 1 and up_keys.open_count == 0
    token.undeclare()


def test_an_id_refused_for_want_of_room_gets_its_key_when_one_closes(hub_and_node, monkeypatch) -> None:
    """With room for two keys, a third id waits while its token is there and is heard once a key closes; an id
    whose token went while it waited gets none."""
    monkeypatch.setattr(up_keys_module, "UP_KEYS_MAX", 2)
    up_keys, node, heard, keys = hub_and_node
    holders = [node.liveliness().declare_token(keys.alive(f"rogue-{i}", "x")) for i in (1, 2)]
    _wait(lambda: up_keys.open_count == 2)
    gave_up = node.liveliness().declare_token(keys.alive("robot-9", "i1"))
    token = node.liveliness().declare_token(keys.alive("robot-1", "i1"))
    pub = node.declare_publisher(keys.up("robot-1"))
    _wait(lambda: up_keys.waiting_count == 2)
    gave_up.undeclare()
    _wait(lambda: up_keys.waiting_count == 1)
    assert not wait_for_up_key(pub, within_s=0.3) and up_keys.refused == 2
    holders[0].undeclare()  # room, a grace after the rogue's token went: robot-1 (waiting), not robot-9 (gone)
    assert wait_for_up_key(pub)
    assert up_keys.open_count == 2 and up_keys.waiting_count == 0
    while not heard.empty():
        heard.get_nowait()
    pub.put(b"heard at last")
    assert heard.get(timeout=5) == b"heard at last"
    for t in (holders[1], token):
        t.undeclare()


def test_a_roster_id_gets_its_key_whatever_the_other_ids_hold(monkeypatch) -> None:
    """With room for two keys taken by other ids, a roster id's token still opens its key at once (it neither waits
    nor counts toward the cap), and an id outside the roster waits as before."""
    monkeypatch.setattr(up_keys_module, "UP_KEYS_MAX", 2)
    keys = Keys("up-keys-roster")
    with _hub_and_node_sessions() as (hub, node):
        up_keys = UpKeys(hub, keys, lambda s: None, lambda item: None, grace_s=GRACE_S, roster=("robot-1",))
        try:
            holders = [node.liveliness().declare_token(keys.alive(f"rogue-{i}", "x")) for i in (1, 2, 3)]
            _wait(lambda: up_keys.others_open == 2 and up_keys.waiting_count == 1)
            token = node.liveliness().declare_token(keys.alive("robot-1", "i1"))
            assert wait_for_up_key(node.declare_publisher(keys.up("robot-1")))
            assert up_keys.open_count == 3 and up_keys.others_open == 2 and up_keys.waiting_count == 1
            stranger = node.liveliness().declare_token(keys.alive("robot-2", "i1"))
            _wait(lambda: up_keys.waiting_count == 2)
            token.undeclare()  # a roster id's key closing frees no room for the others
            _wait(lambda: up_keys.open_count == 2)
            time.sleep(3 * GRACE_S)
            assert up_keys.others_open == 2 and up_keys.waiting_count == 2
            for t in (*holders, stranger):
                t.undeclare()
        finally:
            up_keys.undeclare()


def test_a_roster_id_must_be_a_node_name() -> None:
    with _hub_and_node_sessions() as (hub, _node), pytest.raises(ValueError, match="must be 1-64"):
        UpKeys(hub, Keys("up-keys-bad-roster"), lambda s: None, lambda item: None, roster=("robot/*",))


def test_an_event_the_thread_cannot_handle_is_counted_and_later_tokens_still_open_keys() -> None:
    keys = Keys("up-keys-faults")
    told: list[Any] = []

    def on_alive(item: tuple[Any, ...]) -> None:  # the hub's inbox refusing the first event it is handed
        told.append(item)
        if len(told) == 1:
            raise RuntimeError("inbox refused")

    with _hub_and_node_sessions() as (hub, node):
        up_keys = UpKeys(hub, keys, lambda s: None, on_alive, faults=Faults("test", io.StringIO()))
        try:
            first = node.liveliness().declare_token(keys.alive("robot-1", "i1"))
            _wait(lambda: up_keys.faults.total == 1)
            second = node.liveliness().declare_token(keys.alive("robot-2", "i1"))
            assert wait_for_up_key(node.declare_publisher(keys.up("robot-2")))
            assert up_keys.open_count == 2 and up_keys.faults.to_dict() == {"up keys:RuntimeError": 1}
            first.undeclare()
            second.undeclare()
        finally:
            up_keys.undeclare()


CLOSE_TOKENS = 100


def test_undeclare_ends_the_thread_without_handling_the_tokens_still_waiting(monkeypatch: pytest.MonkeyPatch) -> None:
    """A hub that got SIGTERM while it opened keys for a rogue's 5,000 tokens (cap 4,096) was ended by its 4 s
    deadline (exit 3): ``UpKeys.undeclare`` queued its stop behind every token not yet handled and waited 5 s
    for the thread. Here each key takes 50 ms to open, as thousands of subscriptions made it take, and 100
    tokens are waiting."""
    token_came = UpKeys._token_came

    def slow(self: UpKeys, node_id: str, instance: str) -> None:
        time.sleep(0.05)
        token_came(self, node_id, instance)

    monkeypatch.setattr(UpKeys, "_token_came", slow)
    keys = Keys("up-keys-close")
    seen: list[object] = []
    with _hub_and_node_sessions() as (hub, node):
        keeper = UpKeys(hub, keys, lambda s: None, seen.append)
        tokens = [node.liveliness().declare_token(keys.alive(f"fake-{i}", "x")) for i in range(CLOSE_TOKENS)]
        try:
            _wait(lambda: bool(seen))
            handled, started = len(seen), time.monotonic()
            keeper.undeclare()
            print(f"undeclare took {time.monotonic() - started:.2f} s")
            # at most the token in hand when it began: not a wall-clock bound, which a loaded machine moves
            assert len(seen) - handled <= 1, (handled, len(seen))
            assert not keeper._thread.is_alive() and keeper.open_count == 0
            assert len(seen) < CLOSE_TOKENS  # what was still waiting was let go, not handled
        finally:
            for token in tokens:
                token.undeclare()
