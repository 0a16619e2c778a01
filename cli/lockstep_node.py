"""A node process on lockstep time: wait for the hub in wall time, then run on model time the hub grants."""

from __future__ import annotations

import signal
import sys
import time
from collections.abc import Callable, Coroutine
from typing import Any

from petswarm.clock import LockstepLoop
from radio_hub.interface import HubUnavailable, Keys, open_session
from radio_hub.lockstep import LockstepLink

HUB_WAIT_S = 30.0
"""Wall seconds a lockstep node waits for its hub at start."""


def open_link(endpoint: str, world: str, timeout: float = HUB_WAIT_S) -> LockstepLink:
    """A lockstep link on a client session to ``endpoint``, retried in wall time (model time has not begun)."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            return LockstepLink(open_session("client", endpoint), Keys(world), owns_session=True)
        except HubUnavailable:
            if time.monotonic() >= deadline:
                raise
            time.sleep(0.2)


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
        loop.close()  # which puts SIGTERM back to its default action
        # The node's work is done and its record written: the SIGTERM a run sends its nodes at the end must not
        # kill it while the interpreter and the zenoh session close, or it would report death by signal (-15).
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
