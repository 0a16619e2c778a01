"""The IR token schedule's sans-IO core (petswarm/managers/token_schedule.py) stepped by hand: no event loop, explicit
``now``. First single robots event by event (answer slots, the holder's round, a lost Sync, being overtaken,
the measurement window, leaving), then a few cores on a small instant air (``Air``) for the token's order
along the chain, a holder's death, a lost token and a member leaving.
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from petswarm.managers import messages as m
from petswarm.managers import token_schedule as ts
from petswarm.managers.actions import Incoming
from petswarm.managers.token_schedule import ANSWER_SLOT_MS, WATCH_PERIOD_S, TokenConfig, TokenSchedule
from radio_hub.air.mac import Frame, FrameType
from radio_hub.physics.light import IrConfig, receiver_readings
from radio_hub.values import BROADCAST, RxFrame

SESSION = 9
CONFIG = TokenConfig()
CLEAN = IrConfig().noise_free()
STEP_S = CONFIG.step.deadline_s


def _incoming(src: int, message: m.SwarmMessage) -> Incoming:
    frame = Frame(FrameType.DATA, 0, 0x1000, 1, 0x1000, src, message.encode())
    return Incoming(message, RxFrame(frame, -50.0, 200, 0, 0, 0), received_at=0.0)


def _of(kind: type, actions: list[ts.Action]) -> list[Any]:
    return [a for a in actions if isinstance(a, kind)]


def _logs(actions: list[ts.Action], kind: str) -> list[dict[str, Any]]:
    return [a.detail for a in actions if isinstance(a, ts.Log) and a.kind == kind]


def _member(me: int, chain: tuple[int, ...] = (1, 2, 3), neighbours: tuple[int, ...] = (1,)) -> TokenSchedule:
    core = TokenSchedule(me, CONFIG, 0.0, CLEAN)  # not started: no watch ticks among its timers
    core.join(SESSION, chain, neighbours, False, 0.0)
    return core


def _readings(tx: tuple[float, float], rx: tuple[float, float, float]) -> np.ndarray:
    """A noise-free sweep at ``rx`` (x, y, heading in rad) of a module shining at ``tx``."""
    return receiver_readings(np.array([[*tx, 0.0]]), np.array([rx]), CLEAN, np.random.default_rng(0))[0]


# -- one robot, event by event ---------------------------------------------------------------------


def test_a_member_answers_the_start_sign_in_its_slot_once_receiving_then_sends_its_heading() -> None:
    core = _member(3)
    actions = core.receive(1, m.IrStart(SESSION, 1), 10.0)
    assert _of(ts.OpenWindow, actions) == [ts.OpenWindow(1)]
    [switch] = _of(ts.SetIrMode, actions)
    assert switch.mode == "receive" and core.next_timer() is None  # no answer before the module receives
    assert core.mode_set(switch.ref, 10.002) == []
    # others of holder 1 are (2, 3): robot 3 is second, so it answers one slot after the module is receiving
    assert core.next_timer() == 10.002 + ANSWER_SLOT_MS / 1000
    assert core.handle_timer(10.004) == []  # nothing is due before its slot
    [ack] = core.handle_timer(10.005)
    assert isinstance(ack, ts.Send) and ack.dst == 1 and ack.message == m.IrStartAck(SESSION, 1) and ack.ack
    assert core.sent(ack.ref, 10.006) == [ts.SendHeading(1, SESSION)]  # holder 1 is a neighbour


def test_a_repeated_start_sign_is_answered_again_without_a_new_window_and_non_neighbours_keep_their_heading() -> None:
    core = _member(2, neighbours=(3,))
    [_, switch] = core.receive(1, m.IrStart(SESSION, 1), 10.0)
    core.mode_set(switch.ref, 10.001)
    assert core.next_timer() == 10.001  # robot 2 is first in the holder's others: slot 0
    [ack] = core.handle_timer(10.001)
    assert core.sent(ack.ref, 10.002) == []  # the holder is no neighbour of robot 2: no heading
    again = core.receive(1, m.IrStart(SESSION, 1), 10.06)  # the holder's retry: our answer was lost
    assert again == [] and core.next_timer() == 10.06
    assert [a.message for a in core.handle_timer(10.06)] == [m.IrStartAck(SESSION, 1)]


def test_start_signs_of_another_session_or_an_older_round_are_ignored() -> None:
    core = _member(2)
    core.receive(1, m.Sync(SESSION, 5, 3), 1.0)
    assert core.round == 5
    assert core.receive(3, m.IrStart(SESSION, 4), 1.1) == []
    assert core.receive(3, m.IrStart(SESSION + 1, 6), 1.2) == []
    assert core.last_activity == 1.1  # heard, though: the schedule is alive


def test_the_token_closes_the_window_into_a_fix_and_is_answered_in_the_slot() -> None:
    core = _member(3)
    [_, switch] = core.receive(1, m.IrStart(SESSION, 1), 10.0)
    core.mode_set(switch.ref, 10.0)
    core.handle_timer(10.003)
    actions = core.receive(1, m.Token(SESSION, 1, 2), 10.2)
    assert _of(ts.CloseWindow, actions) == [ts.CloseWindow(1)]
    # holder 1 at (0.3, 1.1) seen from robot 3 at (0, 0) heading 30 degrees: bearing 74.74 - 30 degrees
    readings = _readings((0.3, 1.1), (0.0, 0.0, math.radians(30)))
    fix_actions = core.measured(1, readings, 10, 10.2)
    [fix] = _of(ts.RecordFix, fix_actions)
    assert fix.addr == 1 and fix.at == 10.2
    assert math.degrees(fix.fix.bearing_rad) == pytest.approx(math.degrees(math.atan2(1.1, 0.3)) - 30, abs=1e-6)
    assert fix.fix.distance_m == pytest.approx(math.hypot(0.3, 1.1), rel=1e-9)
    assert _logs(fix_actions, "ir_fix")[0]["sweeps"] == 10 and core.fixes == 1
    assert core.next_timer() == pytest.approx(10.2 + 0.003)
    [ack] = core.handle_timer(10.203)
    assert ack.message == m.TokenAck(SESSION, 1) and ack.dst == 1


def test_an_empty_window_gives_no_fix() -> None:
    core = _member(3)
    assert _logs(core.measured(1, None, 0, 1.0), "ir_no_fix") == [{"holder": 1, "sweeps": 0}]
    assert core.fixes == 0


def test_the_holders_round_start_sign_shine_token_sync_with_its_timing() -> None:
    master = TokenSchedule(1, CONFIG, 0.0, CLEAN)
    [log, start] = master.join(SESSION, (1, 2, 3), (2,), True, 1.0)
    assert log.kind == "ir_schedule" and start.message == m.IrStart(SESSION, 1) and start.dst == BROADCAST
    assert master.holding == 1 and not start.ack
    master.sent(start.ref, 1.004)
    assert master.next_timer() == 1.004 + STEP_S  # the answer deadline starts once the sign is on the air
    assert master.offer(_incoming(2, m.IrStartAck(SESSION, 1)), 1.01) == []
    assert master.offer(_incoming(4, m.TokenAck(SESSION, 1)), 1.01) is None  # no token step runs
    [answers, on] = master.offer(_incoming(3, m.IrStartAck(SESSION, 1)), 1.02)
    assert answers == ts.Answers({2, 3}, set()) and on.mode == "transmit"
    assert master.next_timer() is None  # no watch started: only the round's own timers
    master.mode_set(on.ref, 1.021)
    assert master.next_timer() == 1.021 + CONFIG.slot_s  # it shines for slot_s once the module transmits
    [off] = master.handle_timer(1.021 + CONFIG.slot_s)
    assert off.mode == "idle" and master.rounds_held == 0
    [token] = master.mode_set(off.ref, 1.13)
    assert token.message == m.Token(SESSION, 1, 2) and master.rounds_held == 1  # the next in chain order
    master.sent(token.ref, 1.131)
    master.offer(_incoming(3, m.TokenAck(SESSION, 1)), 1.14)
    [sync] = master.offer(_incoming(2, m.TokenAck(SESSION, 1)), 1.15)
    assert sync.message == m.Sync(SESSION, 2, 2)
    assert master.sent(sync.ref, 1.152) == [] and master.holding is None and master.last_activity == 1.152


def test_the_holder_retries_the_missing_and_passes_the_token_past_a_silent_member() -> None:
    master = TokenSchedule(1, CONFIG, 0.0, CLEAN)
    [_, start] = master.join(SESSION, (1, 2, 3), (), True, 0.0)
    master.sent(start.ref, 0.0)
    master.offer(_incoming(3, m.IrStartAck(SESSION, 1)), 0.01)
    now, retries = STEP_S, []
    while True:
        actions = master.handle_timer(now)
        retries += _logs(actions, "retry")
        sends = _of(ts.Send, actions)
        if not sends:
            break
        master.sent(sends[0].ref, now)  # robot 2 never answers
        now = master.next_timer()
    assert [r["missing"] for r in retries] == [[2]] * CONFIG.step.max_retries and master.retries == 3
    assert _of(ts.Answers, actions) == [ts.Answers({3}, {2})]
    [on] = _of(ts.SetIrMode, actions)
    master.mode_set(on.ref, now)
    [off] = master.handle_timer(now + CONFIG.slot_s)
    [token] = master.mode_set(off.ref, now + CONFIG.slot_s)
    assert token.message == m.Token(SESSION, 1, 3)  # robot 2 did not answer: the token skips it


def test_a_holder_nobody_hears_never_shines() -> None:
    master = TokenSchedule(1, TokenConfig(step=ts.StepTiming(0.05, 0)), 0.0, CLEAN)
    [_, start] = master.join(SESSION, (1, 2), (), True, 0.0)
    master.sent(start.ref, 0.0)
    actions = master.handle_timer(0.05)
    assert _logs(actions, "ir_unheard") == [{"round": 1}] and not _of(ts.SetIrMode, actions)
    assert master.holding is None and master.last_activity == 0.05


def test_a_member_holder_its_master_does_not_hear_never_shines() -> None:
    """Seed 3 case 27 of drive,mixed,follow: robots 2 and 4 cut off from their master by a partition passed the token
    between themselves while the master, hearing nothing for regen_timeout_s, regenerated its own: for 23 ms two
    modules shone at once. A member holder shines only when its master answered its start sign."""

    def hold(answering: tuple[int, ...]) -> list[ts.Action]:
        member = _member(2, chain=(1, 2, 4))
        [start] = _of(ts.Send, member.receive(1, m.Sync(SESSION, 2, 2), 1.0))
        member.sent(start.ref, 1.0)
        actions: list[ts.Action] = []
        for k, sender in enumerate(answering):
            actions += member.offer(_incoming(sender, m.IrStartAck(SESSION, 2)), 1.01 + 0.001 * k) or []
        now = 1.0 + STEP_S
        while not _of(ts.Answers, actions):
            actions = member.handle_timer(now)
            for send in _of(ts.Send, actions):
                member.sent(send.ref, now)
            now = member.next_timer() or now + STEP_S
        return actions

    cut_off = hold((4,))  # robot 4 answers, the master never does
    assert _logs(cut_off, "ir_master_unheard") == [{"round": 2, "master": 1}] and not _of(ts.SetIrMode, cut_off)
    heard = hold((1, 4))
    assert [a.mode for a in _of(ts.SetIrMode, heard)] == ["transmit"]


def test_the_robot_named_next_starts_anyway_when_the_sync_is_lost() -> None:
    core = _member(2)
    core.receive(1, m.Token(SESSION, 1, 2), 5.0)  # no window open: no fix, just the answer and the fallback
    [ack] = core.handle_timer(5.0)
    assert ack.message == m.TokenAck(SESSION, 1)
    due = 5.0 + CONFIG.sync_fallback_s  # the holder's token step with every retry, and a deadline more
    assert core.next_timer() == due and core.handle_timer(due - 1e-9) == []
    actions = core.handle_timer(due)
    assert _logs(actions, "sync_missed") == [{"round": 2}]
    assert [a.message for a in _of(ts.Send, actions)] == [m.IrStart(SESSION, 2)] and core.holding == 2


def test_the_sync_fallback_is_void_once_the_sync_came() -> None:
    core = _member(2)
    core.receive(1, m.Token(SESSION, 1, 2), 5.0)
    [start] = core.receive(1, m.Sync(SESSION, 2, 2), 5.1)
    assert start.message == m.IrStart(SESSION, 2)
    core.handle_timer(5.0)
    assert core.handle_timer(5.0 + CONFIG.sync_fallback_s) == [] and core.holding == 2


def _shining(core: TokenSchedule, chain: tuple[int, ...], now: float) -> None:
    """Bring ``core``, master of ``chain``, to shining in round 1 at ``now``."""
    [_, start] = core.join(SESSION, chain, (), True, now)
    core.sent(start.ref, now)
    for addr in chain[1:]:
        actions = core.offer(_incoming(addr, m.IrStartAck(SESSION, 1)), now)
    [on] = _of(ts.SetIrMode, actions or [])
    core.mode_set(on.ref, now)


def test_a_shining_holder_that_hears_a_higher_round_switches_off_then_receives() -> None:
    core = TokenSchedule(2, CONFIG, 0.0, CLEAN)
    _shining(core, (2, 1, 3), 1.0)
    assert core.receive(1, m.IrStart(SESSION, 1), 1.05) == []  # the same round from a lower address: ours
    actions = core.receive(3, m.IrStart(SESSION, 4), 1.05)
    modes = [a.mode for a in _of(ts.SetIrMode, actions)]
    assert modes == ["idle", "receive"] and _logs(actions, "ir_overtaken") == [{"round": 4, "by": 3}]
    assert core.holding is None and core.round == 4
    assert core.handle_timer(1.0 + CONFIG.slot_s) == []  # the shine's end went with the round


def test_leaving_drops_the_round_switches_off_and_forgets() -> None:
    core = TokenSchedule(1, CONFIG, 0.0, CLEAN)
    core.start(0.0)
    _shining(core, (1, 2, 3), 1.0)
    actions = core.leave(1.05)
    assert actions == [ts.SetIrMode("idle"), ts.DropWindow(), ts.ForgetTable(), ts.SetIrMode("idle")]
    assert not core.active and core.holding is None
    assert core.receive(2, m.IrStart(SESSION, 2), 1.1) == []  # no longer ours
    now: float | None = 1.05
    while now is not None and now < 5.0:  # and a former master regenerates nothing (its watch stops too)
        now = core.next_timer()
        if now is not None:
            assert core.handle_timer(now) == []
    assert core.next_timer() is None


def test_the_master_regenerates_after_regen_timeout_of_silence_seen_at_its_watch() -> None:
    master = TokenSchedule(1, CONFIG, 0.0, CLEAN)
    master.start(0.0)  # watch ticks at 0.05, 0.10, ...
    master.join(SESSION, (1, 2), (), False, 0.0)
    master.rejoin((1, 2), (), True, 0.0)  # master by a handover: it holds nothing yet
    member = _member(2, chain=(1, 2))
    member.start(0.0)
    master.receive(2, m.Sync(SESSION, 7, 2), 2.0123)  # the last word heard: then the holder goes silent
    assert master.holding is None
    now, actions = 2.0123, []
    while not _logs(actions, "token_regenerated"):
        now = master.next_timer()
        actions = master.handle_timer(now)
    assert CONFIG.regen_timeout_s < now - 2.0123 <= CONFIG.regen_timeout_s + WATCH_PERIOD_S
    assert _logs(actions, "token_regenerated") == [{"round": 8}] and master.regenerations == 1
    assert [a.message for a in _of(ts.Send, actions)] == [m.IrStart(SESSION, 8)]
    # a member never regenerates, however long the silence
    t = 0.0
    while t < 10.0:
        t = member.next_timer()
        assert not _logs(member.handle_timer(t), "token_regenerated")


def test_with_the_hub_away_silence_is_no_lost_token() -> None:
    master = TokenSchedule(1, CONFIG, 0.0, CLEAN)
    master.start(0.0)
    master.join(SESSION, (1, 2), (), False, 0.0)
    master.rejoin((1, 2), (), True, 0.0)  # a handover made it master: it now watches for a lost token
    master.air = False
    now = 0.0
    while now < 5.0:
        now = master.next_timer()
        assert master.handle_timer(now) == []
    master.air = True
    start, actions = now, []
    while not actions:
        now = master.next_timer()
        actions = master.handle_timer(now)
    assert CONFIG.regen_timeout_s < now - start <= CONFIG.regen_timeout_s + WATCH_PERIOD_S + 1e-9


def test_out_of_a_swarm_the_watch_stops_waking_and_joining_takes_it_up_on_its_grid() -> None:
    # a robot that is in no swarm (a surround robot) checks once, then has no timer at all; a later join
    # wakes the check again at the next instant of the grid the watch ticked on (0.05, 0.10, ... as
    # accumulated), and a master's lost token is still regenerated within a period of the timeout
    core = TokenSchedule(1, CONFIG, 0.0, CLEAN)
    core.start(0.0)
    assert core.next_timer() == WATCH_PERIOD_S
    assert core.handle_timer(WATCH_PERIOD_S) == [] and core.next_timer() is None
    grid = [WATCH_PERIOD_S]
    while grid[-1] <= 3.01:
        grid.append(grid[-1] + WATCH_PERIOD_S)
    core.join(SESSION, (1, 2), (), True, 3.01)
    assert min(t for t in core.timers().values()) <= grid[-1]  # the master's own round comes first
    assert grid[-1] in core.timers().values()
    core.leave(3.02)
    core.join(SESSION + 1, (1, 2), (), True, 3.03)  # back before the pending check: still one check
    assert list(core.timers().values()).count(grid[-1]) == 1
    # joined as a member and silent from then on: a member checks but never regenerates
    member = TokenSchedule(2, CONFIG, 0.0, CLEAN)
    member.start(0.0)
    member.handle_timer(WATCH_PERIOD_S)
    member.join(SESSION, (1, 2), (), False, 1.0)
    t = 1.0
    while t < 4.0:
        t = member.next_timer()
        assert not _logs(member.handle_timer(t), "token_regenerated")
    master = TokenSchedule(1, CONFIG, 0.0, CLEAN)
    master.start(0.0)
    master.handle_timer(WATCH_PERIOD_S)
    master.join(SESSION, (1, 2), (), False, 0.5)
    master.rejoin((1, 2), (), True, 0.5)
    master.receive(2, m.Sync(SESSION, 7, 2), 2.0123)
    now, actions = 2.0123, []
    while not _logs(actions, "token_regenerated"):
        now = master.next_timer()
        actions = master.handle_timer(now)
    assert CONFIG.regen_timeout_s < now - 2.0123 <= CONFIG.regen_timeout_s + WATCH_PERIOD_S


# -- a few robots on an instant air --------------------------------------------------------------------

AIR_S = 0.002
"""How long a message takes on this air, and a mode switch to be confirmed."""


class Air:
    """A few cores on an ideal air: every message reaches every live robot ``AIR_S`` after it was sent
    (unless ``drop`` says so), mode switches take ``AIR_S``, and each window reads noise-free light of the
    module shining now, from fixed poses."""

    def __init__(self, poses: dict[int, tuple[float, float, float]], config: TokenConfig = CONFIG) -> None:
        self.poses = poses
        self.cores = {addr: TokenSchedule(addr, config, 0.0, CLEAN) for addr in poses}
        self.now = 0.0
        self.modes = dict.fromkeys(poses, "idle")
        self.windows: dict[int, set[int] | None] = dict.fromkeys(poses)
        """Per robot with an open window, the modules seen shining into it."""
        self.shone: list[int] = []
        """Who switched to transmit, in order."""
        self.overlaps = 0
        self.logs: list[tuple[float, int, str, dict[str, Any]]] = []
        self.fixes: dict[tuple[int, int], ts.RecordFix] = {}
        self.dead: set[int] = set()
        self.drop: Callable[[int, m.SwarmMessage], bool] = lambda sender, message: False
        self._events: list[tuple[float, int, Callable[[], None]]] = []
        self._order = itertools.count()
        for core in self.cores.values():
            core.start(0.0)

    def organize(self, chain: tuple[int, ...]) -> None:
        """Everyone in ``chain`` joins; the first is the master."""
        for addr in chain:
            self.run(
                addr, self.cores[addr].join(SESSION, chain, self._neighbours(addr, chain), addr == chain[0], self.now)
            )

    def regenerations(self) -> list[tuple[float, int, str, dict[str, Any]]]:
        return [e for e in self.logs if e[2] == "token_regenerated"]

    def advance(self, until: float) -> None:
        """Run every event and timer due until ``until``."""
        while True:
            due = [c.next_timer() for a, c in self.cores.items() if a not in self.dead]
            timer = min((t for t in due if t is not None), default=math.inf)
            event = self._events[0][0] if self._events else math.inf
            if min(timer, event) > until:
                self.now = until
                return
            if event <= timer:
                self.now, _, deliver = heapq.heappop(self._events)
                deliver()
                continue
            self.now = timer
            for addr, core in self.cores.items():
                if addr not in self.dead and core.next_timer() is not None and core.next_timer() <= self.now:
                    self.run(addr, core.handle_timer(self.now))

    def run(self, addr: int, actions: list[ts.Action]) -> None:
        """Carry out the actions of robot ``addr``."""
        for action in actions:
            if addr not in self.dead:
                self._do(addr, action)

    @staticmethod
    def _neighbours(addr: int, chain: tuple[int, ...]) -> tuple[int, ...]:
        i = chain.index(addr)
        return tuple(chain[j] for j in (i - 1, i + 1) if 0 <= j < len(chain))

    def _later(self, delay: float, then: Callable[[], None]) -> None:
        heapq.heappush(self._events, (self.now + delay, next(self._order), then))

    def _do(self, addr: int, action: ts.Action) -> None:
        core = self.cores[addr]
        if isinstance(action, ts.Send):
            self._transmit(addr, action.dst, action.message)
            if action.ref is not None:
                self._later(AIR_S, lambda: self.run(addr, core.sent(action.ref, self.now)))
        elif isinstance(action, ts.SendHeading):
            heading = round(self.poses[addr][2] * 100) % 36000
            self._transmit(addr, action.dst, m.Heading(action.session, heading))
        elif isinstance(action, ts.SetIrMode):
            self._switch(addr, action)
        elif isinstance(action, ts.OpenWindow):
            self.windows[addr] = set()
        elif isinstance(action, ts.CloseWindow):
            readings = self._window(addr)
            self.run(addr, core.measured(action.holder, readings, 0 if readings is None else 10, self.now))
        elif isinstance(action, ts.DropWindow):
            self.windows[addr] = None
        elif isinstance(action, ts.RecordFix):
            self.fixes[(addr, action.addr)] = action
        elif isinstance(action, ts.Log):
            self.logs.append((self.now, addr, action.kind, action.detail))

    def _transmit(self, sender: int, dst: int, message: m.SwarmMessage) -> None:
        if self.drop(sender, message):
            return
        for addr, core in self.cores.items():
            if addr != sender and dst in (BROADCAST, addr):
                self._later(AIR_S, lambda a=addr, c=core: self._deliver(a, c, sender, message))

    def _deliver(self, addr: int, core: TokenSchedule, sender: int, message: m.SwarmMessage) -> None:
        if addr in self.dead:
            return
        if isinstance(message, (m.IrStartAck, m.TokenAck)):
            self.run(addr, core.offer(_incoming(sender, message), self.now) or [])
        else:
            self.run(addr, core.receive(sender, message, self.now))

    def _switch(self, addr: int, action: ts.SetIrMode) -> None:
        if action.mode == "transmit":
            self.shone.append(addr)
            self.overlaps += any(mode == "transmit" for mode in self.modes.values())
            for other, seen in self.windows.items():
                if seen is not None and self.modes[other] == "receive":
                    seen.add(addr)
        self.modes[addr] = action.mode
        if action.ref is not None:
            self._later(AIR_S, lambda: self.run(addr, self.cores[addr].mode_set(action.ref, self.now)))

    def _window(self, addr: int) -> np.ndarray | None:
        seen, self.windows[addr] = self.windows[addr], None
        if seen is None or len(seen) != 1:
            return None  # nothing shone into it, or two at once: no fix
        x, y, heading = self.poses[addr]
        tx = self.poses[seen.pop()]
        return _readings((tx[0], tx[1]), (x, y, math.radians(heading)))

    def kill(self, addr: int) -> None:
        """``addr`` stops: it sends, hears and shines no more."""
        self.dead.add(addr)
        self.modes[addr] = "off"


POSES = {1: (0.0, 0.0, 0.0), 2: (1.0, 0.0, 90.0), 3: (0.0, 1.2, 180.0), 4: (1.1, 1.0, -45.0)}


def test_the_token_passes_along_the_chain_one_shining_at_a_time_and_everyone_gets_exact_fixes() -> None:
    air = Air(POSES)
    air.organize((1, 2, 3, 4))
    air.advance(3.0)
    assert len(air.shone) >= 12 and air.shone == [(1, 2, 3, 4)[i % 4] for i in range(len(air.shone))]
    assert air.overlaps == 0 and not air.regenerations()
    for me, (x0, y0, h0) in POSES.items():
        for other, (x1, y1, _) in POSES.items():
            if other == me:
                continue
            fix = air.fixes[(me, other)].fix
            bearing = (math.degrees(math.atan2(y1 - y0, x1 - x0)) - h0) % 360
            assert abs((math.degrees(fix.bearing_rad) - bearing + 180) % 360 - 180) < 1e-6
            assert fix.distance_m == pytest.approx(math.hypot(x1 - x0, y1 - y0), rel=1e-9)
    assert air.cores[1].rounds_held >= 3 and all(c.fixes >= 6 for c in air.cores.values())


def test_a_lost_token_is_regenerated_by_the_master_after_regen_timeout_s() -> None:
    air = Air(POSES)
    air.organize((1, 2, 3, 4))
    air.advance(1.0)
    lost: list[int] = []

    def token_of_robot_3(sender: int, msg: m.SwarmMessage) -> bool:
        """The token and Sync of robot 3's next round never arrive anywhere: nobody learns who is next."""
        if sender != 3 or not isinstance(msg, (m.Token, m.Sync)):
            return False
        round_ = msg.round if isinstance(msg, m.Token) else msg.round - 1  # a Sync names the round after
        lost[:] = lost or [round_]
        return round_ == lost[0]

    air.drop = token_of_robot_3
    master = air.cores[1]
    while not air.regenerations():
        silent_since = master.last_activity
        air.advance(air.now + 0.001)
    [(at, addr, _, detail)] = air.regenerations()
    assert addr == 1 and CONFIG.regen_timeout_s < at - silent_since <= CONFIG.regen_timeout_s + WATCH_PERIOD_S
    shone = len(air.shone)
    air.advance(at + 2.0)
    assert air.shone[shone:][:4] == [1, 2, 3, 4] and air.overlaps == 0 and len(air.regenerations()) == 1
    assert detail["round"] > lost[0]


def test_when_the_holder_dies_the_master_regenerates_and_the_token_skips_it() -> None:
    air = Air(POSES)
    air.organize((1, 2, 3, 4))
    air.advance(0.5)
    while air.shone[-1] != 3 or air.modes[3] != "transmit":
        air.advance(air.now + 0.001)
    master = air.cores[1]
    air.kill(3)
    killed_at, silent_since = air.now, master.last_activity
    while not air.regenerations():
        air.advance(air.now + 0.001)
    [(at, *_)] = air.regenerations()
    assert CONFIG.regen_timeout_s < at - silent_since <= CONFIG.regen_timeout_s + WATCH_PERIOD_S
    assert at - killed_at <= CONFIG.regen_timeout_s + WATCH_PERIOD_S
    shone = len(air.shone)
    air.advance(at + 3.0)
    assert 3 not in air.shone[shone:] and air.shone[shone : shone + 3] == [1, 2, 4]  # after retries, skipped
    silent = [e for e in air.logs if e[2] == "retry" and e[3]["step"] == "ir_start"]
    assert silent and all(e[3]["missing"] == [3] for e in silent)
    assert air.overlaps == 0 and len(air.regenerations()) == 1


def test_a_member_that_leaves_is_no_longer_given_the_token() -> None:
    air = Air(POSES)
    air.organize((1, 2, 3, 4))
    air.advance(1.0)
    while air.cores[1].holding is None:  # robot 3 leaves while the master holds (not robot 3 itself)
        air.advance(air.now + 0.001)
    for addr in (1, 2, 4):
        air.run(addr, air.cores[addr].update_members((1, 2, 4), Air._neighbours(addr, (1, 2, 4))))
    air.run(3, air.cores[3].leave(air.now))
    assert air.modes[3] == "idle"
    shone = len(air.shone)
    air.advance(4.0)
    after = air.shone[shone:]
    assert after[:6] == [1, 2, 4, 1, 2, 4] and 3 not in after and len(after) >= 9
    assert not air.regenerations() and air.overlaps == 0
