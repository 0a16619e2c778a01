"""Waiting on real processes in tests: poll for a condition, or read a child's output up to a line; fail saying
what was awaited."""

from __future__ import annotations

import time
from typing import IO, Any


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


def once_settled(probe: Any, settled: Any, timeout: float, every: float = 0.05) -> Any:
    """``probe()`` once ``settled`` holds for it, or its value after ``timeout`` seconds: unlike ``wait_for``, the
    caller gets the last value and asserts on it itself, saying what is wrong in the test's own terms."""
    deadline = time.monotonic() + timeout
    while True:
        value = probe()
        if settled(value) or time.monotonic() > deadline:
            return value
        time.sleep(every)


def read_until(stream: IO[str] | None, text: str, timeout: float) -> str:
    """A child's output read line by line up to the first line holding ``text``, or all of it that came before
    its end or ``timeout`` seconds (the read blocks: a child that falls silent is left to the test's timeout)."""
    assert stream is not None, "the child's output is not a pipe"
    seen, deadline = "", time.monotonic() + timeout
    while text not in seen and time.monotonic() < deadline:
        line = stream.readline()
        if not line:  # its end
            break
        seen += line
    return seen
