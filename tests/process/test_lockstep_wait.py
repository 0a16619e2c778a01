"""A lockstep node waits for its grant in its down channel: the grant moves its loop, a thread or a signal
ends the wait early. A real zenoh session that delivers to itself stands in for the hub."""

from __future__ import annotations

import asyncio
import os
import signal
import threading

import pytest
import zenoh

from petswarm.clock import LockstepLoop
from radio_hub.link import lockstep_link as lockstep
from radio_hub.link import wire
from radio_hub.link.keys import Keys
from radio_hub.link.lockstep_link import LockstepLink
from radio_hub.link.port import HubUnavailable

NODE = "robot-1"
FALLBACK_S = 10.0
"""When a wake-up failed to end the wait, a grant does after this many wall seconds: the test fails, not hangs."""


def _lone_session() -> zenoh.Session:
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("listen/endpoints", "[]")
    config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


def _run(main_of: object) -> tuple[LockstepLink, list[str]]:
    """Run ``main_of(link, loop, seen)`` on a lockstep loop with a link on a lone session; what it saw."""
    session = _lone_session()
    link = LockstepLink(session, Keys("wait"), owns_session=True)
    session.declare_subscriber(link.keys.up(NODE), lambda _: None)  # the hub's ear: a node speaks once it is heard
    seen: list[str] = []
    loop = LockstepLoop()
    try:
        loop.run_until_complete(main_of(link, loop, seen))  # type: ignore[operator]
    finally:
        loop.close()
    return link, seen


def _hub_sends(link: LockstepLink, parts: list[wire.Message], after_s: float = 0.2) -> threading.Timer:
    data = wire.encode_batch([part.encode() for part in parts])
    timer = threading.Timer(after_s, lambda: link.session.put(link.keys.down(NODE), data))
    timer.start()
    return timer


def test_a_grant_moves_the_loop_runs_its_timers_then_releases_its_messages() -> None:
    async def main(link: LockstepLink, loop: LockstepLoop, seen: list[str]) -> None:
        granted = loop.create_future()

        def on_down(data: bytes) -> None:  # what a RadioClient is handed: here, the round's batch
            for part in wire.split_batch(data):
                name = type(wire.decode(part)).__name__
                seen.append(f"down {name} at {loop.time()}")
                if name == "Grant":
                    granted.set_result(None)

        link.open(NODE, "i1", on_down, lambda _: None)
        loop.call_at(1.5, lambda: seen.append(f"timer at {loop.time()}"))
        _hub_sends(link, [wire.Configure(n=1), wire.Grant(at_s=1.5, n=2)])
        await granted
        await link.close()

    _, seen = _run(main)
    assert seen == ["timer at 1.5", "down Configure at 1.5", "down Grant at 1.5"]


def test_a_thread_ends_the_wait_without_moving_model_time() -> None:
    async def main(link: LockstepLink, loop: LockstepLoop, seen: list[str]) -> None:
        link.open(NODE, "i1", lambda data: None, lambda _: None)
        woken = loop.create_future()
        fallback = _hub_sends(link, [wire.Grant(at_s=9.0, n=1)], after_s=FALLBACK_S)  # a wake that never comes
        threading.Timer(0.2, lambda: loop.call_soon_threadsafe(lambda: woken.set_result(loop.time()))).start()
        at = await asyncio.wait_for(woken, timeout=None)
        seen.append(f"woken at {at}")
        fallback.cancel()
        await link.close()

    _, seen = _run(main)
    assert seen == ["woken at 0.0"]


def test_a_signal_ends_the_wait() -> None:
    async def main(link: LockstepLink, loop: LockstepLoop, seen: list[str]) -> None:
        link.open(NODE, "i1", lambda data: None, lambda _: None)
        stopping = asyncio.Event()
        fallback = _hub_sends(link, [wire.Grant(at_s=9.0, n=1)], after_s=FALLBACK_S)
        loop.add_signal_handler(signal.SIGUSR1, stopping.set)
        threading.Timer(0.2, lambda: os.kill(os.getpid(), signal.SIGUSR1)).start()
        await stopping.wait()
        seen.append(f"stopped at {loop.time()}")
        fallback.cancel()
        loop.remove_signal_handler(signal.SIGUSR1)
        await link.close()

    _, seen = _run(main)
    assert seen == ["stopped at 0.0"]


def test_an_empty_message_from_anyone_else_is_held_as_a_message_not_taken_as_a_wake_up() -> None:
    """Only the link's own wake-ups (marked, for its session only) end the wait; anyone who can put on the node's
    down key with an empty message is a sender of a malformed message, handed on with the round for its counters."""

    async def main(link: LockstepLink, loop: LockstepLoop, seen: list[str]) -> None:
        granted = loop.create_future()

        def on_down(data: bytes) -> None:
            if not data:
                seen.append(f"empty at {loop.time()}")
                return
            for part in wire.split_batch(data):
                seen.append(f"down {type(wire.decode(part)).__name__} at {loop.time()}")
            granted.set_result(None)

        link.open(NODE, "i1", on_down, lambda _: None)
        threading.Timer(0.1, lambda: link.session.put(link.keys.down(NODE), b"")).start()  # as a stranger would
        _hub_sends(link, [wire.Configure(n=1), wire.Grant(at_s=0.7, n=2)], after_s=0.5)
        await granted
        await link.close()

    _, seen = _run(main)
    assert seen == ["empty at 0.7", "down Configure at 0.7", "down Grant at 0.7"]


def test_a_node_the_hub_never_hears_says_so_instead_of_waiting_for_grants(monkeypatch: pytest.MonkeyPatch) -> None:
    """Its first idle would go nowhere and the hub would wait for it until it took the node as gone."""
    monkeypatch.setattr(lockstep, "UP_KEY_WAIT_S", 0.2)
    link = LockstepLink(_lone_session(), Keys("unheard"), owns_session=True)  # nobody subscribes to its up key
    loop = LockstepLoop()

    async def main() -> None:
        with pytest.raises(HubUnavailable, match=r"did not open robot-1's up key within 0\.2 s"):
            link.open(NODE, "i1", lambda _: None, lambda _: None)

    try:
        loop.run_until_complete(main())
    finally:
        loop.close()
        link.session.close()
