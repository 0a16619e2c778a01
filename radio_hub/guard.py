"""What a process does with an exception nobody expected: count it per kind, say it once, and go on.

Every entry point that takes input from the network (the hub's job loop, a node's downlink, a robot's
receive loop, a user's belt) runs its handler under a ``Faults`` record: one bad message must never end a
process. The first fault of each kind is written to stderr with its context and the traceback's last line;
later ones of that kind are only counted (a flood must not turn into a flood of log lines).
"""

from __future__ import annotations

import contextlib
import sys
import traceback
from collections import Counter
from typing import TextIO

MAX_KINDS = 64
"""Distinct fault kinds kept; further kinds are counted under ``other`` (exception names come from code, but
a bound costs nothing)."""


class Faults:
    """Unexpected exceptions of one process, counted per ``where:ExceptionType``."""

    def __init__(self, who: str, stream: TextIO | None = None) -> None:
        self.who = who
        self.counts: Counter[str] = Counter()
        self._stream = stream

    def record(self, where: str, err: BaseException, context: str = "") -> None:
        """Count ``err`` raised in ``where``; log it if it is the first of its kind."""
        kind = f"{where}:{type(err).__name__}"
        if kind not in self.counts and len(self.counts) >= MAX_KINDS:
            kind = "other"
        self.counts[kind] += 1
        if self.counts[kind] == 1:
            frame = traceback.extract_tb(err.__traceback__)[-1:] if err.__traceback__ else []
            at = f" at {frame[0].filename}:{frame[0].lineno}" if frame else ""
            extra = f" ({context[:200]})" if context else ""
            stream = self._stream or sys.stderr
            # a log that cannot be written (stderr a closed pipe) must not raise in the handler that counts: the
            # world thread would end there, and ticks, sensors and IR stop while frames flow
            with contextlib.suppress(OSError, ValueError):
                print(f"{self.who}: {kind}: {str(err)[:300]}{at}{extra}; counted, going on", file=stream, flush=True)

    @property
    def total(self) -> int:
        """Every fault counted so far."""
        return sum(self.counts.values())

    def to_dict(self) -> dict[str, int]:
        """Counts per kind (for stats)."""
        return dict(self.counts)
