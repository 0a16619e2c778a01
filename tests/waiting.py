"""Waiting on real processes in tests: poll for a condition, fail saying what was awaited."""

from __future__ import annotations

import time
from typing import Any


def wait_for(what: str, probe: Any, timeout: float, every: float = 0.5) -> Any:
    """Poll ``probe()`` until it returns something truthy; fail saying ``what`` and the last value otherwise."""
    deadline = time.monotonic() + timeout
    last: Any = None
    while True:
        try:
            last = probe()
        except Exception as err:  # a hub restarting, a robot not yet attached: try again
            last = err
        if last and not isinstance(last, Exception):
            return last
        if time.monotonic() >= deadline:
            raise AssertionError(f"{what}: not within {timeout} s (last: {last!r})")
        time.sleep(every)
