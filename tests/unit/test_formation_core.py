"""The sans-IO formation core driven by hand: no event loop, no radio, explicit times.

Each test hands the core events (a message with its frame, a MAC report, a timer, a user's request) with
``now`` and looks at the actions it returns; a master's request is a procedure resumed by hand, its steps
stepped by hand (``exchange_by_hand``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from petswarm.managers import messages as m
from petswarm.managers.actions import Incoming, Log, Send
from petswarm.managers.event_log import EventLog
from petswarm.managers.exchange import SendRequest, StepOver, StepResult
from petswarm.managers.formation_core import (
    ANSWER_ATTEMPTS,
    MEMBER_MISSES,
    Action,
    Answer,
    ConfigurePan,
    Dissolve,
    Done,
    Exchange,
    FormationConfig,
    FormationCore,
    FormationError,
    HandedOver,
    Pause,
    Procedure,
    StartRoster,
    StopRoster,
    Swarm,
    SwarmChanged,
)
from petswarm.managers.sequence import RobotState, SequenceManager, StateChange
from radio_hub.air.mac import Frame, FrameType
from radio_hub.values import BROADCAST, RxFrame, TxResult, TxStatus

WAITING_PAN = 0x1000
SWARM_PAN = 0x2345
CONFIG = FormationConfig()
DEADLINE = CONFIG.step.deadline_s


def _core(me: int, state: RobotState = RobotState.WAITING, user: int = 0, seed: int = 0) -> FormationCore:
    return FormationCore(me, SequenceManager(EventLog(), state), CONFIG, np.random.default_rng(seed), user)


def _incoming(
    sender: int, message: m.SwarmMessage, rssi: float = -50.0, at: float = 0.0, to: int = BROADCAST
) -> Incoming:
    frame = Frame(FrameType.DATA, 1, BROADCAST, to, WAITING_PAN, sender, message.encode(), False)
    return Incoming(message, RxFrame(frame, rssi, 200, 0, 1000, 0), received_at=at)


def _of(actions: list[Action], kind: type) -> list[Any]:
    return [a for a in actions if isinstance(a, kind)]


def _records(actions: list[Action], kind: str) -> list[dict[str, Any]]:
    return [a.detail for a in actions if isinstance(a, Log) and a.kind == kind]


def _member(me: int = 3, master: int = 1, members: tuple[int, ...] = (3, 4)) -> FormationCore:
    """A slave of ``master``'s swarm of session 7 on ``SWARM_PAN``, numbered by its place in ``members``."""
    core = _core(me)
    core.receive(_incoming(master, m.JoinQuery(7, 0, -70, 0, ())), 0.0)
    core.receive(_incoming(master, m.JoinNotice(7, SWARM_PAN, len(members) + 1, members.index(me) + 1, 0)), 0.1)
    core.pan_id = SWARM_PAN
    core.receive(_incoming(master, m.Roster(7, members)), 0.2)
    return core


def _master(me: int = 1, members: tuple[int, ...] = (2, 3)) -> FormationCore:
    """The master of session 7 on ``SWARM_PAN`` with ``members``, as ``organize`` leaves it."""
    core = _core(me, RobotState.FOLLOWING, user=9)
    core.sequence.enter(RobotState.ORGANIZING)
    core.sequence.enter(RobotState.MASTER_DRIVING)
    core.swarm = Swarm(7, SWARM_PAN, me, 0, members)
    core.pan_id = SWARM_PAN
    return core


# -- carrying a procedure out by hand ------------------------------------------------------------------

Answering = Callable[[list[Send], int], list[Incoming]]
"""The robots' side of a step: the answers to one attempt's requests (its number from 1)."""


def exchange_by_hand(
    exchange: Exchange, answering: Answering, now: float
) -> tuple[StepResult, float, list[list[Send]]]:
    """Step ``exchange`` by hand from ``now``: answers arrive 5 ms after each attempt's requests; returns the
    result, the time the step ended and the requests of every attempt."""
    step, attempts = exchange.step, []
    while not isinstance(action := step.next_action(now), StepOver):
        if isinstance(action, SendRequest):
            requests = exchange.requests(action.missing)
            attempts.append(requests)
            step.sent(now)
            now += 0.005
            for incoming in answering(requests, len(attempts)):
                step.offer(incoming, now)
        else:
            now = action.when
    return step.result(), now, attempts


def carry_out(
    procedure: Procedure[Any], answering: dict[str, Answering], now: float = 0.0
) -> tuple[Any, list[Action], dict[str, list[list[Send]]]]:
    """Carry out a master's procedure by hand: every action takes no time except exchanges, run with
    ``answering[name]``. Returns the procedure's result, its actions, and each exchange's attempts."""
    actions: list[Action] = []
    attempts: dict[str, list[list[Send]]] = {}
    done: Done | None = None
    while True:
        try:
            action = procedure.send(done)  # type: ignore[arg-type]
        except StopIteration as stop:
            return stop.value, actions, attempts
        actions.append(action)
        value = None
        if isinstance(action, Exchange):
            value, now, attempts[action.name] = exchange_by_hand(action, answering[action.name], now)
        done = Done(now, value)


def _nobody(requests: list[Send], attempt: int) -> list[Incoming]:
    return []


# -- Table 1: a robot's answer to the joining query ----------------------------------------------------


@pytest.mark.parametrize(
    "state, user, rssi, expected",
    [
        (RobotState.WAITING, 0, -60.0, None),  # not connected, inside: available
        (RobotState.WAITING, 0, -80.0, m.Refusal.OUTSIDE_REGION),  # not connected, outside
        (RobotState.FOLLOWING, 4, -60.0, m.Refusal.CONNECTED_TO_USER),  # connected to another user, inside
        (RobotState.FOLLOWING, 4, -80.0, m.Refusal.CONNECTED_TO_USER),  # connection is checked first
    ],
)
def test_table_1_answers_to_a_listed_query(state: RobotState, user: int, rssi: float, expected: m.Refusal | None):
    core = _core(3, state, user)
    actions = core.receive(_incoming(1, m.JoinQuery(7, 9, -70, 0, (3,)), rssi=rssi), 0.5)
    [answer] = _of(actions, Answer)
    assert answer.dst == 1 and answer.dst_pan == WAITING_PAN  # to the master, on the PAN it sent from
    if expected is None:
        assert answer.message == m.JoinAvailable(7, round(rssi))
        assert core.sequence.state == RobotState.ORGANIZING and core.candidate_of == (7, 1)
        assert _of(actions, StateChange) == [
            StateChange(RobotState.WAITING, RobotState.ORGANIZING, {"session": 7, "master": 1})
        ]
        assert core.get_timer() == pytest.approx(0.5 + CONFIG.candidate_timeout_s)
    else:
        assert answer.message == m.JoinUnavailable(7, int(expected))
        assert core.sequence.state == state and core.get_timer() is None


def test_a_candidate_answers_a_retried_query_the_same_and_refuses_another_master_as_busy():
    core = _core(3)
    core.receive(_incoming(1, m.JoinQuery(7, 9, -70, 0, (3,))), 0.0)
    again = core.receive(_incoming(1, m.JoinQuery(7, 9, -70, 0, (3,))), 0.1)
    assert [a.message for a in _of(again, Answer)] == [m.JoinAvailable(7, -50)] and not _of(again, StateChange)
    other = core.receive(_incoming(5, m.JoinQuery(8, 9, -70, 0, (3,))), 0.2)
    assert [a.message for a in _of(other, Answer)] == [m.JoinUnavailable(8, int(m.Refusal.BUSY))]
    assert core.candidate_of == (7, 1)


def test_a_query_that_lists_others_or_an_unlisted_query_to_a_busy_robot_is_not_answered():
    assert _core(3).receive(_incoming(1, m.JoinQuery(7, 9, -70, 0, (2, 4))), 0.0) == []
    assert _core(3, RobotState.FOLLOWING, 4).receive(_incoming(1, m.JoinQuery(7, 9, -70, 0, ())), 0.0) == []


def test_scan_reply_names_the_state_the_pan_and_the_user_in_an_answer_slot():
    core = _core(10, RobotState.LEADING, user=4)
    core.pan_id = 0x1234
    actions = core.receive(_incoming(1, m.Scan(7, 9, 4)), 0.0)
    # the slotted protocol: address 10 modulo 8 slots of 4 ms
    assert actions == [
        Pause(pytest.approx(0.008)),
        Answer(1, m.ScanReply(7, int(RobotState.LEADING), 0x1234, 4), WAITING_PAN),
    ]
    assert _core(10).receive(_incoming(1, m.Scan(7, 9, 0)), 0.0)[0] == Answer(
        1, m.ScanReply(7, 1, WAITING_PAN, 0), WAITING_PAN
    )


def test_an_answer_the_mac_fails_is_sent_again_after_a_random_pause_then_given_up():
    core = _core(3)
    [answer] = core.receive(_incoming(1, m.Scan(7, 9, 0)), 0.0)
    failed = TxResult(TxStatus.NO_ACK)
    follow = core.answer_sent(answer, failed)
    assert _records(follow, "answer_retry") == [{"type": "ScanReply", "status": "no_ack", "attempt": 0}]
    [pause] = _of(follow, Pause)
    assert 0.002 <= pause.seconds <= 0.02
    [again] = _of(follow, Answer)
    assert again.attempt == 1 and again.message == answer.message
    assert core.answer_sent(again, TxResult(TxStatus.SUCCESS)) == []
    last = Answer(answer.dst, answer.message, answer.dst_pan, ANSWER_ATTEMPTS - 1)
    assert core.answer_sent(last, failed) == [
        Log("answer_failed", {"type": "ScanReply", "status": "no_ack", "attempts": ANSWER_ATTEMPTS})
    ]


# -- joining and leaving as a member -------------------------------------------------------------------


def test_a_chosen_candidate_switches_pan_then_says_joined_on_it():
    core = _core(3)
    core.receive(_incoming(1, m.JoinQuery(7, 9, -70, 0, (3,))), 0.0)
    actions = core.receive(_incoming(1, m.JoinNotice(7, SWARM_PAN, 3, 2, 0)), 0.2)
    assert actions == [
        StateChange(RobotState.ORGANIZING, RobotState.SLAVE_DRIVING, {"session": 7, "pan_id": SWARM_PAN, "number": 2}),
        ConfigurePan(SWARM_PAN),
        SwarmChanged(Swarm(7, SWARM_PAN, 1, 2)),
        Pause(0.0),
        Send(1, m.Joined(7, 2), dst_pan=SWARM_PAN),
    ]
    # the master missed our Joined and asks again: the same answer, no second switch
    again = core.receive(_incoming(1, m.JoinNotice(7, SWARM_PAN, 3, 2, 0)), 0.3)
    assert again == [Pause(0.0), Send(1, m.Joined(7, 2), dst_pan=SWARM_PAN)]
    assert core.get_timer() == pytest.approx(0.2 + CONFIG.master_silence_s)


def test_a_notice_of_a_master_this_robot_did_not_answer_is_ignored():
    core = _core(3)
    assert core.receive(_incoming(1, m.JoinNotice(7, SWARM_PAN, 3, 2, 0)), 0.0) == []
    assert core.sequence.state == RobotState.WAITING


def test_a_candidate_without_a_result_notice_returns_to_waiting_at_its_deadline():
    core = _core(3)
    core.receive(_incoming(1, m.JoinQuery(7, 9, -70, 0, (3,))), 1.0)
    deadline = core.get_timer()
    assert deadline == pytest.approx(1.0 + CONFIG.candidate_timeout_s)
    actions = core.handle_timer(deadline + 0.05)
    assert _of(actions, StateChange)[0].detail == {"session": 7, "reason": "no result notice"}
    assert core.sequence.state == RobotState.WAITING and core.get_timer() is None
    assert not _of(actions, ConfigurePan)  # it never left the waiting PAN


def test_a_roster_keeps_a_member_and_its_silence_sends_it_home_with_word_to_the_master():
    core = _member(3, 1, (3, 4))
    assert core.get_timer() == pytest.approx(0.2 + CONFIG.master_silence_s)
    core.receive(_incoming(1, m.Roster(7, (3, 4))), 1.0)  # the master is alive: the deadline moves on
    assert core.get_timer() == pytest.approx(1.0 + CONFIG.master_silence_s)
    assert core.handle_timer(2.5) == []  # not yet silent for long enough
    core.hub_absent(2.9)  # no air at all: silence means nothing yet
    assert core.get_timer() == pytest.approx(2.9 + CONFIG.master_silence_s)
    actions = core.handle_timer(5.0)
    assert actions == [
        SwarmChanged(None),
        StateChange(RobotState.SLAVE_DRIVING, RobotState.WAITING, {"session": 7, "reason": "master silent"}),
        ConfigurePan(WAITING_PAN),
        Send(1, m.Dispersed(7), dst_pan=BROADCAST),
    ]
    assert core.swarm is None and core.get_timer() is None


def test_a_member_renumbers_on_a_changed_roster_and_leaves_one_that_does_not_count_it():
    core = _member(4, 1, (3, 4))
    assert core.swarm is not None and core.swarm.number == 2
    renumbered = core.receive(_incoming(1, m.Roster(7, (4,))), 0.5)
    assert renumbered == [SwarmChanged(Swarm(7, SWARM_PAN, 1, 1, (4,)))]
    assert core.receive(_incoming(1, m.Roster(7, (4,))), 0.6) == []  # unchanged: nothing to tell
    left = core.receive(_incoming(1, m.Roster(7, (3,))), 0.7)
    assert _of(left, StateChange)[0].detail["reason"] == "not in the master's roster"
    assert ConfigurePan(WAITING_PAN) in left and core.sequence.state == RobotState.WAITING
    assert core.receive(_incoming(1, m.Roster(7, (4,))), 0.8) == []  # no longer of this swarm


def test_a_member_dispersed_answers_in_its_slot_and_again_when_the_master_missed_it():
    core = _member(4, 1, (3, 4))
    actions = core.receive(_incoming(1, m.Disperse(7, 4), to=4), 1.0)
    assert actions[:3] == [
        SwarmChanged(None),
        StateChange(RobotState.SLAVE_DRIVING, RobotState.WAITING, {"session": 7, "reason": "dispersed"}),
        ConfigurePan(WAITING_PAN),
    ]
    assert actions[3:] == [Pause(pytest.approx(0.008)), Answer(1, m.Dispersed(7), WAITING_PAN)]  # member 2's slot
    core.pan_id = WAITING_PAN
    assert core.receive(_incoming(1, m.Disperse(7, 0), to=4), 1.2) == [Answer(1, m.Dispersed(7), WAITING_PAN)]
    assert core.receive(_incoming(1, m.Disperse(8, 0), to=4), 1.3) == []  # another swarm's


# -- the master's requests, carried out by hand ---------------------------------------------------------


def _robots(states: dict[int, RobotState], joins: dict[int, int], rssi: dict[int, float]) -> dict[str, Answering]:
    """Robots that answer the scan with their state, the query by Table 1 on the first attempt, and the
    notice on attempt ``joins[addr]`` (0: never)."""

    def scan(requests: list[Send], attempt: int) -> list[Incoming]:
        return [
            _incoming(a, m.ScanReply(s.message.session_id, int(st), WAITING_PAN, 0), at=0.005)
            for a, st in states.items()
            for s in requests
        ]

    def query(requests: list[Send], attempt: int) -> list[Incoming]:
        [request] = requests
        pending: tuple[int, ...] = request.message.pending  # type: ignore[attr-defined]
        answers = []
        for addr in pending:
            if rssi[addr] >= -70:
                answers.append(
                    _incoming(addr, m.JoinAvailable(request.message.session_id, round(rssi[addr])), rssi[addr])
                )
            else:
                answers.append(
                    _incoming(addr, m.JoinUnavailable(request.message.session_id, int(m.Refusal.OUTSIDE_REGION)))
                )
        return answers

    def notice(requests: list[Send], attempt: int) -> list[Incoming]:
        return [
            _incoming(r.dst, m.Joined(r.message.session_id, r.message.number), at=attempt)  # type: ignore[attr-defined]
            for r in requests
            if joins.get(r.dst) == attempt
        ]

    return {"scan": scan, "query": query, "notice": notice}


def test_organize_scans_asks_the_candidates_notifies_the_closest_and_asks_again_only_the_missing():
    core = _core(1, RobotState.FOLLOWING, user=9)
    robots = _robots(
        {2: RobotState.WAITING, 3: RobotState.WAITING, 4: RobotState.WAITING, 5: RobotState.SLAVE_DRIVING},
        joins={2: 1, 3: 3},
        rssi={2: -40.0, 3: -50.0, 4: -60.0},
    )
    figures, actions, attempts = carry_out(core.organize(2, "paper", 0.0), robots)
    # a slave of another swarm is no candidate; the query lists the three candidates
    assert figures["candidates"] == [2, 3, 4] and figures["available"] == [2, 3, 4]
    assert [r[0].message.pending for r in attempts["query"]] == [(2, 3, 4)]  # type: ignore[attr-defined]
    # Table 2: the two closest; robot 3's Joined comes on the third notice, which goes to it alone
    assert [[r.dst for r in attempt] for attempt in attempts["notice"]] == [[2, 3], [3], [3]]
    assert figures["members"] == [2, 3] and figures["missing"] == [] and figures["step_retries"]["notice"] == 2
    pan = figures["pan_id"]
    assert actions.index(ConfigurePan(pan)) < actions.index(
        Answer(4, m.NotParticipating(figures["session"]), BROADCAST)
    )
    assert core.sequence.state == RobotState.MASTER_DRIVING and core.swarm == Swarm(
        figures["session"], pan, 1, 0, (2, 3)
    )
    assert actions[-2:] == [SwarmChanged(core.swarm), StartRoster()]
    assert core.roster() == m.Roster(figures["session"], (2, 3))
    assert figures["organize_time_s"] == pytest.approx(3.0)  # the Joined that came last (received at 3.0)


def _scan_heard(heard: dict[int, dict[int, RobotState]]) -> Answering:
    """The scan's answers as the master hears them: on attempt ``k`` the replies of ``heard[k]`` (the rest were
    lost: a collision, or no MAC ACK to tell the robot so)."""

    def scan(requests: list[Send], attempt: int) -> list[Incoming]:
        [request] = requests
        session = request.message.session_id
        return [_incoming(a, m.ScanReply(session, int(st), WAITING_PAN, 0)) for a, st in heard.get(attempt, {}).items()]

    return scan


def test_organize_retries_the_scan_while_fewer_free_robots_answered_than_the_user_asked_for():
    # the paper: the middleware retries a step when not all the responses to its request have arrived; for
    # the scan that is fewer free robots than requested. Robots 3 and 4 were waiting all along, but their
    # first replies were lost; without the retry the swarm would end with robot 2 alone
    core = _core(1, RobotState.FOLLOWING, user=9)
    waiting = RobotState.WAITING
    robots = _robots({}, joins={2: 1, 3: 1, 4: 1}, rssi={2: -40.0, 3: -50.0, 4: -60.0})
    robots["scan"] = _scan_heard({1: {2: waiting}, 2: {2: waiting, 3: waiting}, 3: {4: waiting}})
    figures, _, attempts = carry_out(core.organize(3, "paper", 0.0), robots)
    assert len(attempts["scan"]) == 3 and figures["step_retries"]["scan"] == 2
    assert all(a[0].message == m.Scan(figures["session"], 9, 0) for a in attempts["scan"])  # to everyone again
    assert figures["candidates"] == [2, 3, 4] and figures["members"] == [2, 3, 4]


def test_a_scan_reply_of_a_robot_in_another_swarm_does_not_count_towards_the_requested_number():
    core = _core(1, RobotState.FOLLOWING, user=9)
    robots = _robots({}, joins={2: 1, 3: 1}, rssi={2: -40.0, 3: -50.0})
    others = {2: RobotState.WAITING, 5: RobotState.SLAVE_DRIVING, 6: RobotState.MASTER_DRIVING}
    robots["scan"] = _scan_heard({1: others, 2: others, 3: {**others, 3: RobotState.WAITING}})
    figures, _, attempts = carry_out(core.organize(2, "paper", 0.0), robots)
    assert len(attempts["scan"]) == 3  # three replies on the first attempt, but one free robot only
    assert figures["candidates"] == [2, 3] and figures["members"] == [2, 3]


def test_a_scan_reply_heard_outside_the_region_does_not_count_towards_the_requested_number():
    # robot 3 is heard below the region's -70 dBm: by Table 1 it will refuse, so the scan goes on for robot 4
    core = _core(1, RobotState.FOLLOWING, user=9)
    robots = _robots({}, joins={2: 1, 4: 1}, rssi={2: -40.0, 3: -85.0, 4: -50.0})
    waiting = RobotState.WAITING

    def scan(requests: list[Send], attempt: int) -> list[Incoming]:
        heard = {2: -40.0, 3: -85.0} if attempt == 1 else {2: -40.0, 3: -85.0, 4: -50.0}
        session = requests[0].message.session_id
        return [_incoming(a, m.ScanReply(session, int(waiting), WAITING_PAN, 0), rssi) for a, rssi in heard.items()]

    robots["scan"] = scan
    figures, _, attempts = carry_out(core.organize(2, "paper", 0.0), robots)
    assert len(attempts["scan"]) == 2 and figures["candidates"] == [2, 3, 4]
    assert figures["refused"] == {"outside_region": [3]} and figures["members"] == [2, 4]


def test_a_scan_reply_of_a_robot_driving_with_another_user_does_not_count_towards_the_requested_number():
    # robot 3 follows user 5: it is asked (and refuses, connected to a user), but the scan goes on for robot 4
    core = _core(1, RobotState.FOLLOWING, user=9)
    robots = _robots({}, joins={2: 1, 4: 1}, rssi={2: -40.0, 4: -50.0})
    waiting, following = int(RobotState.WAITING), int(RobotState.FOLLOWING)

    def scan(requests: list[Send], attempt: int) -> list[Incoming]:
        session = requests[0].message.session_id
        heard = [_incoming(2, m.ScanReply(session, waiting, WAITING_PAN, 0), -40.0)]
        heard.append(_incoming(3, m.ScanReply(session, following, WAITING_PAN, 5), -45.0))
        if attempt > 1:
            heard.append(_incoming(4, m.ScanReply(session, waiting, WAITING_PAN, 0), -50.0))
        return heard

    def query(requests: list[Send], attempt: int) -> list[Incoming]:
        session = requests[0].message.session_id
        pending: tuple[int, ...] = requests[0].message.pending  # type: ignore[attr-defined]
        rssi = {2: -40.0, 4: -50.0}
        return [
            _incoming(a, m.JoinUnavailable(session, int(m.Refusal.CONNECTED_TO_USER)))
            if a == 3
            else _incoming(a, m.JoinAvailable(session, round(rssi[a])), rssi[a])
            for a in pending
        ]

    figures, _, attempts = carry_out(core.organize(2, "paper", 0.0), {**robots, "scan": scan, "query": query})
    assert len(attempts["scan"]) == 2 and figures["candidates"] == [2, 3, 4]
    assert figures["refused"] == {"connected_to_user": [3]} and figures["members"] == [2, 4]


def test_a_scan_with_enough_free_replies_in_its_first_window_is_not_retried():
    core = _core(1, RobotState.FOLLOWING, user=9)
    robots = _robots({2: RobotState.WAITING, 3: RobotState.WAITING}, joins={2: 1, 3: 1}, rssi={2: -40.0, 3: -50.0})
    figures, _, attempts = carry_out(core.organize(2, "paper", 0.0), robots)
    assert len(attempts["scan"]) == 1 and figures["retries"] == 0 and figures["members"] == [2, 3]


def test_organize_releases_a_chosen_robot_that_never_joined_after_the_last_retry():
    core = _core(1, RobotState.LEADING, user=9)
    robots = _robots({2: RobotState.WAITING, 3: RobotState.WAITING}, joins={2: 1}, rssi={2: -40.0, 3: -45.0})
    figures, actions, attempts = carry_out(core.organize(3, "paper", 0.0), robots)
    # two robots wait where three were asked for: the scan is retried to its limit, then goes on with them
    assert len(attempts["scan"]) == 1 + CONFIG.step.max_retries
    assert len(attempts["notice"]) == 1 + CONFIG.step.max_retries
    assert all([r.dst for r in a] == [3] for a in attempts["notice"][1:])
    assert figures["members"] == [2] and figures["missing"] == [3]
    notice = actions.index(_of(actions, Exchange)[-1])
    assert actions[notice + 1] == Answer(3, m.NotParticipating(figures["session"]), BROADCAST)


def test_organize_with_nobody_around_waits_out_every_scan_deadline_and_goes_back_to_driving():
    core = _core(1, RobotState.LEADING, user=9)
    figures, actions, attempts = carry_out(
        core.organize(3, "paper", 0.0), {"scan": _nobody, "query": _nobody, "notice": _nobody}
    )
    assert len(attempts["scan"]) == 1 + CONFIG.step.max_retries  # nobody answered, so never enough
    assert figures["members"] == [] and figures["organize_time_s"] == pytest.approx(DEADLINE * len(attempts["scan"]))
    assert actions[-3] == ConfigurePan(WAITING_PAN)
    assert _of(actions, StateChange)[-1] == StateChange(
        RobotState.ORGANIZING, RobotState.LEADING, {"session": figures["session"], "reason": "no robot joined"}
    )
    assert core.sequence.state == RobotState.LEADING and core.swarm is None


def test_organize_refused_in_the_wrong_state_and_abandoned_when_the_radio_fails():
    with pytest.raises(FormationError):
        next(_core(1).organize(2, "paper", 0.0))  # waiting: no user to organize for
    with pytest.raises(FormationError, match="lost its user"):
        next(_core(1, RobotState.EMERGENCY, user=9).organize(2, "paper", 0.0))  # no fix of him: would lead blind
    core = _core(1, RobotState.FOLLOWING, user=9)
    procedure = core.organize(2, "paper", 0.0)
    next(procedure)  # the transition to organizing
    assert isinstance(procedure.send(Done(0.0)), Exchange)  # the scan
    abandon = [procedure.throw(ConnectionError("hub gone"))]
    with pytest.raises(ConnectionError):
        while True:
            abandon.append(procedure.send(Done(0.1)))
    assert abandon == [
        Log("organize_failed", {"session": abandon[0].detail["session"]}),  # type: ignore[union-attr]
        StateChange(
            RobotState.ORGANIZING,
            RobotState.FOLLOWING,
            {"session": abandon[0].detail["session"], "reason": "organizing failed"},
        ),  # type: ignore[union-attr]
        ConfigurePan(WAITING_PAN, where="abandon"),
    ]


def test_disperse_asks_the_members_again_until_they_answer_and_always_ends_the_swarm():
    core = _master(1, (2, 3))

    def members(requests: list[Send], attempt: int) -> list[Incoming]:
        return [_incoming(r.dst, m.Dispersed(7)) for r in requests if r.dst == 2 or attempt == 2]

    figures, actions, attempts = carry_out(core.disperse(None, 10.0), {"disperse": members}, now=10.0)
    assert [[r.dst for r in a] for a in attempts["disperse"]] == [[2, 3], [3]]
    assert figures["retries"] == 1 and figures["unconfirmed"] == [] and figures["restored"] == "following"
    assert figures["disperse_time_s"] == pytest.approx(DEADLINE + 0.005)
    assert actions[1:5] == [
        SwarmChanged(None),
        StopRoster(),
        StateChange(RobotState.MASTER_DRIVING, RobotState.FOLLOWING, {"session": 7}),
        ConfigurePan(WAITING_PAN),
    ]
    assert core.swarm is None and core.roster() is None
    with pytest.raises(FormationError):
        next(core.disperse(None, 11.0))  # no swarm to disperse any more


def test_a_handover_accepted_makes_the_old_master_a_slave_of_the_new_one():
    core = _master(1, (2, 3))
    chain = (3, 1, 2)

    def accepts(requests: list[Send], attempt: int) -> list[Incoming]:
        return [_incoming(3, m.HandoverAccepted(7))] if attempt == 2 else []

    procedure = core.hand_over(chain, "leading", "column", 0.6, 0, 0, "user-9", 5.0)
    done, actions, attempts = carry_out(procedure, {"handover": accepts}, now=5.0)
    assert done is True and len(attempts["handover"]) == 2
    handover = attempts["handover"][0][0].message
    assert isinstance(handover, m.MasterHandover) and handover.chain == chain
    assert actions[1:4] == [StopRoster(), Send(BROADCAST, handover, ack=False, where="handover_broadcast"), actions[3]]
    assert core.swarm == Swarm(7, SWARM_PAN, 3, 1, (1, 2)) and core.sequence.state == RobotState.SLAVE_DRIVING
    assert _of(actions, HandedOver) == [HandedOver((1, 2, 3), handover)]
    with pytest.raises(FormationError):
        next(_master(1, (2, 3)).hand_over((1, 3, 2), "leading", "column", 0.6, 0, 0, "u", 0.0))  # not a new master


def test_a_handover_never_accepted_leaves_the_master_in_place():
    core = _master(1, (2, 3))
    done, actions, _ = carry_out(
        core.hand_over((2, 1, 3), "following", "column", 0.6, 0, 0, "u", 0.0), {"handover": _nobody}
    )
    assert done is False and _records(actions, "handover_failed")[0]["retries"] == CONFIG.step.max_retries
    assert core.sequence.state == RobotState.MASTER_DRIVING and core.swarm is not None and core.swarm.number == 0


def test_the_new_master_takes_the_role_accepts_and_announces_its_roster():
    core = _member(3, 1, (3, 4))
    msg = m.MasterHandover(7, SWARM_PAN, (3, 1, 4), "leading", "column", 0.6, 0, 0, "u")
    actions = core.receive(_incoming(1, msg, to=3), 3.0)
    assert actions[0] == StateChange(
        RobotState.SLAVE_DRIVING, RobotState.MASTER_DRIVING, {"cause": "handover", "old_master": 1, "members": [1, 4]}
    )
    assert actions[-2:] == [StartRoster(), Send(1, m.HandoverAccepted(7), dst_pan=SWARM_PAN)]
    assert core.sequence.previous_driving == RobotState.LEADING and core.roster() == m.Roster(7, (1, 4))
    # the old master's late roster does not take the role back
    assert core.receive(_incoming(1, m.Roster(7, (3, 4))), 3.1) == []


# -- rival masters and members lost ----------------------------------------------------------------------


def test_of_two_masters_the_higher_address_yields_and_the_lower_keeps_recording_it_once():
    high, low = _master(5, (2, 3)), _master(2, (5, 3))
    kept = low.receive(_incoming(5, m.Roster(7, (2, 3))), 1.0)
    assert _records(kept, "two_masters") == [{"session": 7, "rival": 5, "verdict": "keep", "since_handover_s": None}]
    assert low.receive(_incoming(5, m.Roster(7, (2, 3))), 1.25) == []  # already recorded
    yielded = high.receive(_incoming(2, m.Roster(7, (5, 3))), 1.0)
    assert _records(yielded, "two_masters")[0]["verdict"] == "yield"
    assert StopRoster() in yielded and high.sequence.state == RobotState.SLAVE_DRIVING
    assert high.swarm == Swarm(7, SWARM_PAN, 2, 1, (5, 3)) and high.get_timer() == pytest.approx(
        1.0 + CONFIG.master_silence_s
    )


def test_an_outranked_master_the_rival_does_not_count_dissolves_its_swarm_once():
    core = _master(5, (2, 3))
    swarm = core.swarm
    actions = core.receive(_incoming(2, m.Roster(7, (3,))), 1.0)
    assert actions[-2:] == [StopRoster(), Dissolve(swarm, "a rival master")]  # type: ignore[arg-type]
    assert core.receive(_incoming(2, m.Roster(7, (3,))), 1.25) == []  # already giving the role up
    dissolved = core.dissolve(swarm, "a rival master", 1.3)  # type: ignore[arg-type]
    assert dissolved == [
        SwarmChanged(None),
        StopRoster(),
        StateChange(RobotState.MASTER_DRIVING, RobotState.FOLLOWING, {"session": 7, "reason": "a rival master"}),
        ConfigurePan(WAITING_PAN, where="dissolve"),
    ]
    assert core.dissolve(swarm, "again", 1.4) == []  # type: ignore[arg-type]


def test_a_member_silent_for_member_misses_rounds_is_dropped_and_the_last_one_ends_the_swarm():
    core = _master(1, (2, 3))
    for _ in range(MEMBER_MISSES - 1):
        assert core.note_answers({2}, {3}) == []
    core.note_answers({3}, set())  # it answered once: its count starts again
    for _ in range(MEMBER_MISSES - 1):
        assert core.note_answers({2}, {3}) == []
    assert core.note_answers({2}, {3}) == [
        Log("member_lost", {"session": 7, "member": 3}),
        SwarmChanged(Swarm(7, SWARM_PAN, 1, 0, (2,))),
    ]
    left = core.receive(_incoming(2, m.Dispersed(7)), 2.0)  # the last member gave up on us
    assert left == [Log("member_left", {"session": 7, "member": 2}), Dissolve(core.swarm, "every member is gone")]  # type: ignore[arg-type]


def test_the_core_imports_no_clock_no_loop_and_no_zenoh():
    import ast
    import inspect

    import petswarm.managers.formation_core as core_module

    imported = set()
    for node in ast.walk(ast.parse(inspect.getsource(core_module))):
        if isinstance(node, ast.Import):
            imported |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            imported |= {f"{node.module}.{alias.name}" for alias in node.names} | {node.module or ""}
    assert not {name for name in imported if name.split(".")[0] in ("asyncio", "time", "zenoh")}
    assert "petswarm.clock" not in imported
