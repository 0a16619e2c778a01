"""The message-processing manager: runs a sans-IO ``Step`` (``petswarm.managers.exchange``) on the event loop,
routing answers to the step waiting for them, sending its requests and waiting out its windows on the loop's
clock.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Awaitable, Callable

from petswarm import clock
from petswarm.managers.actions import Incoming
from petswarm.managers.event_log import EventLog
from petswarm.managers.exchange import SendRequest, Step, StepOver, StepResult, StepTiming
from petswarm.managers.messages import SwarmMessage


class MessageProcessingManager:
    """Runs ``Step``s on the event loop: routes answers to the step waiting for them; counts duplicates and
    late arrivals."""

    def __init__(self, log: EventLog) -> None:
        self.log = log
        self.duplicates = 0
        self.late = 0
        self.retries = 0
        self._steps: list[tuple[Step, asyncio.Event]] = []

    def offer(self, incoming: Incoming) -> bool:
        """Hand a received message to a waiting step; False when no step wants it."""
        for step, arrived in self._steps:
            before = step.duplicates
            if step.offer(incoming, clock.now()):
                self.duplicates += step.duplicates - before
                arrived.set()
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

        ``send(missing)`` puts the request on the air (``missing`` is None when ``expected`` is None, i.e.
        when anyone may answer: then the step collects until the deadline, or until answers stop for
        ``quiet_s``, retrying only if nobody answered at all; ``Step``'s ``enough`` sets another rule).
        """
        return await self.run(name, Step(session, kinds, expected, timing), send)

    async def run(self, name: str, step: Step, send: Callable[[set[int] | None], Awaitable[None]]) -> StepResult:
        """Run a step made elsewhere (a sans-IO core's, ``formation_core.Exchange``): route answers to it, send
        its requests with ``send(missing)``, wait out its windows on the loop's clock."""
        session = step.session
        arrived = asyncio.Event()
        entry = (step, arrived)
        self._steps.append(entry)
        try:
            while not isinstance(action := step.next_action(clock.now()), StepOver):
                if isinstance(action, SendRequest):
                    if action.retry:
                        self.retries += 1
                        missing = sorted(action.missing or ())
                        self.log.record("retry", step=name, session=session, attempt=step.attempts - 1, missing=missing)
                    await send(action.missing)
                    step.sent(clock.now())
                    continue
                arrived.clear()
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(max(action.when - clock.now(), 0.0)):
                        await arrived.wait()
        finally:
            self._steps.remove(entry)
        return step.result()
