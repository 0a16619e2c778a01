"""The member side of network formation driven without processes: a fake RF object stands for the radio."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from petswarm import clock
from petswarm.clock import ModelClockLoop
from petswarm.managers import messages as m
from petswarm.managers.actions import Incoming
from petswarm.managers.event_log import EventLog
from petswarm.managers.formation import ANSWER_ATTEMPTS, FormationConfig, NetworkFormation
from petswarm.managers.sequence import RobotState, SequenceManager
from radio_hub.air.mac import BROADCAST, Frame, FrameType
from radio_hub.values import RxFrame, TxResult, TxStatus

WAITING_PAN = 0x1000
ME, MASTER, USER = 3, 9, 7


@dataclass
class _Identity:
    short_addr: int = ME
    pan_id: int = WAITING_PAN


@dataclass
class _Radio:
    identity: _Identity = field(default_factory=_Identity)
    hub_present: bool = True


@dataclass
class FakeRf:
    """Records every send and answers each with the next status of ``statuses`` (success once they run out)."""

    statuses: list[TxStatus] = field(default_factory=list)
    radio: _Radio = field(default_factory=_Radio)
    sent: list[tuple[int, m.SwarmMessage]] = field(default_factory=list)

    async def send(
        self, dst: int, message: m.SwarmMessage, *, dst_pan: int | None = None, ack: bool = True
    ) -> TxResult:
        """Record the message; report the next scripted MAC status."""
        self.sent.append((dst, message))
        return TxResult(self.statuses.pop(0) if self.statuses else TxStatus.SUCCESS)


class CountingRng:
    """Stands for the formation's generator where only ``uniform`` is drawn: the pause before a retried answer."""

    def __init__(self) -> None:
        self.pauses = 0

    def uniform(self, low: float, high: float) -> float:
        """Count the pause; make it none, so the test does not wait."""
        self.pauses += 1
        return 0.0


def _formation(rf: FakeRf, sequence: SequenceManager, log: EventLog, rng: Any = None) -> NetworkFormation:
    rng = rng if rng is not None else np.random.default_rng(0)
    return NetworkFormation(rf, sequence, None, log, FormationConfig(), rng, user=USER)  # type: ignore[arg-type]


def _incoming(message: m.SwarmMessage, rssi_dbm: float = -50.0) -> Incoming:
    frame = Frame(FrameType.DATA, 1, BROADCAST, BROADCAST, WAITING_PAN, MASTER, message.encode(), False)
    return Incoming(message, RxFrame(frame, rssi_dbm, 200, 0, 1000, 0), clock.now())


async def test_a_former_master_that_became_a_candidate_names_no_user_in_its_scan_reply():
    log = EventLog()
    sequence = SequenceManager(log, RobotState.FOLLOWING)
    # it organized a swarm for its user, handed the master's role over, and the new master dispersed it
    for state in (RobotState.ORGANIZING, RobotState.MASTER_DRIVING, RobotState.SLAVE_DRIVING, RobotState.WAITING):
        sequence.transition(state)
    rf = FakeRf()
    formation = _formation(rf, sequence, log)
    await formation.on_message(_incoming(m.JoinQuery(5, 0, -70, 0, ())))  # another master's query: available
    assert sequence.state == RobotState.ORGANIZING and isinstance(rf.sent[-1][1], m.JoinAvailable)
    await formation.on_message(_incoming(m.Scan(6, 0, 0)))
    dst, reply = rf.sent[-1]
    assert dst == MASTER and reply == m.ScanReply(6, int(RobotState.ORGANIZING), WAITING_PAN, 0)


async def test_an_answer_the_mac_never_gets_out_is_retried_only_between_attempts():
    log = EventLog()
    rf = FakeRf(statuses=[TxStatus.CHANNEL_ACCESS_FAILURE] * (ANSWER_ATTEMPTS + 1))
    rng = CountingRng()
    formation = _formation(rf, SequenceManager(log), log, rng)
    await formation.on_message(_incoming(m.Scan(6, 0, 0)))
    assert len(rf.sent) == ANSWER_ATTEMPTS
    retries = [e for e in log.events if e["kind"] == "answer_retry"]
    assert [e["attempt"] for e in retries] == list(range(ANSWER_ATTEMPTS - 1))
    assert rng.pauses == ANSWER_ATTEMPTS - 1  # no pause after the last attempt: nothing follows it
    [failed] = [e for e in log.events if e["kind"] == "answer_failed"]
    assert failed["type"] == "ScanReply" and failed["status"] == "channel_access_failure"
    assert failed["attempts"] == ANSWER_ATTEMPTS


async def test_an_answer_that_gets_out_on_a_retry_is_not_reported_failed():
    log = EventLog()
    rf = FakeRf(statuses=[TxStatus.NO_ACK])
    rng = CountingRng()
    formation = _formation(rf, SequenceManager(log), log, rng)
    await formation.on_message(_incoming(m.Scan(6, 0, 0)))
    assert len(rf.sent) == 2 and rng.pauses == 1
    assert [e["kind"] for e in log.events] == ["answer_retry"]


def test_a_resting_watch_stops_ticking_when_idle_and_gives_up_on_the_tick_an_always_ticking_one_does() -> None:
    async def scenario(rests: bool) -> tuple[list[float], list[tuple[float, RobotState]]]:
        log = EventLog()
        sequence = SequenceManager(log, RobotState.WAITING)
        formation = _formation(FakeRf(), sequence, log)
        formation.rests = rests
        ticks: list[float] = []
        states: list[tuple[float, RobotState]] = []
        tick = formation._tick

        async def counted() -> None:
            ticks.append(clock.now())
            await tick()
            states.append((clock.now(), sequence.state))

        formation._tick = counted  # type: ignore[method-assign]
        watch = asyncio.create_task(formation.watch())
        await clock.sleep_until(0.37)  # between two ticks: a master's query makes it a candidate
        await formation.on_message(_incoming(m.JoinQuery(5, 0, -70, 0, ())))
        assert sequence.state == RobotState.ORGANIZING
        await clock.sleep_until(8.0)
        watch.cancel()
        return ticks, states

    def run(rests: bool) -> tuple[list[float], list[tuple[float, RobotState]]]:
        loop = ModelClockLoop()
        try:
            return loop.run_until_complete(scenario(rests))
        finally:
            loop.close()

    ticking, ticking_states = run(False)
    resting, resting_states = run(True)
    gave_up = next(t for t, state in ticking_states if t > 0.37 and state == RobotState.WAITING)
    assert 0.37 + FormationConfig().candidate_timeout_s < gave_up < 8.0
    # the resting watch ticks only while there is a timer, on the instants the ticking one does
    assert resting and set(resting) <= set(ticking) and len(resting) < len(ticking) / 2
    assert resting[0] == min(t for t in ticking if t > 0.37) and resting[-1] == gave_up
    assert next(t for t, state in resting_states if t > 0.37 and state == RobotState.WAITING) == gave_up
