"""A node process on lockstep time: wait for the hub in wall time, then run on model time the hub grants."""

from __future__ import annotations

import signal
import sys
import time
from collections.abc import Callable, Coroutine
from typing import Any

import zenoh

from petswarm.clock import LockstepLoop
from radio_hub.interface import Keys, LockstepLink, open_session
from radio_hub.values import HubUnavailable

HUB_WAIT_S = 30.0
"""Wall seconds a lockstep node waits for its hub at start."""


def open_link(endpoint: str, world: str, timeout: float = HUB_WAIT_S) -> LockstepLink:
    """A lockstep link on a client session to ``endpoint``, once the hub serves its world (retried in wall
    time: model time has not begun). A router that listens may not have declared the hub's keys yet, and what
    a node sends before that is lost, its first idle too, which would leave the hub waiting for it for ever."""
    deadline = time.monotonic() + timeout
    keys = Keys(world)
    while True:
        try:
            session = open_session("client", endpoint)
        except HubUnavailable:
            pass
        else:
            if _hub_serves(session, keys, deadline):
                return LockstepLink(session, keys, owns_session=True)
            session.close()
        if time.monotonic() >= deadline:
            raise HubUnavailable(f"no lockstep hub serves world {world!r} on {endpoint} within {timeout:g} s")
        time.sleep(0.2)


def _hub_serves(session: zenoh.Session, keys: Keys, deadline: float) -> bool:
    """True once the hub's liveliness token is seen (it is declared after every key the hub serves), asked
    again until ``deadline`` (monotonic seconds)."""
    while True:
        if any(reply.ok is not None for reply in session.liveliness().get(keys.hub_alive, timeout=1.0)):
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.1)


def run_node(name: str, endpoint: str, world: str, main: Callable[[LockstepLink], Coroutine[Any, Any, int]]) -> int:
    """Run ``main(link)`` on a ``LockstepLoop``; returns its exit code (2 when no hub answers)."""
    try:
        link = open_link(endpoint, world)
    except HubUnavailable as err:
        print(f"{name}: {err}", file=sys.stderr)
        return 2
    loop = LockstepLoop()
    try:
        return loop.run_until_complete(main(link))
    finally:
        loop.close()  # which leaves a SIGTERM handler of the node's as "ignore"
        # The node's work is done and its record written: the SIGTERM a run sends its nodes at the end must not
        # kill it while the interpreter and the zenoh session close, or it would report death by signal (-15).
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
