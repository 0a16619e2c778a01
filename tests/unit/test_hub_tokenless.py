"""The hub shell's second line behind liveliness: attaches whose process shows no token are bounded and expire.

Since the hub listens only on the up keys of ids with a token (``radio_hub.link.up_keys``), such an attach comes
from a process that has a token for another instance of the id, or in the 2 s a key stays open after its token
went. The job thread's steps are taken by hand on a hub that is never opened (no zenoh)."""

from __future__ import annotations

import zenoh

from radio_hub.link import wire
from radio_hub.shell.hub import ATTACH_TOKEN_TIMEOUT_S, MAX_UNPROVEN, RadioHub


def _attach(node_id: str, short: int, instance: str) -> bytes:
    msg = wire.Attach(short_addr=short, pan_id=0x1000, position=[float(short), 0.0], instance=instance, n=1, s=short)
    return msg.encode()


def _take(hub: RadioHub, item: tuple[object, ...]) -> None:
    hub._admit(item)
    hub._take(hub._inbox.get_nowait())


def test_attaches_without_a_token_are_capped_then_detached_while_a_proven_one_stays() -> None:
    hub = RadioHub("tcp/127.0.0.1:0", "tokenless")
    keys = hub.keys
    _take(hub, ("alive", keys.alive("robot-1", "i1"), zenoh.SampleKind.PUT))
    _take(hub, ("up", keys.up("robot-1"), _attach("robot-1", 1, "i1")))
    before = hub.now_us()
    for i in range(MAX_UNPROVEN + 3):  # tokens of other instances, or none at all
        _take(hub, ("up", keys.up(f"rogue-{i}"), _attach(f"rogue-{i}", 100 + i, "not-the-token")))
    live = hub.stats()["liveliness"]
    assert (live["tokenless"], live["refused_unproven"]) == (MAX_UNPROVEN, 3)
    assert len(hub.env.kinds) == 1 + MAX_UNPROVEN

    after = hub.now_us()
    hub._expire_tokenless(before + int(ATTACH_TOKEN_TIMEOUT_S * 1e6) - 1)
    assert len(hub.env.kinds) == 1 + MAX_UNPROVEN  # not yet
    hub._expire_tokenless(after + int(ATTACH_TOKEN_TIMEOUT_S * 1e6) + 1)
    assert set(hub.env.kinds) == {"robot-1"} and hub.stats()["liveliness"]["expired"] == MAX_UNPROVEN
