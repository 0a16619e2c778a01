"""The lockstep hub's rounds, fed node messages directly (no zenoh session: its downlink sends nothing).

The process tests (tests/process/test_lockstep.py) run it over zenoh; these pin down what one late or stale
node can do to the rounds of everyone else."""

from __future__ import annotations

import time

from radio_hub.environment import EnvironmentConfig
from radio_hub.link import wire
from radio_hub.link.lockstep_link import _GRANT_TYPE, _grant_of
from radio_hub.shell.lockstep import LockstepHub

SLOW_S = 0.05
"""``dead_after_s`` of the tests of a node taken as gone (they sleep past it); the others leave it at 60 s, so
that a loaded machine's pause between two lines of a test cannot bury a node (a CI run took robot-2 as gone
within 50 ms and the round went on: "now_s 0.02 == 0.0")."""


def _hub(expect: int = 2, dead_after_s: float = 60.0) -> LockstepHub:
    return LockstepHub("tcp/127.0.0.1:1", "unit", EnvironmentConfig(), seed=1, expect=expect, dead_after_s=dead_after_s)


def _up(hub: LockstepHub, node_id: str, msg: wire.Message) -> None:
    hub._handle(("up", hub.keys.up(node_id), msg.encode()))
    hub._bury_the_silent()
    hub._run_rounds()


def _attach(hub: LockstepHub, node_id: str, key: int) -> None:
    _up(hub, node_id, wire.Attach(ext_addr=key, short_addr=key, instance=f"i{key}", n=1, s=key))
    _up(hub, node_id, wire.Idle(seen=0, next_s=0.5, n=2, s=key))


def _robot_2_slow_and_taken_as_gone() -> tuple[LockstepHub, int]:
    """Two robots in their rounds; robot-2 says nothing past dead_after_s while robot-1 answers. Returns the hub
    and the grant robot-2 was last sent."""
    hub = _hub(dead_after_s=SLOW_S)
    _attach(hub, "robot-1", 11)
    _attach(hub, "robot-2", 12)
    late = hub.nodes["robot-2"].granted
    time.sleep(0.1)
    _up(hub, "robot-1", wire.Idle(seen=hub.nodes["robot-1"].granted, next_s=0.5, n=3, s=11))
    return hub, late


def test_rounds_go_on_once_every_node_is_idle_and_stop_at_a_busy_one() -> None:
    hub = _hub()
    _attach(hub, "robot-1", 11)
    assert hub.rounds == 0  # one of the two expected nodes: model time has not started
    _attach(hub, "robot-2", 12)
    assert hub.rounds > 0 and hub.nodes["robot-1"].granted and not hub.nodes["robot-1"].idle
    before = hub.now_s
    _up(hub, "robot-1", wire.Idle(seen=hub.nodes["robot-1"].granted, next_s=0.5, n=3, s=11))
    assert hub.now_s == before  # robot-2 has not answered its grant: nobody moves on


def test_a_node_taken_as_gone_that_answers_late_does_not_stall_the_others() -> None:
    """A node silent past dead_after_s is taken as gone; its late idle (it was only slow) must not bring it
    back as a node that is never granted again and so never idle: that stalled every run for good."""
    hub, late = _robot_2_slow_and_taken_as_gone()
    assert [d["node"] for d in hub.dead] == ["robot-2"] and "robot-2" not in hub.nodes
    at = hub.now_s
    _up(hub, "robot-2", wire.Idle(seen=late, next_s=0.5, n=3, s=12))  # it was only slow
    assert "robot-2" not in hub.nodes and hub.stats()["lockstep"]["stale_idles"] == 1
    _up(hub, "robot-1", wire.Idle(seen=hub.nodes["robot-1"].granted, next_s=0.5, n=4, s=11))
    assert hub.now_s > at  # robot-1 goes on alone


def test_a_late_attach_of_a_node_taken_as_gone_does_not_stall_the_world_either() -> None:
    """The slow node's last round held a (re)sent Attach before its idle: the Attach makes it a node again, never
    granted; it is taken as gone once it stays busy past dead_after_s, and the world goes on."""
    hub, late = _robot_2_slow_and_taken_as_gone()
    _up(hub, "robot-2", wire.Attach(ext_addr=12, short_addr=12, instance="i12", n=3, s=12))
    _up(hub, "robot-2", wire.Idle(seen=late, next_s=0.5, n=4, s=12))
    at = hub.now_s
    time.sleep(0.1)
    _up(hub, "robot-1", wire.Idle(seen=hub.nodes["robot-1"].granted, next_s=0.5, n=4, s=11))
    assert [d["node"] for d in hub.dead] == ["robot-2", "robot-2"] and hub.now_s > at


def test_an_earlier_process_idle_does_not_count_for_the_new_one() -> None:
    """A restarted process's Attach made the node; the old process's idle (its own session key) must not mark
    the new one idle before the new one has said so itself."""
    hub = _hub(expect=1)
    _up(hub, "robot-1", wire.Attach(ext_addr=11, short_addr=11, instance="new", n=1, s=21))
    _up(hub, "robot-1", wire.Idle(seen=0, next_s=0.5, n=9, s=11))  # the old process's
    assert hub.rounds == 0 and hub.env.counters.foreign == 1 and not hub.nodes["robot-1"].idle


def test_a_node_that_attaches_and_never_says_idle_does_not_hold_the_start_for_good() -> None:
    hub = LockstepHub(
        "tcp/127.0.0.1:1", "unit", EnvironmentConfig(), seed=1, expect=2, dead_after_s=SLOW_S, start_within_s=SLOW_S
    )
    _attach(hub, "robot-1", 11)
    _up(hub, "robot-2", wire.Attach(ext_addr=12, short_addr=12, instance="i12", n=1, s=12))  # then it hangs
    time.sleep(0.1)
    _up(hub, "robot-1", wire.Idle(seen=0, next_s=0.5, n=3, s=11))
    assert hub.rounds > 0 and "robot-2" not in hub.nodes
    assert any("did not come" in d["why"] for d in hub.dead) and any(d["node"] == "robot-2" for d in hub.dead)


def test_every_grant_carries_the_bytes_a_node_looks_for_and_nothing_else_is_taken_for_one() -> None:
    """A node's zenoh thread decodes only messages holding ``_GRANT_TYPE``: every grant must hold them."""
    for grant in (wire.Grant(), wire.Grant(at_s=1e300, n=2**63 - 1, s=7), wire.Grant(at_s=-0.0, n=1)):
        data = grant.encode()
        assert _GRANT_TYPE in data and _grant_of(data) == grant
    idle = wire.Idle(seen=3, next_s=0.5).encode()
    frame = wire.Received(psdu=b"\xa1t\xa5grant", rssi_dbm=-50.0).encode()  # the bytes inside a frame's payload
    assert _grant_of(idle) is None and _grant_of(frame) is None


def test_a_grant_that_closes_a_batch_is_found_and_nothing_else_in_a_batch_is_taken_for_one() -> None:
    """The hub sends a node's messages of a round and its grant in one batch: the node's zenoh thread must see
    the grant that closes it, and only that (a grant is always a round's last message)."""
    grant = wire.Grant(at_s=2.5, n=9)
    frame = wire.Received(psdu=b"\xa1t\xa5grant", rssi_dbm=-50.0).encode()
    assert _grant_of(wire.encode_batch([frame, grant.encode()])) == grant
    assert _grant_of(wire.encode_batch([grant.encode(), frame])) is None
    assert _grant_of(wire.encode_batch([frame, frame])) is None
    assert _grant_of(wire.encode_batch([frame, grant.encode()])[:-3]) is None  # cut short: malformed, not a grant


def test_a_node_batch_is_taken_as_its_messages_in_order() -> None:
    """A lockstep node puts its round's messages and its idle as one batch: the hub takes them as if sent one by
    one (here an attach and its first idle start model time as two separate puts do)."""
    one_by_one, batched = _hub(expect=1), _hub(expect=1)
    attach = wire.Attach(ext_addr=11, short_addr=11, instance="i11", n=1, s=11).encode()
    idle = wire.Idle(seen=0, next_s=0.5, n=2, s=11).encode()
    for data in (attach, idle):
        one_by_one._handle(("up", one_by_one.keys.up("robot-1"), data))
    batched._handle(("up", batched.keys.up("robot-1"), wire.encode_batch([attach, idle])))
    for hub in (one_by_one, batched):
        hub._run_rounds()
    assert batched.rounds == one_by_one.rounds > 0
    node, reference = batched.nodes["robot-1"], one_by_one.nodes["robot-1"]
    assert (node.granted, node.idle, node.next_s, node.key) == (reference.granted, reference.idle, reference.next_s, 11)
    assert batched.up_puts == 1 and one_by_one.up_puts == 2


def test_a_malformed_node_batch_is_counted_once_and_dropped_whole() -> None:
    hub = _hub(expect=1)
    attach = wire.Attach(ext_addr=11, short_addr=11, instance="i11", n=1, s=11).encode()
    hub._handle(("up", hub.keys.up("robot-1"), wire.encode_batch([attach, attach])[:-4]))
    hub._handle(("up", hub.keys.up("robot-1"), wire.encode_batch([attach, 7])))  # type: ignore[list-item]
    assert hub.env.counters.malformed == 2 and not hub.nodes
