"""The message-processing manager: deadlines, retries of the missing only, duplicates, late answers."""

import asyncio

import pytest

from petswarm import clock
from petswarm.managers.actions import Incoming
from petswarm.managers.event_log import EventLog
from petswarm.managers.exchange import SendRequest, Step, StepOver, StepTiming, WaitUntil
from petswarm.managers.message_processing import MessageProcessingManager
from petswarm.managers.messages import JoinAvailable, Joined
from radio_hub.air.mac import Frame, FrameType
from radio_hub.values import RxFrame

TIMING = StepTiming(deadline_s=0.02, max_retries=3)


def _incoming(src: int, message) -> Incoming:
    frame = Frame(FrameType.DATA, 0, 0x1000, 1, 0x1000, src, message.encode())
    return Incoming(message, RxFrame(frame, -50.0, 200, 0, 0, 0), clock.now())


async def test_step_ends_as_soon_as_everyone_answered():
    mpm = MessageProcessingManager(EventLog())
    sent = []

    async def send(missing):
        sent.append(missing)
        for addr in (2, 3):
            mpm.offer(_incoming(addr, Joined(7, addr - 1)))

    result = await asyncio.wait_for(mpm.step("notice", 7, (Joined,), send, {2, 3}, StepTiming(5.0, 3)), 1.0)
    assert set(result.responses) == {2, 3} and result.retries == 0 and sent == [{2, 3}]


async def test_missing_robots_are_asked_again_until_the_retries_run_out():
    log = EventLog()
    mpm = MessageProcessingManager(log)
    asked = []

    async def send(missing):
        asked.append(sorted(missing))
        if len(asked) == 2:
            mpm.offer(_incoming(3, Joined(7, 2)))
        mpm.offer(_incoming(2, Joined(7, 1)))  # robot 2 answers every time: a duplicate after the first

    result = await mpm.step("notice", 7, (Joined,), send, {2, 3, 4}, TIMING)
    assert asked == [[2, 3, 4], [3, 4], [4], [4]]
    assert result.attempts == 4 and result.retries == 3 and result.missing == {4}
    assert mpm.duplicates == 3 and mpm.retries == 3
    assert [e["missing"] for e in log.events if e["kind"] == "retry"] == [[3, 4], [4], [4]]


async def test_answers_of_another_session_or_type_are_not_taken():
    mpm = MessageProcessingManager(EventLog())

    async def send(missing):
        assert not mpm.offer(_incoming(2, Joined(8, 1)))  # other session
        assert not mpm.offer(_incoming(2, JoinAvailable(7, -50)))  # other type

    result = await mpm.step("notice", 7, (Joined,), send, {2}, StepTiming(0.01, 0))
    assert result.responses == {} and result.missing == {2}
    assert not mpm.offer(_incoming(2, Joined(7, 1)))  # the step is over: the caller counts it late


async def test_open_step_collects_until_the_deadline_and_retries_only_if_nobody_answered():
    mpm = MessageProcessingManager(EventLog())
    calls = []

    async def send(missing):
        calls.append(missing)
        if len(calls) == 2:
            mpm.offer(_incoming(5, Joined(1, 1)))

    result = await mpm.step("scan", 1, (Joined,), send, None, TIMING)
    assert calls == [None, None] and set(result.responses) == {5} and result.retries == 1


async def test_open_step_with_a_quiet_gap_ends_once_answers_stop():
    mpm = MessageProcessingManager(EventLog())

    async def send(missing):
        mpm.offer(_incoming(5, Joined(1, 1)))
        asyncio.get_running_loop().call_later(0.03, mpm.offer, _incoming(6, Joined(1, 2)))

    loop = asyncio.get_running_loop()
    started = loop.time()
    result = await mpm.step("scan", 1, (Joined,), send, None, StepTiming(2.0, 0, quiet_s=0.06))
    elapsed = loop.time() - started
    assert set(result.responses) == {5, 6}  # the second answer came inside the gap and was waited for
    assert 0.08 <= elapsed < 1.0  # ended a quiet gap after the last answer, long before the deadline


# -- the sans-IO step, stepped by hand: no loop, no clock ---------------------------------------------------


def test_a_closed_step_asks_the_missing_again_at_each_deadline_and_ends_when_all_answered():
    step = Step(7, (Joined,), {2, 3}, StepTiming(deadline_s=0.1, max_retries=3))
    assert step.next_action(0.0) == SendRequest({2, 3}, retry=False)
    step.sent(0.001)
    assert step.next_action(0.05) == WaitUntil(0.101)
    assert step.offer(_incoming(2, Joined(7, 1)), 0.06)
    assert step.next_action(0.06) == WaitUntil(0.101)  # robot 3 still missing: the window stays open
    assert step.next_action(0.101) == SendRequest({3}, retry=True)
    step.sent(0.102)
    assert step.offer(_incoming(3, Joined(7, 2)), 0.15)
    assert step.next_action(0.15) == StepOver()  # complete before the deadline: no waiting it out
    result = step.result()
    assert set(result.responses) == {2, 3} and result.retries == 1 and result.missing == set()


def test_a_closed_step_gives_up_after_max_retries_and_names_who_never_answered():
    step = Step(7, (Joined,), {2, 3}, StepTiming(deadline_s=0.1, max_retries=2))
    now, sends = 0.0, []
    while not isinstance(action := step.next_action(now), StepOver):
        if isinstance(action, SendRequest):
            sends.append(sorted(action.missing or ()))
            step.sent(now)
        else:
            now = action.when
    assert sends == [[2, 3]] * 3 and now == pytest.approx(0.3)
    assert step.result().missing == {2, 3} and step.result().attempts == 3


def test_an_open_step_with_a_quiet_gap_ends_once_answers_stop_and_counts_duplicates():
    step = Step(1, (Joined,), None, StepTiming(deadline_s=1.0, max_retries=2, quiet_s=0.05))
    assert step.next_action(0.0) == SendRequest(None, retry=False)
    step.sent(0.0)
    assert step.next_action(0.01) == WaitUntil(1.0)  # no answer yet: the whole deadline
    step.offer(_incoming(4, Joined(1, 1)), 0.02)
    step.offer(_incoming(4, Joined(1, 1)), 0.03)
    assert step.duplicates == 1
    assert step.next_action(0.03) == WaitUntil(pytest.approx(0.07))
    assert step.next_action(0.07) == StepOver()
    assert not step.offer(_incoming(5, JoinAvailable(1, -50)), 0.08)  # another type: not this step's


def test_a_step_expecting_nobody_is_over_at_once():
    assert Step(1, (Joined,), set(), TIMING).next_action(0.0) == StepOver()


def test_an_open_step_with_a_rule_of_enough_asks_everyone_again_until_enough_answered():
    # the scan's rule: two answers are enough; one came in the first window, so the request goes out again
    step = Step(1, (Joined,), None, StepTiming(deadline_s=0.1, max_retries=3), enough=lambda got: len(got) >= 2)
    assert step.next_action(0.0) == SendRequest(None, retry=False)
    step.sent(0.0)
    step.offer(_incoming(4, Joined(1, 1)), 0.01)
    assert step.next_action(0.01) == WaitUntil(0.1)  # an open step waits out its window
    assert step.next_action(0.1) == SendRequest(None, retry=True)  # not enough: to everyone again
    step.sent(0.1)
    step.offer(_incoming(4, Joined(1, 1)), 0.11)  # the same robot again is no second answer
    assert step.next_action(0.2) == SendRequest(None, retry=True)
    step.sent(0.2)
    step.offer(_incoming(5, Joined(1, 2)), 0.21)
    assert step.next_action(0.31) == StepOver()
    assert set(step.result().responses) == {4, 5} and step.result().retries == 2 and step.duplicates == 1


def test_a_retried_open_step_gives_its_answers_a_whole_quiet_gap_from_the_resend():
    # the slotted scan: answers stop coming for the quiet gap, not enough came, so it asks again; the new
    # request's answers need their slots too. Counting the gap from the last answer of the first window ended
    # every retry at once: five resends in 8 ms, and a robot whose first answer was lost answered too late.
    timing = StepTiming(deadline_s=0.1, max_retries=5, quiet_s=0.04)
    step = Step(1, (Joined,), None, timing, enough=lambda got: len(got) >= 2)
    step.next_action(0.0)
    step.sent(0.0)
    step.offer(_incoming(4, Joined(1, 1)), 0.01)
    assert step.next_action(0.05) == SendRequest(None, retry=True)  # quiet since 0.01, one answer of two
    step.sent(0.05)
    assert step.next_action(0.051) == WaitUntil(pytest.approx(0.09))  # the resend's own quiet gap
    step.offer(_incoming(5, Joined(1, 2)), 0.07)
    assert step.next_action(0.12) == StepOver()  # quiet since 0.07, and enough
    assert set(step.result().responses) == {4, 5} and step.result().retries == 1


def test_an_open_step_that_never_has_enough_ends_after_max_retries_with_what_came():
    step = Step(1, (Joined,), None, StepTiming(deadline_s=0.1, max_retries=2), enough=lambda got: len(got) >= 3)
    now, sends = 0.0, 0
    while not isinstance(action := step.next_action(now), StepOver):
        if isinstance(action, SendRequest):
            sends += 1
            step.sent(now)
            step.offer(_incoming(4, Joined(1, 1)), now)
        else:
            now = action.when
    assert sends == 3 and now == pytest.approx(0.3) and set(step.result().responses) == {4}


def test_only_an_open_step_takes_a_rule_of_enough():
    with pytest.raises(ValueError):
        Step(1, (Joined,), {2}, TIMING, enough=lambda got: True)
