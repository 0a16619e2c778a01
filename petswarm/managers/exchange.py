"""Message processing, sans-IO: a request, the responses it expects, its deadline and retries, as a ``Step``
(``petswarm.managers.message_processing`` runs steps on the event loop).

A step of the swarm process sends a request, then waits until every expected robot has answered or the
deadline passes; it then repeats the request to the robots still missing, a bounded number of times. An open
step (anyone may answer: the scan) cannot name the missing, so it repeats its request to everyone while the
answers that came are not ``enough`` (the paper: the middleware retries when it determines that not all of
the responses to the request have arrived; for the scan, fewer than the user asked for).
Responses are matched by session and type; a duplicate (the same robot again) or a late one (after the
step ended) is counted and otherwise ignored, so retries are idempotent.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from petswarm.managers.actions import Incoming
from petswarm.managers.messages import SwarmMessage


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


@dataclass(frozen=True)
class SendRequest:
    """Put the step's request on the air, to ``missing`` (None: to anyone, an open step's first attempt)."""

    missing: set[int] | None
    retry: bool
    """True from the second attempt on."""


@dataclass(frozen=True)
class WaitUntil:
    """Nothing to do before ``when`` (seconds) unless an answer arrives."""

    when: float


@dataclass(frozen=True)
class StepOver:
    """The step has ended: every expected answer came, or the attempts ran out."""


StepAction = SendRequest | WaitUntil | StepOver


class Step:
    """One request/response step as a sans-IO state machine: answers and ``now`` in, actions out.

    The driver asks ``next_action(now)``: ``SendRequest`` (it sends, then calls ``sent(now)``), ``WaitUntil``
    (it waits until then or until ``offer`` takes an answer), or ``StepOver``. No clock, no I/O: the same
    object runs under the asyncio manager, in model time, or stepped by hand in a test.
    """

    def __init__(
        self,
        session: int,
        kinds: tuple[type[SwarmMessage], ...],
        expected: set[int] | None,
        timing: StepTiming,
        enough: Callable[[Mapping[int, Incoming]], bool] | None = None,
    ) -> None:
        """``enough`` (open steps only): whether the answers so far end the step at the end of a window; by
        default any answer does."""
        if enough is not None and expected is not None:
            raise ValueError("only an open step (expected None) decides by its answers when it has enough")
        self.session = session
        self.kinds = kinds
        self.expected = None if expected is None else set(expected)
        self.timing = timing
        self.enough = enough
        self.responses: dict[int, Incoming] = {}
        self.attempts = 0
        self.duplicates = 0
        self._deadline: float | None = None
        """End of the current attempt's window; None before the first send and between attempts."""
        self._last_answer = 0.0
        self._sent_at = 0.0

    @property
    def missing(self) -> set[int] | None:
        """Expected robots that have not answered (None for an open step)."""
        return None if self.expected is None else self.expected - self.responses.keys()

    def offer(self, incoming: Incoming, now: float) -> bool:
        """Take an answer meant for this step (a duplicate is counted); False when it is not for this step."""
        msg = incoming.message
        if msg.session_id != self.session or not isinstance(msg, self.kinds):
            return False
        if incoming.sender in self.responses:
            self.duplicates += 1
        else:
            self.responses[incoming.sender] = incoming
            self._last_answer = now
        return True

    def sent(self, now: float) -> None:
        """The request of the current attempt is on the air: its answer window starts now."""
        self._deadline = now + self.timing.deadline_s
        self._sent_at = now

    def next_action(self, now: float) -> StepAction:
        """What to do at ``now``."""
        if self.expected is not None and not self.expected:
            return StepOver()
        if self._deadline is not None:
            end = self._window_end()
            if now < end and not self._complete():
                return WaitUntil(end)
            self._deadline = None
            if self._done():
                return StepOver()
        if self.attempts > self.timing.max_retries:
            return StepOver()
        self.attempts += 1
        return SendRequest(self.missing, retry=self.attempts > 1)

    def result(self) -> StepResult:
        """What the step collected."""
        return StepResult(self.responses, self.attempts, self.missing or set())

    def _window_end(self) -> float:
        assert self._deadline is not None
        quiet = self.timing.quiet_s
        if self.expected is None and quiet is not None and self.responses:
            # answers have stopped coming; a resend's answers get a whole gap of their own
            return min(self._deadline, max(self._last_answer, self._sent_at) + quiet)
        return self._deadline

    def _complete(self) -> bool:
        return self.expected is not None and self.expected <= self.responses.keys()

    def _done(self) -> bool:
        if self.expected is not None:
            return self._complete()
        return bool(self.responses) if self.enough is None else self.enough(self.responses)
