"""The hub shell keeps room for its run's roster wherever a flood of other ids could take it: the inbox's buckets
(a roster id's first messages and its tokens' comings and goings) and the tokens it remembers. The job thread's
steps are taken by hand on a hub that is never opened (no zenoh)."""

from __future__ import annotations

import zenoh

from radio_hub.link import wire
from radio_hub.shell.hub import (
    BATCH,
    INBOX_OTHER,
    ROSTER_TOKENS_PER_ID,
    STRANGERS_PER_S,
    TOKENS_KEPT,
    RadioHub,
)

PUT, DELETE = zenoh.SampleKind.PUT, zenoh.SampleKind.DELETE


def _attach(short: int, instance: str) -> bytes:
    return wire.Attach(
        short_addr=short, pan_id=0x1000, position=[float(short), 0.0], instance=instance, n=1, s=short
    ).encode()


def _drain(hub: RadioHub) -> None:
    while not hub._inbox.empty():
        hub._take(hub._inbox.get_nowait())


def test_a_roster_ids_token_and_first_attach_pass_a_full_inbox_and_a_spent_strangers_rate() -> None:
    hub = RadioHub("tcp/127.0.0.1:0", "roster-inbox", roster=("robot-1",))
    keys = hub.keys
    for i in range(INBOX_OTHER + 10):  # a storm of others' tokens fills their bucket
        hub._admit(("alive", keys.alive(f"rogue-{i}", "x"), PUT))
    for i in range(STRANGERS_PER_S + 10):  # and others' messages spend the strangers' rate
        hub._admit(("up", keys.up(f"rogue-{i % 50}"), _attach(100 + i % 50, "x")))
    dropped = dict(hub.inbox_dropped)
    assert dropped["other"] == 10 and dropped["stranger"] >= 10, dropped
    hub._admit(("alive", keys.alive("robot-1", "i1"), PUT))
    hub._admit(("up", keys.up("robot-1"), _attach(1, "i1")))
    hub._admit(("alive", keys.alive("robot-2", "i1"), PUT))  # not in the roster: refused with the others
    hub._admit(("up", keys.up("robot-2"), _attach(2, "i1")))
    assert hub.inbox_dropped["other"] == 11 and hub.inbox_dropped["stranger"] == dropped["stranger"] + 1
    _drain(hub)
    assert "robot-1" in hub.env.kinds and "robot-2" not in hub.env.kinds
    assert hub._token_present("robot-1", "i1")


def test_others_tokens_never_push_a_roster_ids_token_out_and_a_roster_id_keeps_a_bounded_number() -> None:
    hub = RadioHub("tcp/127.0.0.1:0", "roster-tokens", roster=("robot-1",))
    hub._token_seen("robot-1", "i1")  # the robot's token came before it attached
    for i in range(2 * TOKENS_KEPT + 1):  # others fill what is kept, twice: the ones not attached are forgotten
        hub._token_seen(f"rogue-{i}", "x")
    assert hub._token_present("robot-1", "i1")
    assert len(hub._tokens) <= TOKENS_KEPT + 1
    for i in range(2, ROSTER_TOKENS_PER_ID + 5):  # anyone may use the name: its tokens are bounded too
        hub._token_seen("robot-1", f"i{i}")
    assert sum(1 for node_id, _ in hub._tokens if node_id == "robot-1") == ROSTER_TOKENS_PER_ID
    assert hub.tokens_dropped >= 4
    hub._admit(("alive", hub.keys.alive("robot-1", "i2"), DELETE))
    _drain(hub)
    assert not hub._token_present("robot-1", "i2")
    hub._token_seen("robot-1", "late")  # a token that went frees its room
    assert hub._token_present("robot-1", "late")


def test_a_roster_ids_attach_is_taken_ahead_of_a_backlog_of_other_nodes_traffic() -> None:
    """A rogue's attached nodes flood until their buckets are full; a roster id's token and attach that come after
    are handled in the job thread's next pass, not behind the whole backlog."""
    hub = RadioHub("tcp/127.0.0.1:0", "roster-first", roster=("robot-1",))
    keys = hub.keys
    rogues = [f"rogue-{i}" for i in range(4)]
    for i, node_id in enumerate(rogues):
        hub._admit(("alive", keys.alive(node_id, "x"), PUT))
        hub._admit(("up", keys.up(node_id), _attach(100 + i, "x")))
    _drain(hub)
    assert set(hub.env.kinds) == set(rogues)
    for i, node_id in enumerate(rogues):  # each sends with its own session key: its own bucket, full
        drive = wire.Drive(vx=0.1, n=2, s=100 + i).encode()
        for _ in range(1000):
            hub._admit(("up", keys.up(node_id), drive))
    backlog = hub._inbox.qsize()
    assert backlog == 4000, backlog
    hub._admit(("alive", keys.alive("robot-1", "i1"), PUT))
    hub._admit(("up", keys.up("robot-1"), _attach(1, "i1")))
    hub._take(hub._inbox.get_nowait())  # one pass of the job thread
    assert "robot-1" in hub.env.kinds
    assert hub._inbox.qsize() >= backlog - BATCH, hub._inbox.qsize()  # the rogues' traffic mostly still waits
