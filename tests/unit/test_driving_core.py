"""The driver's sans-IO core (petswarm/controllers/driving_core.py) stepped by hand: events with an explicit ``now`` in,
actions out, no event loop and no clock. The user's modes (spec pet-bot-wearable.md), the lost user, the
turn-about, Table 3 of swarm-middleware.md in both columns, and a slave steering to its slot."""

from __future__ import annotations

import ast
import inspect
import math
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest

from petswarm.controllers import driving_core, surround_core
from petswarm.controllers.driving_core import (
    CONTROL_PERIOD_S,
    LOST_AFTER_S,
    REMOTE_HOLD_S,
    STATES,
    TRACK_PERIOD_S,
    WAKE_PERIOD_S,
    BleSend,
    Disperse,
    Drive,
    DriverCore,
    HandOver,
    LfBurst,
    Log,
    Organize,
    SendSwarm,
    SetUser,
    Telemetry,
    user_id,
)
from petswarm.controllers.formation_shapes import Mode
from petswarm.controllers.motion import MotorCommand
from petswarm.managers import messages as m
from petswarm.managers.event_log import EventLog
from petswarm.managers.sequence import RobotState, SequenceManager, TransitionError
from petswarm.wearables import user_link
from radio_hub.values import BROADCAST, OwnSensors

BELT = "user-1"
ANGLES = np.linspace(0.0, 2 * math.pi, 8, endpoint=False)


@dataclass
class Swarm:
    """The formation's view of a swarm, as the core reads it."""

    session: int
    master: int
    number: int
    members: tuple[int, ...]


@dataclass
class Formation:
    swarm: Swarm | None = None
    me: int = 1


@dataclass
class Fix:
    distance_m: float | None
    bearing_rad: float | None
    fixed_at: float | None


@dataclass
class Fixes:
    table: dict[int, Fix] = field(default_factory=dict)


def make(state: RobotState = RobotState.WAITING, robot_id: int = 1) -> tuple[DriverCore, Formation, Fixes]:
    formation, fixes = Formation(me=robot_id), Fixes()
    core = DriverCore(robot_id, SequenceManager(EventLog(), state), formation, fixes, now=0.0)
    core.start(0.0)
    return core, formation, fixes


def ble(kind: str, **fields: Any) -> bytes:
    return user_link.encode(kind, **fields)


def lf_ahead(distance: float) -> bytes:
    """The belt's LF report for a user straight on the robot's axis (ahead, or behind when leading)."""
    d = math.hypot(distance, 0.1)  # the antennas sit 0.1 m either side of the centre
    return ble("lf", seq=1, dl=d, dr=d)


def sensors(t: float, yaw: float = 0.0, ranges: float = math.nan) -> OwnSensors:
    return OwnSensors(int(t * 1e6), np.full(8, ranges), ANGLES, yaw, (0.0, 0.0, 0.0))


def of(actions: list[Any], kind: type) -> list[Any]:
    return [a for a in actions if isinstance(a, kind)]


def logs(actions: list[Any], kind: str) -> list[dict[str, Any]]:
    return [a.detail for a in of(actions, Log) if a.kind == kind]


def states(actions: list[Any]) -> list[str]:
    """The states the robot told its owner."""
    return [user_link.decode(a.payload).get("state") for a in of(actions, BleSend)]


def run_until(core: DriverCore, end: float) -> list[Any]:
    """Wake the core at each of its timers up to ``end`` (a DriveState put on the air leaves at once)."""
    out: list[Any] = []
    while (when := core.next_timer()) is not None and when <= end:
        core.handle_timer(when)
        actions = core.actions()
        out.extend(actions)
        if of(actions, SendSwarm):
            core.drive_state_sent(when)
    return out


def paired(state: RobotState = RobotState.FOLLOWING, request: str = "follow") -> DriverCore:
    """A robot whose owner's belt answered its wake-up, with ``request`` chosen on the watch."""
    core, *_ = make()
    core.ble_message(BELT, ble("owner", d=0.8, seq=challenge(run_until(core, 0.0))), 0.01)
    core.ble_message(BELT, ble("request", request=request), 0.02)
    assert core.sequence.state == state
    core.actions()
    return core


def challenge(actions: list[Any]) -> int:
    """The sequence byte of the latest wake burst among ``actions``: what the belt that heard it echoes."""
    return user_link.parse_lf_data(of(actions, LfBurst)[-1].data)[1]


def drives(actions: list[Any]) -> list[Any]:
    return [a.command for a in of(actions, Drive)]


# -- the module is sans-IO ---------------------------------------------------------------------------


@pytest.mark.parametrize("module", [driving_core, surround_core])
def test_the_cores_import_no_clock_no_event_loop_and_no_transport(module: ModuleType) -> None:
    tree = ast.parse(Path(inspect.getfile(module)).read_text())
    imported = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imported |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    names = {a.name for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) for a in n.names}
    assert not imported & {"asyncio", "time", "zenoh", "petswarm.clock"}, imported
    assert "clock" not in names


# -- owner and timers --------------------------------------------------------------------------------


def test_a_waiting_robot_fires_a_wake_up_burst_every_3_s_and_takes_a_belt_within_1_m_as_owner() -> None:
    core, *_ = make()
    bursts = of(run_until(core, 6.0), LfBurst)
    assert [b.antenna for b in bursts] == ["left"] * 3  # at 0, 3 and 6 s
    assert [user_link.parse_lf_data(b.data)[2] for b in bursts] == [user_link.LF_WAKE] * 3
    assert core.timer("lf") == pytest.approx(3 * WAKE_PERIOD_S)

    heard = user_link.parse_lf_data(bursts[-1].data)[1]
    core.ble_message("user-2", ble("owner", d=1.4, seq=heard), 6.1)  # beyond the wake range: not an owner
    assert core.owner is None and core.actions() == []
    core.ble_message(BELT, ble("owner", d=0.7, seq=heard), 6.2)
    actions = core.actions()
    assert core.owner == BELT and core.sequence.state == RobotState.COMMAND_WAITING
    assert of(actions, SetUser) == [SetUser(user_id(BELT))]
    assert states(actions) == ["command-waiting"]
    core.ble_message("user-2", ble("request", request="follow"), 6.3)  # not the owner's watch
    assert logs(core.actions(), "ble_ignored") == [{"src": "user-2", "message": "request"}]
    assert core.sequence.state == RobotState.COMMAND_WAITING


def test_only_a_belt_that_heard_the_wake_burst_becomes_the_owner_and_only_its_user_commands() -> None:
    """An outsider (user-9) became robot 2's owner over BLE with a bare owner claim and had it organize a swarm.
    A claim must echo the challenge of a recent wake burst (the LF reaches about 1 m); a wrong one is refused,
    counted, and spends the pending challenges, so a guesser gets one try per burst."""
    core, *_ = make(robot_id=2)
    heard = challenge(run_until(core, 0.0))
    for claim in ({"d": 0.3}, {"d": 0.3, "seq": (heard + 1) % 256}, {"d": 0.3, "seq": "x"}):
        core.ble_message("user-9", ble("owner", **claim), 0.1)
        assert core.owner is None and core.sequence.state == RobotState.WAITING
    assert core.unpaired == 3 and len(logs(core.actions(), "owner_refused")) == 3
    core.ble_message(BELT, ble("owner", d=0.7, seq=heard), 0.2)  # spent by the refused guess: wait for a burst
    assert core.owner is None and core.unpaired == 4
    core.ble_message(BELT, ble("owner", d=0.7, seq=challenge(run_until(core, 3.0))), 3.1)
    assert core.owner == BELT and core.sequence.state == RobotState.COMMAND_WAITING
    core.ble_message("user-9", ble("request", request="organize", robots=3), 3.2)
    core.ble_message("user-9", ble("owner", d=0.1, seq=heard), 3.3)
    actions = core.actions()
    assert of(actions, Organize) == [] and core.owner == BELT and core.unpaired == 6
    # challenges differ from burst to burst and from robot to robot (unpredictable without the robot's key)
    seen = {challenge(run_until(c, t)) for c in (make(robot_id=2)[0], make(robot_id=3)[0]) for t in (0.0, 3.0, 6.0)}
    assert len(seen) >= 4


def test_malformed_or_refused_ble_messages_are_logged_and_dropped() -> None:
    core = paired()
    core.ble_message(BELT, b"\xc1garbage", 1.0)
    core.ble_message(BELT, ble("request", request="mode", mode="sideways"), 1.1)
    refused = logs(core.actions(), "ble_refused")
    assert [r["error"].split(":")[0] for r in refused] == ["ValueError", "ValueError"]
    assert core.sequence.state == RobotState.FOLLOWING


def test_a_request_fig4_refuses_raises_when_called_directly_and_is_logged_when_it_comes_over_ble() -> None:
    core, *_ = make(RobotState.SLAVE_DRIVING, robot_id=2)
    core.owner = BELT  # a slave has no owner of its own; a stale one must not move it out of the swarm
    with pytest.raises(TransitionError):
        core.user_request({"request": "follow"}, 1.0)
    core.ble_message(BELT, ble("request", request="lead"), 1.1)
    [refused] = logs(core.actions(), "ble_refused")
    assert refused["error"].startswith("TransitionError") and core.sequence.state == RobotState.SLAVE_DRIVING


def test_tracking_fires_both_antennas_5_ms_apart_every_350_ms() -> None:
    core = paired()
    start = core.timer("lf")
    assert start is not None
    times = []
    while (when := core.next_timer()) is not None and when < start + 2 * TRACK_PERIOD_S - 1e-3:
        core.handle_timer(when)
        times += [(when, b.antenna) for b in of(core.actions(), LfBurst)]
    assert [a for _, a in times] == ["left", "right", "left", "right"]
    assert times[1][0] - times[0][0] == pytest.approx(0.005)
    assert times[2][0] - times[0][0] == pytest.approx(TRACK_PERIOD_S)


def test_timers_due_at_one_instant_run_first_set_first_and_handle_timer_runs_only_what_is_due() -> None:
    core, *_ = make(RobotState.COMMAND_WAITING)
    assert core.next_timer() == 0.0
    core.handle_timer(0.0)
    assert [type(a) for a in core.actions()] == []  # no owner yet: no burst, just the next LF round
    assert core.timer("control") == pytest.approx(CONTROL_PERIOD_S)
    core.handle_timer(0.04)
    assert core.actions() == []
    core.handle_timer(0.05)
    assert drives(core.actions()) == [MotorCommand()]  # waiting for a command: stand still


# -- the user's modes --------------------------------------------------------------------------------


def test_following_drives_toward_a_user_ahead_and_stops_when_the_fix_is_lost_then_recovers() -> None:
    core = paired()
    core.sensors_sample(sensors(0.02), 0.02)
    core.ble_message(BELT, lf_ahead(1.6), 0.03)
    [cmd] = drives(run_until(core, 0.06))
    assert cmd.vx > 0.1 and abs(cmd.vy) < 1e-9 and abs(cmd.omega) < 1e-9  # closes in along the axis

    actions = run_until(core, 0.03 + LOST_AFTER_S + 0.06)  # no LF fix any more
    assert core.sequence.state == RobotState.EMERGENCY
    alerts = [user_link.decode(a.payload) for a in of(actions, BleSend)]
    assert {"k": "alert", "reason": "user lost"} in alerts
    assert drives(actions)[-1].speed == 0 and drives(actions)[-1].omega == 0

    now = core.next_timer()
    core.ble_message(BELT, lf_ahead(1.2), now)
    run_until(core, now + 0.06)
    assert core.sequence.state == RobotState.FOLLOWING  # user found: back to the mode before the emergency


def test_a_fix_just_outside_the_valid_range_loses_the_user_only_after_lost_after_s() -> None:
    """A robot that overshot as its user stopped sees him at 2.1 m for a fix or two and drives back: it is
    lost only when no fix inside the 2 m range has come for LOST_AFTER_S."""
    core = paired(RobotState.LEADING, "lead")
    core.sensors_sample(sensors(0.02), 0.02)
    core.ble_message(BELT, lf_ahead(1.5), 0.03)
    run_until(core, 0.1)
    for k in range(int(LOST_AFTER_S / TRACK_PERIOD_S)):  # every fix outside the range, until just before 2 s
        now = 0.35 + k * TRACK_PERIOD_S
        core.ble_message(BELT, lf_ahead(2.1), now)
        actions = run_until(core, now + 0.06)
        assert core.sequence.state == RobotState.LEADING and not of(actions, BleSend)
        assert drives(actions)[-1].vx < 0  # backing toward the user behind
    core.ble_message(BELT, lf_ahead(2.1), 0.03 + LOST_AFTER_S + 0.05)
    actions = run_until(core, 0.03 + LOST_AFTER_S + 0.11)
    assert core.sequence.state == RobotState.EMERGENCY
    assert {"k": "alert", "reason": "user lost"} in [user_link.decode(a.payload) for a in of(actions, BleSend)]


def test_leading_takes_the_user_behind_and_keeps_ahead_of_him() -> None:
    core = paired(RobotState.LEADING, "lead")
    assert core.mode == Mode.LEADING
    core.ble_message(BELT, lf_ahead(0.6), 0.03)
    assert core.fix is not None and core.fix.forward_m == pytest.approx(-0.6)
    [cmd] = drives(run_until(core, 0.06))
    assert cmd.vx > 0.1  # the user is too close behind: the robot moves on ahead


def test_leading_into_an_obstacle_becomes_remote_control_and_return_goes_back() -> None:
    core = paired(RobotState.LEADING, "lead")
    core.sensors_sample(sensors(0.02, ranges=0.15), 0.02)
    core.ble_message(BELT, lf_ahead(1.0), 0.03)
    actions = run_until(core, 0.06)
    assert core.sequence.state == RobotState.REMOTE_CONTROL and states(actions) == ["remote-control"]
    core.ble_message(BELT, ble("request", request="return"), 0.4)
    assert core.sequence.state == RobotState.LEADING


def test_remote_control_moves_on_a_gesture_for_its_hold_time_and_a_circle_cancels() -> None:
    core = paired(RobotState.REMOTE_CONTROL, "remote")
    run_until(core, 1.0)
    core.ble_message(BELT, ble("request", request="gesture", gesture="forward"), 1.0)
    moving = drives(run_until(core, 1.0 + REMOTE_HOLD_S - 0.05))
    assert moving and all(c.vx == pytest.approx(0.3) and c.vy == 0 for c in moving)
    after = drives(run_until(core, 1.0 + REMOTE_HOLD_S + 0.2))
    assert after[-1].speed == 0
    core.ble_message(BELT, ble("request", request="gesture", gesture="circle"), 3.0)
    assert core.sequence.state == RobotState.COMMAND_WAITING


def test_cancel_goes_back_to_waiting_for_a_command() -> None:
    core = paired()
    core.ble_message(BELT, ble("request", request="cancel"), 1.0)
    assert core.sequence.state == RobotState.COMMAND_WAITING
    assert states(core.actions()) == ["command-waiting"]


# -- turn-about --------------------------------------------------------------------------------------


def test_a_single_robot_turns_round_on_its_ahrs_when_following_becomes_leading() -> None:
    core = paired()
    core.sensors_sample(sensors(0.02, yaw=0.0), 0.02)
    core.ble_message(BELT, lf_ahead(1.0), 0.03)
    core.ble_message(BELT, ble("request", request="lead"), 0.04)
    actions = core.actions()
    assert core.sequence.state == RobotState.LEADING and core.mode == Mode.LEADING
    [turn] = logs(actions, "turn_about")
    assert abs(turn["to_yaw"]) == pytest.approx(math.pi, abs=1e-3)
    [cmd] = drives(run_until(core, 0.06))
    assert cmd.vx == 0 and cmd.vy == 0 and abs(cmd.omega) == pytest.approx(1.5)  # in place, at the limit
    core.sensors_sample(sensors(0.07, yaw=math.pi - 0.05), 0.07)
    actions = run_until(core, 0.11)
    assert logs(actions, "turn_about_done") == [{}]
    assert core.fix is None and core.turn_to is None  # the fix taken facing the other way is forgotten


def test_a_turn_about_gives_the_first_fix_facing_the_new_way_the_lost_user_time() -> None:
    core = paired()
    core.sensors_sample(sensors(0.02, yaw=0.0), 0.02)
    core.ble_message(BELT, lf_ahead(1.0), 0.03)
    core.ble_message(BELT, ble("request", request="lead"), 0.04)
    core.sensors_sample(sensors(0.07, yaw=math.pi - 0.05), 0.07)
    actions = run_until(core, 0.11)
    assert logs(actions, "turn_about_done") == [{}]
    # no fix yet facing the new way: not lost until LOST_AFTER_S has passed without one
    actions = run_until(core, 0.10 + LOST_AFTER_S - 0.1)
    assert core.sequence.state == RobotState.LEADING and not of(actions, BleSend)
    actions = run_until(core, 0.10 + LOST_AFTER_S + 0.1)
    assert core.sequence.state == RobotState.EMERGENCY
    assert {"k": "alert", "reason": "user lost"} in [user_link.decode(a.payload) for a in of(actions, BleSend)]


def test_the_first_choice_after_pairing_turns_nothing_and_a_later_change_of_side_turns_in_any_state() -> None:
    core = paired(RobotState.LEADING, "lead")  # the user placed the robot ahead of him: no turn
    assert not logs(core.actions(), "turn_about") and core.turn_to is None
    core.sensors_sample(sensors(0.02, yaw=0.0), 0.02)
    core.ble_message(BELT, ble("request", request="cancel"), 0.03)
    core.ble_message(BELT, ble("request", request="follow"), 0.04)  # from command-waiting: faces him now
    assert core.sequence.state == RobotState.FOLLOWING and logs(core.actions(), "turn_about")
    [cmd] = drives(run_until(core, 0.06))
    assert cmd.vx == 0 and cmd.vy == 0 and abs(cmd.omega) == pytest.approx(1.5)


def test_a_mode_change_in_command_waiting_or_remote_control_turns_the_robot_at_once() -> None:
    core = paired(RobotState.LEADING, "lead")
    core.sensors_sample(sensors(0.02, yaw=0.0), 0.02)
    core.ble_message(BELT, ble("request", request="cancel"), 0.03)
    core.ble_message(BELT, ble("request", request="mode", mode="following"), 0.04)
    assert core.sequence.state == RobotState.COMMAND_WAITING and core.mode == Mode.FOLLOWING
    [cmd] = drives(run_until(core, 0.06))
    assert abs(cmd.omega) == pytest.approx(1.5)  # turning round while it waits for a command

    core = paired(RobotState.LEADING, "lead")
    core.sensors_sample(sensors(0.02, yaw=0.0, ranges=0.3), 0.02)
    core.ble_message(BELT, lf_ahead(1.0), 0.03)
    run_until(core, 0.06)  # an obstacle ahead: remote control, the user points the way
    assert core.sequence.state == RobotState.REMOTE_CONTROL and core.exception_from == RobotState.LEADING
    core.actions()
    core.ble_message(BELT, ble("request", request="mode", mode="following"), 0.07)
    assert core.exception_from == RobotState.FOLLOWING  # "return" comes back to the side it now faces
    [cmd] = drives(run_until(core, 0.11))
    assert abs(cmd.omega) == pytest.approx(1.5)
    core.ble_message(BELT, ble("request", request="remote"), 0.12)  # remote control keeps the side
    assert core.mode == Mode.FOLLOWING


# -- the swarm: Table 3 ------------------------------------------------------------------------------


def master_of_three(shape: str = "column", mode: str = "follow", user_m: float = 1.0) -> tuple[DriverCore, Formation]:
    """Robot 1, master of 1-2-3 with its owner ``user_m`` on its axis (ahead following, behind leading)."""
    core = paired(STATES[mode], mode)
    run_until(core, 0.3)
    core.ble_message(BELT, ble("request", request="organize", robots=3, shape=shape), 0.3)
    assert of(core.actions(), Organize) == [Organize(3)]
    core.sequence.transition(RobotState.ORGANIZING)  # what the formation does meanwhile
    core.sequence.transition(RobotState.MASTER_DRIVING)
    formation = core.formation
    assert isinstance(formation, Formation)
    formation.swarm = Swarm(7, 1, 0, (2, 3))
    run_until(core, 0.5)
    core.organized([2, 3], None, 0.5)
    core.sensors_sample(sensors(0.5), 0.5)
    core.ble_message(BELT, lf_ahead(user_m), 0.5)
    core.actions()
    return core, formation


def test_table3_no_change_the_master_stays_and_the_slots_are_mirrored() -> None:
    core, _ = master_of_three("line")
    core.ble_message(BELT, ble("request", request="mode", mode="leading", change_master=False), 1.0)
    actions = core.actions()
    [change] = logs(actions, "mode_change")
    assert change["applied"] == "no-change" and change["table3_master"] == 0
    assert not of(actions, HandOver)
    assert core.mirrored and core.mode == Mode.LEADING
    assert core.sequence.state == RobotState.MASTER_DRIVING
    assert core.sequence.previous_driving == RobotState.LEADING  # dispersing restores the new mode
    assert logs(actions, "turn_about")


def test_table3_change_hands_the_master_role_to_the_robot_table3_picks() -> None:
    core, _ = master_of_three("column")
    core.ble_message(BELT, ble("request", request="mode", mode="leading", change_master=True), 1.0)
    actions = core.actions()
    [change] = logs(actions, "mode_change")
    assert change["applied"] == "change" and change["table3_master"] == 2  # the column's tail
    [handover] = of(actions, HandOver)
    assert handover.chain == (3, 2, 1) and handover.mode == "leading" and handover.owner == BELT
    assert not core.mirrored  # every robot keeps its place: nothing is mirrored


def test_table3_change_leading_to_following_makes_the_robot_closest_to_the_user_master() -> None:
    core, _ = master_of_three("column", "lead", user_m=2.2)  # the column's tail is 1.0 m ahead of the user
    core.ble_message(BELT, ble("request", request="mode", mode="following", change_master=True), 1.0)
    actions = core.actions()
    [change] = logs(actions, "mode_change")
    assert change["distances"] == {"1": 2.2, "2": 1.6, "3": 1.0}
    assert change["applied"] == "change" and change["table3_master"] == 2
    [handover] = of(actions, HandOver)
    assert handover.chain == (3, 2, 1) and handover.mode == "following"


def test_table3_change_keeps_the_master_when_it_is_the_closest_itself() -> None:
    core, _ = master_of_three("line", "lead", user_m=1.0)  # a line: the master, in the middle, is closest
    core.ble_message(BELT, ble("request", request="mode", mode="following", change_master=True), 1.0)
    actions = core.actions()
    [change] = logs(actions, "mode_change")
    assert change["table3_master"] == 0 and change["applied"] == "no-change"
    assert not of(actions, HandOver) and core.mirrored and core.mode == Mode.FOLLOWING


def test_table3_change_falls_back_to_no_change_when_the_new_master_never_accepts() -> None:
    core, _ = master_of_three("column")
    core.ble_message(BELT, ble("request", request="mode", mode="leading", change_master=True), 1.0)
    core.actions()
    core.handed_over(False, None, 1.6)
    assert logs(core.actions(), "mode_change_fallback") == [{"applied": "no-change"}]
    assert core.mirrored and core.sequence.state == RobotState.MASTER_DRIVING


def test_after_the_handover_the_old_master_re_pairs_the_belt_and_gives_its_owner_up() -> None:
    core, formation = master_of_three("column")
    core.ble_message(BELT, ble("request", request="mode", mode="leading", change_master=True), 1.0)
    [handover] = of(core.actions(), HandOver)
    core.sequence.transition(RobotState.SLAVE_DRIVING)
    formation.swarm = Swarm(7, 3, 2, (2, 1))
    msg = m.MasterHandover(7, 0x2000, handover.chain, "leading", "column", 0.6, 0, 0, BELT)
    core.handover((1, 2, 3), msg, 1.3)
    actions = core.actions()
    assert [user_link.decode(a.payload) for a in of(actions, BleSend)] == [{"k": "pair", "robot": 3}]
    assert core.owner is None and core.fix is None
    assert logs(actions, "owner_handed_over") == [{"owner": BELT, "to": 3}]
    # every robot keeps its place, now in the new master's frame (it turned round at the column's tail)
    assert core.kept is not None
    assert core.kept[3] == pytest.approx((0.0, 0.0)) and core.kept[1] == pytest.approx((-1.2, 0.0))


def test_the_new_master_takes_the_owner_and_announces_itself_on_its_first_fix() -> None:
    core, formation, _ = make(RobotState.SLAVE_DRIVING, robot_id=3)
    formation.swarm = Swarm(7, 1, 2, (2, 3))
    core.sensors_sample(sensors(1.0, yaw=0.3), 1.0)
    core.sequence.transition(RobotState.MASTER_DRIVING)
    formation.swarm = Swarm(7, 3, 0, (2, 1))
    msg = m.MasterHandover(7, 0x2000, (3, 2, 1), "leading", "column", 0.6, 0, 0, BELT)
    core.handover((1, 2, 3), msg, 1.1)
    actions = core.actions()
    assert core.owner == BELT and core.mode == Mode.LEADING
    assert of(actions, SetUser) == [SetUser(user_id(BELT))] and logs(actions, "turn_about")
    assert core.kept is not None
    assert core.kept[1] == pytest.approx((-1.2, 0.0))  # the old master: last, nearest the user
    core.ble_message(BELT, lf_ahead(1.0), 1.2)
    assert logs(core.actions(), "owner_tracked")


def test_the_master_broadcasts_its_drive_state_every_100_ms_after_each_has_left() -> None:
    core, _ = master_of_three("column")
    when = core.timer("broadcast")
    assert when is not None and 0.5 < when <= 0.6
    core.handle_timer(when)
    sends = of(core.actions(), SendSwarm)
    assert len(sends) == 1 and sends[0].dst == BROADCAST and not sends[0].ack
    state = sends[0].message
    assert isinstance(state, m.DriveState) and state.session == 7 and state.shape == "column"
    assert state.user_x == pytest.approx(1.0) and state.mode == "following"
    assert core.timer("broadcast") is None  # the next waits until this one has left
    core.drive_state_sent(when + 0.002, "hub away")
    assert logs(core.actions(), "error") == [{"where": "drive_state", "error": "hub away"}]
    assert core.timer("broadcast") == pytest.approx(when + 0.102)


def test_disperse_asks_the_formation_and_clears_the_swarm_geometry_when_done() -> None:
    core, _ = master_of_three("line")
    core.ble_message(BELT, ble("request", request="mode", mode="leading", change_master=False), 1.0)
    core.ble_message(BELT, ble("request", request="disperse"), 2.0)
    assert of(core.actions(), Disperse) == [Disperse()]
    core.dispersed("FormationError: no swarm", 2.1)
    assert logs(core.actions(), "watch_disperse_failed") == [{"error": "FormationError: no swarm"}]
    assert not core.mirrored and core.kept is None


# -- the slave ---------------------------------------------------------------------------------------


def slave_of(master: int = 1) -> tuple[DriverCore, Fixes]:
    core, formation, fixes = make(RobotState.SLAVE_DRIVING, robot_id=2)
    formation.swarm = Swarm(7, master, 1, (2, 3))
    core.sensors_sample(sensors(0.0), 0.0)
    return core, fixes


def drive_state(seq: int = 1, vx: float = 0.0) -> m.DriveState:
    return m.DriveState(7, seq, vx, 0.0, 0.0, 0.0, 0, 0.0, "following", "column", 0.6, 1.0, 0.0, 0, 0)


def test_a_slave_steers_to_its_slot_behind_the_master_from_its_ir_fix() -> None:
    core, fixes = slave_of()
    core.drive_state(1, drive_state(), 0.01)
    fixes.table[1] = Fix(1.0, 0.0, 0.02)  # the master 1.0 m ahead; the slot is 0.6 m behind it
    [cmd] = drives(run_until(core, 0.05))
    assert cmd.vx > 0.05 and abs(cmd.vy) < 0.05
    fixes.table[1] = Fix(0.3, 0.0, 0.06)  # too close: back off
    [cmd] = drives(run_until(core, 0.1))
    assert cmd.vx < 0


def test_a_slave_ignores_other_robots_drive_states_and_stops_when_its_master_falls_silent() -> None:
    core, fixes = slave_of()
    core.drive_state(3, drive_state(), 0.01)  # not the master
    core.drive_state(1, m.DriveState(8, 1, 0, 0, 0, 0, 0, 0, "following", "column", 0.6, 1, 0, 0, 0), 0.01)
    assert core.counters["drive_states"] == 0
    core.drive_state(1, drive_state(vx=0.5), 0.02)
    assert core.counters["drive_states"] == 1 and logs(core.actions(), "user_activity_heard")
    fixes.table[1] = Fix(1.0, 0.0, 0.02)
    assert drives(run_until(core, 0.05))[-1].vx > 0
    silent = drives(run_until(core, 1.1))
    assert silent[-1] == MotorCommand()  # more than 1 s without a word: stop safely


def test_telemetry_every_ten_control_steps_names_the_slave_slot() -> None:
    core, _ = slave_of()
    core.drive_state(1, drive_state(), 0.01)
    actions = run_until(core, 0.5)
    [telemetry] = of(actions, Telemetry)
    assert telemetry.role == "slave" and telemetry.master == "robot-1" and telemetry.state == "slave-driving"
    assert telemetry.slot == pytest.approx((-0.6, 0.0))


def _ring_sample(t: float, yaw_deg: float, ahead_m: float, vx: float) -> OwnSensors:
    ranges = np.full(8, math.nan)
    ranges[0] = ahead_m
    return OwnSensors(int(t * 1e6), ranges, ANGLES, math.radians(yaw_deg), (vx, 0.0, 0.0))


def test_an_echo_seen_while_the_ring_turns_is_not_taken_for_one_moving_away() -> None:
    """Seed 1 case 581, seed 5 case 52: a robot turning on the spot at 1.5 rad/s while driving at 0.7 m/s had its
    front beam swing from the user (0.4 m) onto a robot as far: the range did not change, so the robot counted that
    robot as receding at its own speed and drove into it. Over a turn wider than a cone's half-width (15 degrees)
    the range rates are unknown (no allowance for a receding echo); a steady ring keeps them."""
    from petswarm.controllers.driving_core import EchoRanges

    steady = EchoRanges(strict=True)
    for k in range(6):
        steady.observe(_ring_sample(0.04 * k, 90.0 + k, 0.4, 0.7))
    _, _, receding = steady.floats(_ring_sample(0.24, 96.0, 0.4, 0.7))
    # the echo keeps its range as the robot drives at it: it moves away at 0.7 m/s, faster than noise could fake (less
    # what it may have lost since, braking: 2 m/s^2 over half the 0.2 s span and one 0.04 s ring period)
    assert receding[0] == pytest.approx(0.7 - 2.0 * (0.1 + 0.04))
    for ahead_m, counted in ((0.1, 0.0), (0.4, 0.1 - 0.28)):
        slow = EchoRanges(strict=True)
        for k in range(6):
            slow.observe(_ring_sample(0.04 * k, 90.0 + k, ahead_m, 0.1))
        _, _, receding = slow.floats(_ring_sample(0.24, 96.0, ahead_m, 0.1))
        # 0.1 m/s over 0.2 s is within what noise fakes: not counted inside the stop distance, where it alone would
        # let the robot close in; beyond it, counted as before
        assert receding[0] == pytest.approx(counted)
    turning = EchoRanges(strict=True)
    for k in range(6):
        turning.observe(_ring_sample(0.04 * k, 90.0 + 3.5 * k, 0.4, 0.7))
    _, _, receding = turning.floats(_ring_sample(0.24, 111.0, 0.4, 0.7))
    assert receding == ()
    plain = EchoRanges()  # the surround laws' rates: as measured, turn or not
    for k in range(6):
        plain.observe(_ring_sample(0.04 * k, 90.0 + 3.5 * k, 0.4, 0.7))
    assert plain.floats(_ring_sample(0.24, 111.0, 0.4, 0.7))[2][0] == pytest.approx(0.7)


def test_a_robot_speeding_up_behind_a_leader_reads_the_leader_s_speed_not_its_own_gain() -> None:
    """Seed 1 case 117: a slave accelerating to 1.1 m/s behind its braking master added its latest speed to a range
    rate averaged over 0.2 s, read the master receding at 1.1 m/s (it drove at 0.5) and ran into it. The rate is the
    span's mean, so the strict ring adds its own speed's mean over that span: a leader at a steady 0.5 m/s is read
    at 0.5 m/s whatever the follower's acceleration."""
    from petswarm.controllers.driving_core import EchoRanges

    def sample(t: float) -> OwnSensors:  # the follower at 0.5 m/s + 3 m/s^2, the leader 0.6 m ahead at 0.5 m/s
        return _ring_sample(t, 90.0, 0.6 - 1.5 * t * t, 0.5 + 3.0 * t)

    ring = EchoRanges(strict=True)
    for k in range(6):
        ring.observe(sample(0.04 * k))
    _, _, receding = ring.floats(sample(0.24))
    assert receding[0] == pytest.approx(0.5 - 2.0 * (0.1 + 0.04))  # the leader's speed, less what braking may take
    plain = EchoRanges()  # the surround laws' ring keeps the latest speed
    for k in range(6):
        plain.observe(sample(0.04 * k))
    assert plain.floats(sample(0.24))[2][0] > 0.7


def test_a_receding_echo_s_speed_is_read_no_higher_than_a_braking_leader_s_can_be_now() -> None:
    """Seed 2 case 84: a robot following at 1.2 m/s read a robot ahead, stopping at 2 m/s^2, receding at its mean
    speed over the 0.2 s rate span plus the readings' age: 0.3-0.4 m/s above its true speed, and ran into it. The
    strict ring now reads no more than the leader's speed can still be, whatever its braking (at most the base's
    2 m/s^2)."""
    from petswarm.controllers.driving_core import EchoRanges

    def sample(t: float) -> OwnSensors:  # the follower at a steady 1 m/s, the leader braking from 1 m/s at 2 m/s^2
        return _ring_sample(t, 90.0, 0.5 - t * t, 1.0)

    ring = EchoRanges(strict=True)
    for k in range(6):
        ring.observe(sample(0.04 * k))
    _, _, receding = ring.floats(sample(0.24))
    # the leader's speed one ring period after the latest reading (0.24 s), when the follower acts on it
    assert receding[0] <= 1.0 - 2.0 * (0.24 + 0.04) + 1e-9
