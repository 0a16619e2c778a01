"""The robot's event log: every structured event, stamped with wall and monotonic time as it is recorded.

It is the runtime's sink, not part of any core, and the one part of the managers that reads the clock (model
time in model and lockstep runs): a core hands out ``Log`` actions and ``StateChange``s, its runtime records
them here.
"""

from __future__ import annotations

import json
from collections import deque
from dataclasses import dataclass, field
from typing import IO, Any

from petswarm import clock

MEMORY_EVENTS = 20_000
"""Events a robot keeps in memory for its control channel; the record file (if any) keeps them all."""


@dataclass
class EventLog:
    """Structured events of one robot, in order; each also goes to ``sink`` (a JSON-lines file) at once."""

    events: deque[dict[str, Any]] = field(default_factory=lambda: deque(maxlen=MEMORY_EVENTS))
    sink: IO[str] | None = None

    def record(self, kind: str, **detail: Any) -> dict[str, Any]:
        """Append an event stamped with wall time and monotonic time (seconds; both model time in model time)."""
        event = {"t": round(clock.wall_time(), 6), "mono": round(clock.now(), 6), "kind": kind, **detail}
        self.events.append(event)
        if self.sink is not None:
            # flushed per event: a robot killed outright loses at most the event being written
            try:
                self.sink.write(json.dumps(event, default=str) + "\n")
                self.sink.flush()
            except OSError as err:  # a full disk must not stop the robot: keep running, stop recording
                self.sink = None
                self.events.append({**event, "kind": "record_lost", "error": str(err)})
        return event
