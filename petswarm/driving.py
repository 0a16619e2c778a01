"""Driving with the user: owner detection over LF/BLE, the single robot's modes, and swarm driving.

The asyncio shell around the pure controllers (``pet_controller``, ``slave_controller``,
``formation_shapes``) and the wearables' models (``lf_location``):

- waiting for a user, the robot fires an LF wake-up burst every 3 s; a belt holding its pattern within
  1 m answers over BLE and becomes the robot's owner (command-waiting);
- tracking (following, leading, master-driving), it fires LF every 350 ms from each antenna in turn; the
  belt answers with the two distances, which ``locate`` turns into the user's distance and bearing;
- the watch's requests select the operation (follow, lead, remote), cancel it, organize or disperse a
  swarm, change the driving mode, steer by gestures in remote control, or return from an exception;
- every 50 ms the controller of the current state produces a motor command; the master broadcasts
  ``DriveState`` every 100 ms on the swarm's PAN; a slave steers to its formation slot from its IR fix of
  the master, dead-reckoned between token rounds with its own odometry and the master's broadcast speed.
"""

from __future__ import annotations

import asyncio
import math
import zlib
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from petswarm import clock, user_link
from petswarm import messages as m
from petswarm.activity import Activity, Movement
from petswarm.formation import FormationError, NetworkFormation
from petswarm.formation_shapes import (
    STANDARD_DISTANCE_M,
    Mode,
    handover_chain,
    kept_slots,
    mode_change,
    neighbours,
    slots,
)
from petswarm.formation_shapes import master_target_distance as formation_distance
from petswarm.gestures import Gesture, combine
from petswarm.lf_location import UserFix, locate
from petswarm.motion import MotorCommand, Vec, wrap
from petswarm.pet_controller import PetControllerConfig, Ranges, UserObservation, follow, lead, obstacle_ahead, safety
from petswarm.relative_location import RelativeLocationManager
from petswarm.rf import Incoming, RfCommunicationManager
from petswarm.sequence import EventLog, RobotState, SequenceManager, TransitionError
from petswarm.slave_controller import RelativeFix, RelativeTracker, SlaveControllerConfig, slave_decision
from radio_hub.interface import BROADCAST, HubUnavailable, OwnSensors, RadioError
from radio_hub.lf import LfConfig, wake_pattern

WAKE_PERIOD_S = 3.0
TRACK_PERIOD_S = 0.35
CONTROL_PERIOD_S = 0.05
BROADCAST_PERIOD_S = 0.1
LF_VALID_RANGE_M = 2.0
LOST_AFTER_S = 2.0
"""No reliable LF fix for this long: the user is lost (emergency)."""
REMOTE_SPEED_MPS = 0.3
REMOTE_HOLD_S = 1.5
"""A gesture moves the robot for this long, then it stops and waits for the next."""
MASTER_SILENT_S = 1.0
"""A slave that hears no DriveState for this long stops (the master may be gone)."""
STATES = {"follow": RobotState.FOLLOWING, "lead": RobotState.LEADING, "remote": RobotState.REMOTE_CONTROL}
STEERED = (RobotState.FOLLOWING, RobotState.LEADING)
ACTIVITY_SPEED_MPS = {Movement.STOP: 0.0, Movement.REST: 0.4, Movement.WALK: 1.0, Movement.RUN: 2.5}
"""Typical speeds of the belt's movement classes, used until the LF distance gives a better one."""
MAX_USER_SPEED_MPS = 2.5
RATE_WINDOW_S = 1.0
"""Two fixes further apart than this do not make a rate (a burst was lost, or the robot turned round)."""
TURN_GAIN = 2.0
"""Turn-about: omega per radian still to turn (1/s), capped by the base's limit."""
TURN_DONE_RAD = math.radians(10)
FAR_MARGIN_M = 0.5
"""A dispersed master loses its user when the user is this much farther than the master's swarm distance
(a user who steps away, not the gap the formation kept); chosen as about one step."""


@dataclass
class DrivingConfig:
    """The user's formation choices and the controllers' settings."""

    shape: str = "column"
    spacing_m: float = 0.6
    pet: PetControllerConfig = field(default_factory=PetControllerConfig)
    slave: SlaveControllerConfig = field(default_factory=SlaveControllerConfig)


class Driver:
    """One robot's driving: its owner, its mode, its controller and (as master) the drive broadcast."""

    def __init__(
        self,
        robot_id: int,
        rf: RfCommunicationManager,
        sequence: SequenceManager,
        formation: NetworkFormation,
        locations: RelativeLocationManager,
        log: EventLog,
        config: DrivingConfig | None = None,
    ) -> None:
        self.robot_id = robot_id
        self.rf = rf
        self.radio = rf.radio
        self.sequence = sequence
        self.formation = formation
        self.locations = locations
        self.log = log
        self.config = config or DrivingConfig()
        self.lf = LfConfig()
        """The robot's calibration: the belt's datasheet curve."""
        self.owner: str | None = None
        self.fix: UserFix | None = None
        self.fix_at = -math.inf
        self.activity = Activity(Movement.STOP, False, 0.0, 0.0)
        self.command = MotorCommand()
        self.intent = MotorCommand()
        """What the controller wants before the safety stage: what the master broadcasts, so slaves ahead
        of it (leading) move on at the user's pace instead of waiting for a master they block."""
        self.mode = Mode.FOLLOWING
        self.shape = self.config.shape
        self.spacing = self.config.spacing_m
        self.mirrored = False
        self.kept: dict[int, Vec] | None = None
        """After a master handover (Table 3, Change): every robot's slot by short address in the current
        master's frame, each robot having kept its place. None: the references are the shape's slots."""
        self._announce_on_fix = False
        self._far_limit_m: float | None = None
        """After dispersing, the user distance beyond which the user is lost, until a fix inside the LF's
        valid range comes: a master keeps the formation's depth beyond 1 m (2.2 m leading a column of 3),
        and the robots it dispersed may stand between it and the user, so it may not close in at once."""
        self.exception_from: RobotState | None = None
        self.remote = MotorCommand()
        self.remote_until = 0.0
        self.drive_state: m.DriveState | None = None
        self.drive_state_at = -math.inf
        self.tracker = RelativeTracker()
        self._echoes = EchoRanges()
        self.opening_rate: float | None = None
        """How fast the LF distance to the user grows (m/s, smoothed over fixes)."""
        self.turn_to: float | None = None
        """AHRS yaw a turn-about is turning to."""
        self._fix_seen: float | None = None
        self._seq = 0
        self._last_control = clock.now()
        self.counters = {"wake_bursts": 0, "track_bursts": 0, "lf_fixes": 0, "lf_rejected": 0, "drive_states": 0}

    # -- tasks -----------------------------------------------------------------------------------

    def tasks(self) -> list[Any]:
        """The coroutines the robot runs for driving."""
        return [self._lf_loop(), self._ble_loop(), self._control_loop(), self._broadcast_loop()]

    async def _lf_loop(self) -> None:
        pattern = wake_pattern(self.robot_id)
        seq = 0
        while True:
            state = self.sequence.state
            seq = (seq + 1) & 0xFF
            if state == RobotState.WAITING and self.owner is None:
                self.counters["wake_bursts"] += 1
                self.radio.lf_burst("left", pattern, user_link.lf_data(self.robot_id, seq, user_link.LF_WAKE))
                await asyncio.sleep(WAKE_PERIOD_S)
            elif self.owner is not None and self._tracking(state):
                self.counters["track_bursts"] += 1
                data = user_link.lf_data(self.robot_id, seq, user_link.LF_TRACK)
                self.radio.lf_burst("left", pattern, data)
                await asyncio.sleep(0.005)  # the antennas fire in turn
                self.radio.lf_burst("right", pattern, data)
                await asyncio.sleep(TRACK_PERIOD_S - 0.005)
            else:
                await asyncio.sleep(TRACK_PERIOD_S)

    def _tracking(self, state: RobotState) -> bool:
        return state in (
            RobotState.FOLLOWING,
            RobotState.LEADING,
            RobotState.EMERGENCY,
            RobotState.MASTER_DRIVING,
            RobotState.REMOTE_CONTROL,
            RobotState.COMMAND_WAITING,
        ) or (state == RobotState.ORGANIZING and self.sequence.previous_driving is not None)

    async def _ble_loop(self) -> None:
        while True:
            message = await self.radio.ble_receive()
            try:
                body = user_link.decode(message.payload)
                await self._on_ble(message.src, body)
            except (ValueError, KeyError, TypeError, TransitionError, FormationError) as err:
                self.log.record("ble_refused", src=message.src, error=f"{type(err).__name__}: {err}")

    async def _on_ble(self, src: str, body: dict[str, Any]) -> None:
        kind = body["k"]
        if kind == "owner":
            self._on_owner(src, float(body["d"]))
        elif src != self.owner:
            self.log.record("ble_ignored", src=src, message=kind)  # only the owner's wearables count
        elif kind == "lf":
            self._on_lf(float(body["dl"]), float(body["dr"]))
        elif kind == "activity":
            self.activity = Activity.from_dict({k: v for k, v in body.items() if k not in ("k", "t")})
        elif kind == "request":
            await self._on_request(body)

    def _on_owner(self, src: str, distance: float) -> None:
        if self.owner is not None or self.sequence.state != RobotState.WAITING or distance > self.lf.wake_range_m:
            return
        self.owner = src
        self.formation.user = zlib.crc32(src.encode()) & 0xFFFF or 1
        self.sequence.transition(RobotState.COMMAND_WAITING, owner=src, distance=round(distance, 3))
        self._tell_owner()

    def _on_lf(self, d_left: float, d_right: float) -> None:
        fix = locate(d_left, d_right, self.lf, behind=self._user_behind())
        if fix is None:
            self.counters["lf_rejected"] += 1
            return
        self.counters["lf_fixes"] += 1
        now = clock.now()
        if self.fix is not None and 0 < now - self.fix_at < RATE_WINDOW_S:
            rate = (fix.distance_m - self.fix.distance_m) / (now - self.fix_at)
            self.opening_rate = rate if self.opening_rate is None else 0.5 * (self.opening_rate + rate)
        else:
            self.opening_rate = None
        self.fix, self.fix_at = fix, now
        if self._announce_on_fix:  # a new master's first fix: the belt has re-paired with us by now
            self._announce_on_fix = False
            self.log.record("owner_tracked", distance=round(fix.distance_m, 3), lf_fixes=self.counters["lf_fixes"])
            self._tell_owner()

    def _user_behind(self) -> bool:
        # leading: the user walks behind the robot (front/back is ambiguous for LF)
        state = self.sequence.state
        if state == RobotState.LEADING or (state == RobotState.REMOTE_CONTROL and self.exception_from):
            return True
        return state == RobotState.MASTER_DRIVING and self.mode == Mode.LEADING

    async def _on_request(self, body: dict[str, Any]) -> None:
        request = body["request"]
        self.log.record("watch_request", **{k: v for k, v in body.items() if k != "k"})
        state = self.sequence.state
        if request in STATES:
            self._select(STATES[request])
        elif request == "cancel" and state in (RobotState.FOLLOWING, RobotState.LEADING, RobotState.REMOTE_CONTROL):
            self.exception_from = None
            self.sequence.transition(RobotState.COMMAND_WAITING, cause="cancel")
        elif request == "return" and state == RobotState.REMOTE_CONTROL and self.exception_from is not None:
            back, self.exception_from = self.exception_from, None
            self.sequence.transition(back, cause="return")
        elif request == "gesture":
            self._on_gesture(Gesture(body["gesture"]))
        elif request == "organize":
            self.shape = str(body.get("shape", self.shape))
            self.spacing = float(body.get("spacing", self.spacing))
            asyncio.get_running_loop().create_task(self._organize(int(body.get("robots", 1))))
        elif request == "disperse":
            asyncio.get_running_loop().create_task(self._disperse())
        elif request == "mode":
            self._change_mode(Mode(body["mode"]), bool(body.get("change_master", False)))
        self._tell_owner()

    def _select(self, target: RobotState) -> None:
        state = self.sequence.state
        turning_round = state in (RobotState.FOLLOWING, RobotState.LEADING) and target in STEERED
        if state == RobotState.MASTER_DRIVING or turning_round:
            self._change_mode(Mode.LEADING if target == RobotState.LEADING else Mode.FOLLOWING, False)
            return
        self.mode = Mode.LEADING if target == RobotState.LEADING else Mode.FOLLOWING
        if state != target:
            self.sequence.transition(target, cause="watch")

    def _on_gesture(self, gesture: Gesture) -> None:
        if gesture == Gesture.CIRCLE:
            if self.sequence.state in (RobotState.FOLLOWING, RobotState.LEADING, RobotState.REMOTE_CONTROL):
                self.sequence.transition(RobotState.COMMAND_WAITING, cause="cancel")
            return
        vx_sign, vy_sign, turn_deg = combine([gesture])
        omega = math.radians(turn_deg) / REMOTE_HOLD_S
        self.remote = MotorCommand(vx_sign * REMOTE_SPEED_MPS, vy_sign * REMOTE_SPEED_MPS, omega)
        self.remote_until = clock.now() + REMOTE_HOLD_S

    def _change_mode(self, mode: Mode, change_master: bool) -> None:
        """Table 3 as the master applies it. No change: the master keeps its role and the slots are mirrored
        to its other side. Change (``change_master``): the robot ``mode_change`` chooses takes the master's
        role (``_hand_over``) and every robot keeps its place; when Table 3 chooses the master itself, or the
        handover fails, the No-change column applies."""
        if mode == self.mode:
            return
        self._start_turn_about()
        swarm = self.formation.swarm
        if self.sequence.state == RobotState.MASTER_DRIVING and swarm is not None:
            chain = (swarm.master, *swarm.members)
            layout = self._reference(chain, self.shape, self.spacing, self.mirrored, self.kept is not None)
            members = list(range(len(chain)))
            distances = self._user_distances(layout)
            outcome = mode_change(self.mode, mode, change_master, members, distances, layout)
            handing_over = change_master and outcome.new_master != 0
            self.log.record(
                "mode_change",
                frm=str(self.mode),
                to=str(mode),
                change_master_requested=change_master,
                table3_master=outcome.new_master,
                distances={str(chain[k]): round(d, 3) for k, d in distances.items()},
                applied="change" if handing_over else "no-change",
            )
            if handing_over:
                kept = kept_slots(dict(zip(chain, layout, strict=True)), chain[outcome.new_master])
                new_chain = handover_chain(kept, chain[outcome.new_master])
                asyncio.get_running_loop().create_task(self._hand_over(new_chain, mode))
            else:
                self.mirrored = not self.mirrored
            # dispersing restores the driving state the user has now chosen, not the one before the swarm
            self.sequence.previous_driving = RobotState.LEADING if mode == Mode.LEADING else RobotState.FOLLOWING
        else:
            self.log.record("mode_change", frm=str(self.mode), to=str(mode))
            target = RobotState.LEADING if mode == Mode.LEADING else RobotState.FOLLOWING
            if self.sequence.state in (RobotState.FOLLOWING, RobotState.LEADING):
                self.sequence.transition(target, cause="mode")
        self.mode = mode

    def _user_distances(self, layout: list[Vec]) -> dict[int, float]:
        """Each robot's distance to the user as the master estimates it: its slot in the master's frame
        against the user's position from the master's LF fix. The master has no fix of its slaves (IR fixes
        are each measuring robot's own), so it takes them at their slots; without an LF fix, the user is at
        the standard distance ahead (following) or behind (leading)."""
        if self.fix is not None:
            ux, uy = self.fix.forward_m, self.fix.left_m
        else:
            ux, uy = (STANDARD_DISTANCE_M if self.mode == Mode.FOLLOWING else -STANDARD_DISTANCE_M), 0.0
        return {k: math.hypot(x - ux, y - uy) for k, (x, y) in enumerate(layout)}

    async def _hand_over(self, chain: tuple[int, ...], mode: Mode) -> None:
        """The old master's side of Table 3's Change column; the formation does the radio part and calls
        ``on_handover`` back once the new master has accepted."""
        owner = self.owner or ""
        flags = int(self.mirrored), int(self.kept is not None)
        try:
            done = await self.formation.hand_over(chain, str(mode), self.shape, self.spacing, *flags, owner)
        except (FormationError, RadioError, HubUnavailable, TransitionError) as err:
            self.log.record("handover_refused", error=f"{type(err).__name__}: {err}")
            done = False
        if not done and self.sequence.state == RobotState.MASTER_DRIVING:
            self.mirrored = not self.mirrored  # the master keeps its role: Table 3's No-change column
            self.log.record("mode_change_fallback", applied="no-change")

    def on_handover(self, old_chain: tuple[int, ...], msg: m.MasterHandover | None) -> None:
        """The master's role moved (formation's callback): turn every slot into the new master's frame, each
        robot keeping its place; the new master takes the owner and the mode, the old one gives them up and
        re-pairs the user's belt with the new master (over BLE: the project's choice, the paper has none)."""
        swarm = self.formation.swarm
        if swarm is None:
            return
        ds = self.drive_state
        if msg is not None:
            shape, spacing, mirrored, kept = msg.shape, msg.spacing, bool(msg.mirrored), bool(msg.kept)
        elif ds is not None:
            shape, spacing, mirrored, kept = ds.shape, ds.spacing, bool(ds.mirrored), bool(ds.kept)
        else:
            shape, spacing, mirrored, kept = self.shape, self.spacing, self.mirrored, self.kept is not None
        old = dict(zip(old_chain, self._reference(old_chain, shape, spacing, mirrored, kept), strict=True))
        self.kept = kept_slots(old, swarm.master)
        self.mirrored = False
        self.shape, self.spacing = shape, spacing
        self.tracker, self._fix_seen, self.drive_state = RelativeTracker(), None, None
        if msg is not None:
            self.mode = Mode(msg.mode)
        if swarm.number == 0 and msg is not None:
            self.owner = msg.owner or None
            self.formation.user = zlib.crc32(msg.owner.encode()) & 0xFFFF or 1
            self.fix, self.opening_rate, self.exception_from = None, None, None
            self._start_turn_about()
            self._announce_on_fix = True
            self._tell_owner()
        elif swarm.number and self.owner is not None:
            self.radio.ble_send(self.owner, user_link.encode("pair", robot=swarm.master))
            self.log.record("owner_handed_over", owner=self.owner, to=swarm.master)
            self.owner, self.fix, self.turn_to, self.exception_from = None, None, None, None

    def _start_turn_about(self) -> None:
        """Following and leading face opposite ways relative to the user: a mode change that comes with
        the user's turn-about first turns the robot round (on its AHRS), and forgets its LF fix, which was
        taken with the user on the other side (LF cannot tell front from back)."""
        sensors = self.radio.sensors
        if sensors is None:
            return
        self.turn_to = wrap(sensors.yaw_rad + math.pi)
        self.log.record("turn_about", from_yaw=round(sensors.yaw_rad, 3), to_yaw=round(self.turn_to, 3))

    def _turning(self) -> MotorCommand | None:
        """The in-place turn of a turn-about, or None when there is none (any more)."""
        sensors = self.radio.sensors
        if self.turn_to is None or sensors is None:
            return None
        error = wrap(self.turn_to - sensors.yaw_rad)
        if abs(error) < TURN_DONE_RAD:
            self.turn_to, self.fix, self.fix_at, self.opening_rate = None, None, clock.now(), None
            self.log.record("turn_about_done")
            return None
        limit = self.config.pet.limits.max_omega
        return MotorCommand(0.0, 0.0, max(-limit, min(limit, TURN_GAIN * error)))

    async def _organize(self, count: int) -> None:
        self.kept = None
        try:
            result = await self.formation.organize(count)
            self.log.record("watch_organized", members=result.get("members"))
        except (FormationError, RadioError, HubUnavailable, TransitionError) as err:
            self.log.record("watch_organize_failed", error=str(err))
        self._tell_owner()

    async def _disperse(self) -> None:
        # The swarm's geometry, before it ends, and set before the dispersal: it restores the driving state
        # midway (then answers the members and moves PAN), and the control loop judges the user at once; set
        # after it, a user 2.4 m behind a leading master counted as lost in that gap (1 of 4 CI runs).
        self._far_limit_m = self._target_distance_of(self.mode) + FAR_MARGIN_M
        try:
            await self.formation.disperse()
        except (FormationError, RadioError, HubUnavailable, TransitionError) as err:
            self.log.record("watch_disperse_failed", error=str(err))
        self.mirrored, self.kept = False, None
        self._tell_owner()

    def _tell_owner(self) -> None:
        if self.owner is not None:
            self.radio.ble_send(self.owner, user_link.encode("state", state=self.sequence.state.label))

    # -- control ---------------------------------------------------------------------------------

    async def _control_loop(self) -> None:
        tick = 0
        while True:
            await asyncio.sleep(CONTROL_PERIOD_S)
            now = clock.now()
            dt, self._last_control = now - self._last_control, now
            self.command = self._decide(now, dt)
            self.radio.drive(self.command.vx, self.command.vy, self.command.omega)
            tick += 1
            if tick % 10 == 0:
                self._telemetry()

    def _decide(self, now: float, dt: float) -> MotorCommand:
        state = self.sequence.state
        ranges = self._ranges()
        self.intent = MotorCommand()
        if state == RobotState.SLAVE_DRIVING:
            return self._slave(now, dt, ranges)
        if state == RobotState.REMOTE_CONTROL:
            return safety(self.remote if now < self.remote_until else MotorCommand(), ranges, self.config.pet)
        if not self._tracking(state) or state in (RobotState.COMMAND_WAITING, RobotState.ORGANIZING):
            return MotorCommand()
        turn = self._turning()
        if turn is not None:
            self.intent = turn
            return turn
        observation = self._observation(now)
        if self._lost(now, state):
            return MotorCommand()
        if state == RobotState.EMERGENCY:
            return MotorCommand()
        leading = self._user_behind()
        target = self._target_distance() if state == RobotState.MASTER_DRIVING else None
        if leading and state == RobotState.LEADING and obstacle_ahead(ranges, self.config.pet):
            self.exception_from = state
            self.sequence.transition(RobotState.REMOTE_CONTROL, cause="obstacle ahead")
            self._tell_owner()
            return MotorCommand()
        control = lead if leading else follow
        self.intent = control(observation, Ranges(), self.config.pet, target)
        return safety(self.intent, ranges, self.config.pet)

    def _observation(self, now: float) -> UserObservation | None:
        if self.fix is None:
            return None
        activity = self.activity
        return UserObservation(
            distance_m=self.fix.distance_m,
            bearing_rad=self.fix.bearing_rad,
            user_speed_mps=self._user_speed(),
            rotating=activity.rotating,
            angular_speed_rps=activity.angular_speed_rps if activity.rotating else 0.0,
            age_s=max(0.0, now - self.fix_at),
        )

    def _user_speed(self) -> float:
        """The user's speed along the way: the robot's own (odometry) plus how fast the LF distance opens
        (following: the user ahead pulls away) or closes (leading: the user behind catches up). The belt's
        activity reports a walk only about 0.8 s after it begins; the distance shows it within two fixes.
        Without two recent fixes, the activity's typical speed."""
        sensors = self.radio.sensors
        if self.opening_rate is None or sensors is None:
            return ACTIVITY_SPEED_MPS[self.activity.movement]
        own = sensors.odometry[0]
        along = own - self.opening_rate if self._user_behind() else own + self.opening_rate
        return max(0.0, min(MAX_USER_SPEED_MPS, along))

    def _lost(self, now: float, state: RobotState) -> bool:
        """Emergency per the spec: no reliable LF fix for LOST_AFTER_S; back when one comes again."""
        # lost = too far (the LF fix's valid range is 2 m) or no fix at all; a user off the axis is not lost
        if self.fix is not None and self.fix.distance_m <= LF_VALID_RANGE_M:
            self._far_limit_m = None  # back inside the LF's valid range: the single robot's rule again
        limit = max(LF_VALID_RANGE_M, self._far_limit_m or 0.0)
        fresh = self.fix is not None and self.fix.distance_m <= limit and now - self.fix_at < LOST_AFTER_S
        if state in (RobotState.FOLLOWING, RobotState.LEADING) and not fresh and self.fix_at > -math.inf:
            self.exception_from = state
            self.sequence.transition(RobotState.EMERGENCY, cause="user lost")
            if self.owner is not None:
                self.radio.ble_send(self.owner, user_link.encode("alert", reason="user lost"))
            return True
        if state == RobotState.EMERGENCY and fresh:
            back, self.exception_from = self.exception_from or RobotState.FOLLOWING, None
            self.sequence.transition(back, cause="user found")
        return False

    def _target_distance(self) -> float:
        return self._target_distance_of(self.mode)

    def _target_distance_of(self, mode: Mode) -> float:
        swarm = self.formation.swarm
        chain = (self.formation.me,) if swarm is None else (swarm.master, *swarm.members)
        layout = self._reference(chain, self.shape, self.spacing, self.mirrored, self.kept is not None)
        return formation_distance(mode, layout)

    def _reference(self, chain: tuple[int, ...], shape: str, spacing: float, mirrored: bool, kept: bool) -> list[Vec]:
        """Every robot's slot in the master's frame, by member number: the robots' kept places after a
        handover (when this robot knows them all), else the shape's slots; mirrored by No-change."""
        if kept and self.kept is not None and all(a in self.kept for a in chain):
            layout = [self.kept[a] for a in chain]
        else:
            layout = slots(shape, len(chain), spacing)
        return [(-x, y) for x, y in layout] if mirrored else layout

    def _ranges(self) -> Ranges:
        sensors: OwnSensors | None = self.radio.sensors
        return Ranges() if sensors is None else self._echoes.ranges(sensors)

    # -- the swarm -------------------------------------------------------------------------------

    async def _broadcast_loop(self) -> None:
        while True:
            await asyncio.sleep(BROADCAST_PERIOD_S)
            swarm = self.formation.swarm
            # no owner found over LF (a master connected by the control channel's stand-in): nobody to
            # accompany, so the swarm holds still and slaves, hearing no DriveState, stay where they are
            if self.sequence.state != RobotState.MASTER_DRIVING or swarm is None or self.owner is None:
                continue
            self._seq += 1
            fix, activity, cmd = self.fix, self.activity, self.intent
            yaw = self.radio.sensors.yaw_rad if self.radio.sensors is not None else 0.0
            state = m.DriveState(
                swarm.session,
                self._seq & 0xFFFF,
                cmd.vx,
                cmd.vy,
                cmd.omega,
                yaw,
                int(activity.movement),
                activity.angular_speed_rps if activity.rotating else 0.0,
                str(self.mode),
                self.shape,
                self.spacing,
                0.0 if fix is None else fix.forward_m,
                0.0 if fix is None else fix.left_m,
                int(self.mirrored),
                int(self.kept is not None),
            )
            try:
                await self.rf.send(BROADCAST, state, ack=False)
            except (RadioError, HubUnavailable) as err:
                self.log.record("error", where="drive_state", error=str(err))

    @staticmethod
    def handles(message: m.SwarmMessage) -> bool:
        """True for the messages this manager takes."""
        return isinstance(message, m.DriveState)

    def on_message(self, incoming: Incoming) -> None:
        """A DriveState from our master."""
        swarm = self.formation.swarm
        msg = incoming.message
        if swarm is None or not isinstance(msg, m.DriveState) or msg.session != swarm.session:
            return
        if incoming.sender != swarm.master:
            return
        self.counters["drive_states"] += 1
        if (
            self.drive_state is None
            or msg.movement != self.drive_state.movement
            or (msg.user_rate != 0) != (self.drive_state.user_rate != 0)
        ):
            self.log.record("user_activity_heard", movement=msg.movement, user_rate=round(msg.user_rate, 3))
        self.drive_state, self.drive_state_at = msg, clock.now()

    def _slave(self, now: float, dt: float, ranges: Ranges) -> MotorCommand:
        swarm, state = self.formation.swarm, self.drive_state
        if swarm is None or state is None or now - self.drive_state_at > MASTER_SILENT_S:
            return MotorCommand()  # no word from the master: stop safely
        own_yaw = self.radio.sensors.yaw_rad if self.radio.sensors is not None else 0.0
        heading_rel = wrap(state.yaw - own_yaw)
        master_motion = MotorCommand(state.vx, state.vy, state.omega)
        entry = self.locations.table.get(swarm.master)
        if entry is not None and entry.fixed_at is not None and entry.fixed_at != self._fix_seen:
            self._fix_seen = entry.fixed_at
            assert entry.distance_m is not None and entry.bearing_rad is not None
            self.tracker.fix(RelativeFix(entry.distance_m, entry.bearing_rad, heading_rel, entry.fixed_at))
            self.tracker.predict(max(0.0, now - entry.fixed_at), self.command, master_motion)
        elif self.tracker.pose is not None:
            self.tracker.predict(dt, self.command, master_motion)
        if self.tracker.pose is None:
            return MotorCommand()
        pose = (self.tracker.pose[0], self.tracker.pose[1], heading_rel)
        chain = (swarm.master, *swarm.members)
        layout = self._reference(chain, state.shape, state.spacing, bool(state.mirrored), bool(state.kept))
        number = swarm.number
        near = neighbours(state.shape, number)
        neighbour_fix, neighbour_ref = None, None
        if near and near[0] != 0:
            other = self.locations.table.get(chain[near[0]])
            if other is not None and other.fixed_at is not None and other.distance_m is not None:
                neighbour_fix = RelativeFix(other.distance_m, other.bearing_rad or 0.0, None, other.fixed_at)
                neighbour_ref = layout[near[0]]
        decision = slave_decision(
            pose,
            neighbour_fix,
            layout[number],
            neighbour_ref,
            master_motion,
            state.mode,
            state.user_rate,
            self.config.slave,
            (state.user_x, state.user_y),
        )
        return safety(decision.command, ranges, self.config.pet)

    def _telemetry(self) -> None:
        swarm = self.formation.swarm
        state = self.sequence.state
        role, master, slot = "", "", None
        if swarm is None and self.owner is not None:
            role = "single"  # driving with its user, no swarm: the metrics' reaction counts it as the master
        if swarm is not None and state in (RobotState.MASTER_DRIVING, RobotState.SLAVE_DRIVING):
            role = "master" if swarm.number == 0 else "slave"
            master = user_link.robot_node(swarm.master)
            if role == "slave" and self.drive_state is not None:
                ds = self.drive_state
                chain = (swarm.master, *swarm.members)
                slot = self._reference(chain, ds.shape, ds.spacing, bool(ds.mirrored), bool(ds.kept))[swarm.number]
        try:
            self.radio.telemetry(state.label, role, master, slot, str(self.mode))
        except Exception as err:  # telemetry is for viewers: never let it stop the controller
            self.log.record("error", where="telemetry", error=str(err))


class EchoRanges:
    """The ultrasonic ring as the safety stage reads it: each echo's range and how fast it moves away."""

    def __init__(self) -> None:
        self._history: deque[OwnSensors] = deque(maxlen=6)

    def ranges(self, sensors: OwnSensors) -> Ranges:
        """The latest readings (nan = no echo) with their receding speeds."""
        readings = tuple(
            (a, None if math.isnan(r) else r)
            for a, r in zip(_floats(sensors.angles_rad), _floats(sensors.ranges_m), strict=True)
        )
        return Ranges(readings, receding_mps=self._receding(sensors))

    def _receding(self, sensors: OwnSensors) -> tuple[float, ...]:
        """Each echo's range rate over the last ~0.2 s (one 25 Hz step would turn 1 cm of ranging noise
        into 0.35 m/s) plus the robot's own speed along the beam."""
        history = self._history
        if not history or history[-1].t_us != sensors.t_us:
            history.append(sensors)
        oldest = history[0]
        dt = (sensors.t_us - oldest.t_us) / 1e6
        if dt < 0.1 or len(oldest.ranges_m) != len(sensors.ranges_m):
            return ()
        rates = (sensors.ranges_m - oldest.ranges_m) / dt
        vx, vy, _ = sensors.odometry
        own = vx * np.cos(sensors.angles_rad) + vy * np.sin(sensors.angles_rad)
        return tuple(0.0 if math.isnan(r) else r + o for r, o in zip(rates.tolist(), own.tolist(), strict=True))


def _floats(values: Any) -> list[float]:
    """A sequence of numbers as Python floats (one conversion for the whole array, not one per value)."""
    return np.asarray(values, dtype=float).tolist()
