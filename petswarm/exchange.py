"""Message-processing manager: requests, the responses they expect, deadlines and retries.

A step of the swarm process sends a request, then waits until every expected robot has answered or the
deadline passes; it then repeats the request to the robots still missing, a bounded number of times.
Responses are matched by session and type; a duplicate (the same robot again) or a late one (after the
step ended) is counted and otherwise ignored, so retries are idempotent.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field

from petswarm.messages import SwarmMessage
from petswarm.rf import Incoming
from petswarm.sequence import EventLog


@dataclass(frozen=True)
class StepTiming:
    """How long one step waits for answers and how often it retries."""

    deadline_s: float = 0.1
    max_retries: int = 5
    quiet_s: float | None = None
    """Open steps only (anyone may answer): end early once answers have come and none for this long."""

    def __post_init__(self) -> None:
        if self.deadline_s <= 0 or self.max_retries < 0:
            raise ValueError("a step needs a positive deadline and max_retries >= 0")
        if self.quiet_s is not None and self.quiet_s <= 0:
            raise ValueError("a quiet gap must be positive")


@dataclass
class StepResult:
    """What one step collected."""

    responses: dict[int, Incoming] = field(default_factory=dict)
    attempts: int = 0
    missing: set[int] = field(default_factory=set)

    @property
    def retries(self) -> int:
        """Attempts beyond the first."""
        return max(self.attempts - 1, 0)


@dataclass
class _Collector:
    session: int
    kinds: tuple[type[SwarmMessage], ...]
    responses: dict[int, Incoming]
    expected: set[int] | None
    complete: asyncio.Event


class MessageProcessingManager:
    """Routes responses to the step waiting for them; counts duplicates and late arrivals."""

    def __init__(self, log: EventLog) -> None:
        self.log = log
        self.duplicates = 0
        self.late = 0
        self.retries = 0
        self._collectors: list[_Collector] = []

    def offer(self, incoming: Incoming) -> bool:
        """Hand a received message to a waiting step; False when no step wants it."""
        msg = incoming.message
        for col in self._collectors:
            if msg.session_id == col.session and isinstance(msg, col.kinds):
                if incoming.sender in col.responses:
                    self.duplicates += 1
                else:
                    col.responses[incoming.sender] = incoming
                    if col.expected is None or col.expected <= col.responses.keys():
                        col.complete.set()  # an open step takes it as "something arrived"
                return True
        return False

    def count_late(self) -> None:
        """A response to a step that has ended."""
        self.late += 1

    async def step(
        self,
        name: str,
        session: int,
        kinds: tuple[type[SwarmMessage], ...],
        send: Callable[[set[int] | None], Awaitable[None]],
        expected: set[int] | None,
        timing: StepTiming,
    ) -> StepResult:
        """Run one request/response step.

        ``send(missing)`` puts the request on the air (``missing`` is None on the first attempt when
        ``expected`` is None, i.e. when anyone may answer: then the step simply collects until the
        deadline, retrying only if nobody answered at all).
        """
        col = _Collector(session, kinds, {}, None if expected is None else set(expected), asyncio.Event())
        if col.expected is not None and not col.expected:
            return StepResult()
        self._collectors.append(col)
        result = StepResult(col.responses)
        try:
            while result.attempts <= timing.max_retries:
                missing = None if col.expected is None else col.expected - col.responses.keys()
                if result.attempts:
                    self.retries += 1
                    self.log.record(
                        "retry", step=name, session=session, attempt=result.attempts, missing=sorted(missing or ())
                    )
                result.attempts += 1
                await send(missing)
                await self._collect(col, timing)
                if self._step_done(col):
                    break
        finally:
            self._collectors.remove(col)
        result.missing = set() if col.expected is None else col.expected - col.responses.keys()
        return result

    @staticmethod
    async def _collect(col: _Collector, timing: StepTiming) -> None:
        """Wait for the answers of one attempt: until all expected came, or the deadline; an open step
        with a quiet gap also ends once answers stop coming."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timing.deadline_s
        while (remaining := deadline - loop.time()) > 0:
            quiet = col.expected is None and timing.quiet_s is not None and col.responses
            if col.expected is None:
                col.complete.clear()
            try:
                async with asyncio.timeout(min(remaining, timing.quiet_s) if quiet else remaining):  # type: ignore[type-var]
                    await col.complete.wait()
            except TimeoutError:
                if quiet:
                    return
                continue
            if col.expected is not None:
                return

    @staticmethod
    def _step_done(col: _Collector) -> bool:

        if col.expected is None:
            return bool(col.responses)
        return col.expected <= col.responses.keys()
