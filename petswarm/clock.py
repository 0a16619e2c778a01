"""Time for the robot middleware: one reading of ``now`` that is the wall clock or model time.

Every manager asks ``now()`` (seconds, monotonic) and sleeps with ``asyncio.sleep``; both go through the
running event loop. On an ordinary loop that is the wall clock (``--clock wall``). On a
``ModelClockLoop`` it is model time: the loop never blocks, and when nothing is ready it jumps straight
to the earliest timer (``--clock model``). The same robot code therefore runs unchanged in both clocks,
and in model time a run is as fast as the CPU allows and independent of the machine's load.

Ties: callbacks due at one instant run in the order they were scheduled. asyncio's ready queue is FIFO, but
its timer heap compares deadlines only, so equal deadlines would pop in heap order; a ``ModelClockLoop``
timer also carries a sequence number that breaks the tie (first scheduled, first run). Nothing else can
interleave in model time, so a run is a pure function of its seed and options.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import selectors
import signal
import time
from collections.abc import Callable
from typing import Any, Protocol

from radio_hub.values import MODEL_EPOCH_S


class ModelTimeStalled(RuntimeError):
    """Nothing is ready and no timer is pending: every task waits on something that can never happen."""


class _ModelSelector(selectors.DefaultSelector):
    """A real selector (the loop's self-pipe still works) that never blocks: a wait advances model time."""

    def __init__(self) -> None:
        super().__init__()
        self.now = 0.0
        self.loop: ModelClockLoop | None = None

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        loop = self.loop
        assert loop is not None
        if loop.checkpoint is not None:
            loop.checkpoint()
        if timeout == 0 and loop.nothing_to_read():
            return []  # callbacks are ready: a poll of the self-pipe alone, nobody having written it, finds nothing
        ready = super().select(0)
        if ready or timeout == 0:
            return ready
        # nothing is ready: the instant is over for every task on this loop
        if loop.on_quiescent is not None and loop.on_quiescent():
            return []
        return loop.wait_quiet(super().select)


class _OrderedTimer(asyncio.TimerHandle):
    """A timer that, at an equal deadline, comes after every timer scheduled before it."""

    __slots__ = ("_order",)

    def __init__(
        self, when: float, callback: Callable[..., Any], args: tuple[Any, ...], loop: Any, context: Any, order: int
    ) -> None:
        super().__init__(when, callback, args, loop, context)
        self._order = order

    def __lt__(self, other: object) -> bool:
        # the heap compares timers on every push and pop (about 130,000 times in a 22 s cylinder run): no tuples
        if type(other) is _OrderedTimer:
            when, other_when = self._when, other._when
            # (``is``: as a tuple compares its items, so a nan deadline orders as the tuples did)
            return when < other_when or ((when is other_when or when == other_when) and self._order < other._order)
        if isinstance(other, _OrderedTimer):
            return (self._when, self._order) < (other._when, other._order)
        return super().__lt__(other)


class ModelClockLoop(asyncio.SelectorEventLoop):
    """An asyncio loop on model time: ``time()`` starts at 0 and moves only when the loop would wait."""

    def __init__(self) -> None:
        self._model = _ModelSelector()
        self._model.loop = self
        self._timer_order = itertools.count()
        self._written = False
        """A thread (``call_soon_threadsafe``) wrote to the self-pipe since the selector last polled it."""
        self.on_quiescent: Callable[[], bool] | None = None
        """Called when nothing is ready, before time moves; True when it made something ready (a driver
        releasing the messages it held for this instant, ``radio_hub.coordinator``)."""
        self.checkpoint: Callable[[], None] | None = None
        """Called once per pass of the loop, before it looks for I/O: an exception it raises leaves
        ``run_until_complete`` with the loop as it was between two passes (``Interrupts.check``)."""
        super().__init__(self._model)

    def call_at(
        self, when: float, callback: Callable[..., Any], *args: Any, context: Any = None
    ) -> asyncio.TimerHandle:
        """As asyncio's, with ties at one deadline run first scheduled, first run."""
        self._check_closed()  # type: ignore[attr-defined]
        timer = _OrderedTimer(when, callback, args, self, context, next(self._timer_order))
        heapq.heappush(self._scheduled, timer)  # type: ignore[attr-defined]
        timer._scheduled = True  # type: ignore[attr-defined]
        return timer

    def time(self) -> float:
        """Model seconds since the loop was made."""
        return self._model.now

    def nothing_to_read(self) -> bool:
        """Whether a poll of the selector would surely find nothing: only the loop's self-pipe is watched, no
        thread has written to it since the last poll, and no signal can (asyncio's signal handlers write to it
        from C, unseen by ``_write_to_self``). Model time polls once per pass of the loop: about 60,000 system
        calls in a 48 s driving scenario that, with nothing watched, can only come back empty."""
        if self._written or self._signal_handlers or len(self._model.get_map()) > 1:  # type: ignore[attr-defined]
            self._written = False
            return False
        return True

    def _write_to_self(self) -> None:
        self._written = True
        super()._write_to_self()  # type: ignore[misc]

    def next_timer(self) -> float | None:
        """When the earliest live timer is due (None: no timer); cancelled timers at the head are dropped, as
        asyncio itself does before it computes a timeout."""
        scheduled = self._scheduled  # type: ignore[attr-defined]
        while scheduled and scheduled[0]._cancelled:
            self._timer_cancelled_count -= 1  # type: ignore[attr-defined]
            heapq.heappop(scheduled)._scheduled = False
        return scheduled[0]._when if scheduled else None

    def wait_quiet(self, real_select: Callable[[float | None], Any]) -> Any:
        """Every task waits: move model time exactly to the earliest timer (now + timeout would round)."""
        when = self.next_timer()
        if when is None:
            raise ModelTimeStalled("model time stalled: no task is ready and no timer is pending")
        self._model.now = max(self._model.now, when)
        return []

    def advance_to(self, when: float) -> None:
        """Move model time forward to ``when`` (never back); for drivers that own the clock."""
        self._model.now = max(self._model.now, when)


class LockstepSync(Protocol):
    """What a lockstep loop tells the hub when every task waits (``radio_hub.link.lockstep_link.LockstepLink``)."""

    def idle(self, next_timer: float | None) -> None:
        """Report: all handled, nothing ready, the next timer due at ``next_timer`` (model seconds)."""

    def wait_grant(self) -> None:
        """Block until the hub's grant arrives (and ``grant`` the loop its instant), or until ``wake``."""

    def wake(self) -> None:
        """End a ``wait_grant`` under way (from any thread or a signal handler)."""


class LockstepLoop(ModelClockLoop):
    """A process's loop on model time that the hub owns (``--clock lockstep``).

    When every task waits, it reports idle to the hub (``sync.idle``) and blocks in ``sync.wait_grant`` until the
    hub's grant arrives, which moves ``time()`` with ``grant`` before asyncio looks at its timers: the timers due
    at the granted instant run in that same pass, before the instant's messages are released, as a model-time
    loop that jumps to an instant takes them. A thread's ``call_soon_threadsafe`` or a signal ends the wait
    early (``sync.wake``). Until a link syncs it there is no model time to wait for; once the link has left
    (``sync`` back to None) the process is out of the world and its loop waits on timers and threads as it
    needs to shut down.
    """

    def __init__(self) -> None:
        super().__init__()
        self.sync: LockstepSync | None = None
        self._synced = False
        self._waiting = False
        """In ``sync.wait_grant``: a wake-up for the loop must end that wait, not only write the self-pipe."""
        self._pokes = 0
        """Wake-ups asked for (threads, signals); ``_pokes_seen``: as many as the loop had when it last waited.
        A wake-up that came just before ``_waiting`` was set is seen this way, and the wait skipped."""
        self._pokes_seen = 0

    def attach_sync(self, sync: LockstepSync | None) -> None:
        """Start (or, with None, end) reporting to the hub."""
        self._synced = self._synced or sync is not None
        self.sync = sync

    def grant(self, at_s: float) -> None:
        """The hub's grant: model time is now ``at_s`` (it never goes back)."""
        self._model.now = max(self._model.now, at_s)

    def wait_quiet(self, real_select: Callable[[float | None], Any]) -> Any:
        """Report idle and block until the hub answers; before or after the world, wait as needed."""
        sync = self.sync
        if sync is not None:
            sync.idle(self.next_timer())
            self._waiting = True
            try:
                if self._pokes == self._pokes_seen:
                    sync.wait_grant()
            finally:
                self._waiting = False
                self._pokes_seen = self._pokes
            return real_select(0)  # what a thread or a signal wrote to the self-pipe meanwhile
        if not self._synced:
            raise RuntimeError("a lockstep loop waited before its link to the hub was open")
        if self.next_timer() is None:
            return real_select(None)  # a thread (the session closing) will wake us
        return super().wait_quiet(real_select)

    def _write_to_self(self) -> None:
        super()._write_to_self()  # type: ignore[misc]
        self._wake_waiting()

    def add_signal_handler(self, sig: int, callback: Callable[..., Any], *args: Any) -> None:
        """As asyncio's, and a signal that comes while the loop waits for its grant ends that wait (asyncio's
        own wake-up goes to the self-pipe, which nobody watches then)."""
        super().add_signal_handler(sig, callback, *args)
        signal.signal(sig, self._on_signal)

    def close(self) -> None:
        """As asyncio's, except that a SIGTERM handler of the loop's is left as "ignore", never at the default
        action: a node whose loop closes has done its work and written its record, and the SIGTERM a run sends
        its nodes at the end must not kill it while it closes (it would report death by signal, -15). asyncio's
        close resets each of the loop's signals to its default first; a SIGTERM in that gap killed a robot in CI
        right after its stop event. A loop without a SIGTERM handler (the run's own) leaves SIGTERM alone."""
        if signal.SIGTERM in self._signal_handlers:  # type: ignore[attr-defined]
            work_done(self)
        super().close()

    def _on_signal(self, signum: int, frame: Any) -> None:
        self._wake_waiting()

    def _wake_waiting(self) -> None:
        self._pokes += 1  # first: a loop about to wait sees it (see ``_pokes``)
        sync = self.sync
        if self._waiting and sync is not None:
            sync.wake()


def work_done(loop: asyncio.AbstractEventLoop) -> None:
    """A node process whose work is done and written (a robot after its close): SIGTERM is ignored from now on,
    and the loop's stop signals are handed back before the loop closes.

    Why: asyncio's close puts each of the loop's signals back to its default action, and the SIGTERM that comes
    next (the supervisor's after ``timeout``'s to the process group, or after a terminal's Ctrl-C) killed a
    wall-clock robot that had stopped and written its last event: its exit code said death by signal (-15). A
    second SIGTERM 20 to 50 ms after the first did so 8 times in 8. asyncio's close also shuts its self-pipe
    before it hands the signals back, and a signal in between was written to a closed descriptor ("Exception
    ignored ... Bad file descriptor" in a robot's log). ``LockstepLoop.close`` calls it for a lockstep node."""
    handlers = getattr(loop, "_signal_handlers", {})  # asyncio's: it resets whatever is left there on close
    if handlers.pop(signal.SIGTERM, None) is not None:  # popped, not removed: no moment at the default action
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    if signal.SIGINT in handlers:
        loop.remove_signal_handler(signal.SIGINT)  # Ctrl-C is Python's own again, as asyncio's close leaves it
    if not handlers:
        signal.set_wakeup_fd(-1)  # the self-pipe closes with the loop: no signal is written there from now on


async def sleep_until(when: float) -> None:
    """Sleep until the loop's clock reads ``when`` (not at all if it already does). ``call_at`` takes the
    deadline itself: ``asyncio.sleep(when - now)`` would add it back to ``now`` and may miss it by a rounding."""
    if when <= now():
        return
    loop = asyncio.get_running_loop()
    woken = loop.create_future()
    handle = loop.call_at(when, _wake, woken)
    try:
        await woken
    finally:
        handle.cancel()


def _wake(future: asyncio.Future[None]) -> None:
    if not future.done():
        future.set_result(None)


def now() -> float:
    """Monotonic seconds on the running loop's clock (model time on a ``ModelClockLoop``)."""
    try:
        return asyncio.get_running_loop().time()
    except RuntimeError:  # no loop (a constructor called from plain code): the wall clock
        return time.monotonic()


def wall_time() -> float:
    """Seconds since the epoch: the real date, or ``MODEL_EPOCH_S`` + model time in model time."""
    loop = _running_loop()
    if isinstance(loop, ModelClockLoop):
        return MODEL_EPOCH_S + loop.time()
    return time.time()


def in_model_time() -> bool:
    """True when the running loop is a ``ModelClockLoop``."""
    return isinstance(_running_loop(), ModelClockLoop)


def _running_loop() -> Any:
    try:
        return asyncio.get_running_loop()
    except RuntimeError:
        return None
