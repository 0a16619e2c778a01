"""``Interrupts`` (petswarm/lab/processes.py): the first stop signal waits for a safe point (``at_safe_points``) or
is raised again at one when it was lost, is never dropped on the way out, and once a run was interrupted later
signals stay only noted until the process ends. Each test hands the signals back (``release``), as the process
that ends would not need to."""

from __future__ import annotations

import signal
import weakref

import pytest

from petswarm.lab.processes import Interrupts


@pytest.fixture(autouse=True)
def _handlers_back():
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    yield
    for signum, handler in before.items():
        signal.signal(signum, handler)


def test_the_first_signal_waits_for_the_safe_point_and_is_raised_there_once() -> None:
    interrupts = Interrupts(at_safe_points=True)
    with pytest.raises(KeyboardInterrupt):
        try:
            signal.raise_signal(signal.SIGTERM)  # the handler returns: nothing is raised where it landed
            assert interrupts.pending
            interrupts.check()
        finally:
            signal.raise_signal(signal.SIGINT)  # during the stop: only noted
            with interrupts.deferred():
                interrupts.check()  # raised already: the stop is not interrupted again
    assert interrupts.noted == [signal.SIGINT] and not interrupts.pending


def test_a_signal_still_pending_when_the_stop_begins_is_raised_after_the_stop() -> None:
    interrupts = Interrupts(at_safe_points=True)
    signal.raise_signal(signal.SIGINT)  # after the last safe point
    stopped = []
    with pytest.raises(KeyboardInterrupt), interrupts.deferred():
        stopped.append(True)
    assert stopped == [True]
    # on the way out (exit 130) a second Ctrl-C is only noted, not a KeyboardInterrupt that ends it as -2
    signal.raise_signal(signal.SIGINT)
    assert interrupts.noted == [signal.SIGINT]
    interrupts.release()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_run_no_signal_touched_hands_the_signals_back() -> None:
    before = signal.getsignal(signal.SIGTERM)
    interrupts = Interrupts()
    assert signal.getsignal(signal.SIGTERM) != before
    with interrupts.deferred():
        pass
    assert signal.getsignal(signal.SIGTERM) == before  # the next run of an experiment takes them


def test_without_safe_points_the_first_signal_raises_where_it_lands() -> None:
    interrupts = Interrupts()
    with pytest.raises(KeyboardInterrupt):
        try:
            signal.raise_signal(signal.SIGINT)
        finally:
            with interrupts.deferred():
                pass
    assert not interrupts.pending and interrupts.noted == []


class _Dropped:
    """An object whose only strong reference goes away: its weakref's callback runs at once."""


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_a_first_signal_lost_in_a_weakref_callback_is_raised_again_at_the_runs_next_check() -> None:
    interrupts = Interrupts()  # a run of processes: the handler raises where the signal lands
    dropped = _Dropped()
    ref = weakref.ref(dropped, lambda _: signal.raise_signal(signal.SIGTERM))
    del dropped  # the handler's KeyboardInterrupt is raised in the callback, where Python drops it
    assert ref() is None  # and this line runs: the run would go on
    with pytest.raises(KeyboardInterrupt):
        interrupts.check()  # the run's loop (Supervision.check) raises it again
    with interrupts.deferred():
        interrupts.check()  # the stop under way is not interrupted again
    assert interrupts.noted == []
