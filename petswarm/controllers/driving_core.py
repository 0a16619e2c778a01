"""The driver's protocol logic as a sans-IO object: events with ``now`` in, actions out.

``DriverCore`` is everything ``petswarm.controllers.driving.Driver`` decides, with no clock, no sleeping, no radio and
no
zenoh in it (the h11 / aioquic shape): its entry points take an event and the time it happened, and what the
robot must do comes out as actions (``Drive``, ``LfBurst``, ``BleSend``, ``SendSwarm``, ``Organize``,
``Disperse``, ``HandOver``, ``SetUser``, ``Log``, ``Telemetry``). Its periodic work (LF bursts, the 20 Hz
control step, the master's 10 Hz ``DriveState``) runs on timers it keeps itself: ``next_timer()`` says when
it wants to be woken, ``handle_timer(now)`` runs what is due. Calls into the formation (organize, disperse,
hand over) are actions whose outcomes come back as events (``organized``, ``dispersed``, ``handed_over``).

Events:

- ``ble_message(src, payload, now)``: a BLE message from the wearables (owner, LF distances, activity,
  watch requests and gestures); malformed or refused ones are logged and dropped. The owner's, decoded,
  go on to ``lf_sample(d_left, d_right, now)``, ``user_request(body, now)`` and ``gesture(gesture, now)``,
  which a test may also call directly;
- ``sensors_sample(sensors, now)``: the robot's own AHRS, odometry and ultrasonic ring;
- ``drive_state(sender, message, now)``: a ``DriveState`` heard on the swarm's PAN;
- ``handover(old_chain, message, now)``: the formation moved the master's role;
- ``drive_state_sent(now, error)``, ``organized``, ``dispersed``, ``handed_over``: outcomes of actions.

The core reads, never writes, two neighbours' plain state: the formation's view of its swarm (``SwarmView``)
and the IR fix table (``FixTable``). It moves the robot through Fig. 4 on the shared ``SequenceManager``,
the same pure state machine the formation uses (a transition is refused there with ``TransitionError``).

Actions are collected in order and taken with ``actions()``; a runtime that passes ``on_action`` instead gets
each action as it is made, so what it records and sends keeps the order of the sequence manager's own
records (the run's digest depends on that order).
"""

from __future__ import annotations

import hashlib
import math
import zlib
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from petswarm.controllers.formation_shapes import (
    STANDARD_DISTANCE_M,
    Mode,
    handover_chain,
    kept_slots,
    mode_change,
    neighbours,
    slots,
)
from petswarm.controllers.formation_shapes import master_target_distance as formation_distance
from petswarm.controllers.motion import MotorCommand, Vec, wrap
from petswarm.controllers.pet_controller import (
    PetControllerConfig,
    Ranges,
    UserObservation,
    follow,
    lead,
    obstacle_ahead,
    safety,
)
from petswarm.controllers.side_check import ACTIVITY_LAG_S, UNSURE_SPEED_MPS, SideCheck
from petswarm.controllers.slave_controller import RelativeFix, RelativeTracker, SlaveControllerConfig, slave_decision
from petswarm.managers import messages as m
from petswarm.managers.actions import Log
from petswarm.managers.sequence import RobotState, SequenceManager, TransitionError
from petswarm.wearables import user_link
from petswarm.wearables.activity import Activity, Movement
from petswarm.wearables.gestures import Gesture, combine
from petswarm.wearables.lf_location import UserFix, locate
from radio_hub.datasheet import LfConfig, wake_pattern
from radio_hub.values import BROADCAST, OwnSensors, lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

WAKE_PERIOD_S = 3.0
TRACK_PERIOD_S = 0.35
ANTENNA_GAP_S = 0.005
"""A tracking burst fires the left antenna, then the right one this much later."""
CONTROL_PERIOD_S = 0.05
BROADCAST_PERIOD_S = 0.1
TELEMETRY_EVERY = 10
"""Control steps between telemetry messages (2 Hz)."""
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
LF, CONTROL, BROADCAST_TIMER = "lf", "control", "broadcast"
"""The core's timers, in the order ``handle_timer`` runs timers due at one instant (when set at one instant)."""


@dataclass
class DrivingConfig:
    """The user's formation choices and the controllers' settings."""

    shape: str = "column"
    spacing_m: float = 0.6
    pet: PetControllerConfig = field(default_factory=PetControllerConfig)
    slave: SlaveControllerConfig = field(default_factory=SlaveControllerConfig)


CHALLENGES_KEPT = 2
"""Wake bursts whose challenge an owner claim may echo: the latest, and the one before it (a reply to a burst can
arrive after the next one fired, 3 s later, only if BLE lags that long)."""


# -- what the core reads of its neighbours ----------------------------------------------------------


class SwarmInfo(Protocol):
    """The formation's view of the swarm this robot belongs to (``formation.Swarm``)."""

    session: int
    master: int
    number: int
    members: tuple[int, ...]


class SwarmView(Protocol):
    """What the core reads of the formation: the swarm (None outside one) and the robot's own address."""

    @property
    def swarm(self) -> SwarmInfo | None:
        """The robot's swarm, or None."""

    @property
    def me(self) -> int:
        """The robot's short address."""


class FixTable(Protocol):
    """The relative-location table: per short address an entry with ``distance_m``, ``bearing_rad`` and
    ``fixed_at`` (None until the first IR fix)."""

    @property
    def table(self) -> Mapping[int, Any]:
        """The entries by short address."""


# -- actions -----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Drive:
    """Command the motors."""

    command: MotorCommand


@dataclass(frozen=True)
class LfBurst:
    """Fire one LF burst from the ``left`` or ``right`` antenna."""

    antenna: str
    pattern: int
    data: bytes


@dataclass(frozen=True)
class BleSend:
    """A BLE message to the user's wearables (``user_link`` encoded)."""

    to: str
    payload: bytes


@dataclass(frozen=True)
class SendSwarm:
    """Put a swarm message on the air; its outcome comes back with ``drive_state_sent``."""

    dst: int
    message: m.SwarmMessage
    ack: bool


@dataclass(frozen=True)
class Organize:
    """Ask the formation to organize a swarm of ``count``; the outcome comes back with ``organized``."""

    count: int


@dataclass(frozen=True)
class Disperse:
    """Ask the formation to disperse the swarm; the outcome comes back with ``dispersed``."""


@dataclass(frozen=True)
class HandOver:
    """Ask the formation to hand the master's role over (Table 3, Change); back with ``handed_over``."""

    chain: tuple[int, ...]
    mode: str
    shape: str
    spacing: float
    mirrored: int
    kept: int
    owner: str


@dataclass(frozen=True)
class SetUser:
    """The formation's user id changes (the robot's owner, as it appears in scans)."""

    user: int


@dataclass(frozen=True)
class Telemetry:
    """What the robot believes, for viewers and metrics (never other robots)."""

    state: str
    role: str
    master: str
    slot: Vec | None
    mode: str


DriverAction = Drive | LfBurst | BleSend | SendSwarm | Organize | Disperse | HandOver | SetUser | Log | Telemetry


def user_id(owner: str) -> int:
    """The 16-bit user id a robot gives its owner's belt (never 0: 0 means no user)."""
    return zlib.crc32(owner.encode()) & 0xFFFF or 1


class DriverCore:
    """One robot's driving decisions: its owner, its mode, its controller and (as master) the drive broadcast."""

    def __init__(
        self,
        robot_id: int,
        sequence: SequenceManager,
        formation: SwarmView,
        locations: FixTable,
        now: float,
        config: DrivingConfig | None = None,
        on_action: Callable[[DriverAction], None] | None = None,
        pairing_seed: int = 0,
    ) -> None:
        self.robot_id = robot_id
        self._pairing_key = hashlib.blake2b(f"pairing/{pairing_seed}/{robot_id}".encode(), digest_size=16).digest()
        """What makes the wake bursts' challenges this robot's own (from the run's seed: no draw of any stream)."""
        self._challenges: deque[int] = deque(maxlen=CHALLENGES_KEPT)
        """The challenges of the latest wake bursts: an owner claim must echo one (it heard the LF within 1 m)."""
        self.unpaired = 0
        """BLE messages refused from a wearable this robot did not pair with: an owner claim that echoes no
        challenge of a recent wake burst, and anything but an owner claim from a user who is not the owner."""
        self.sequence = sequence
        self.formation = formation
        self.locations = locations
        self.config = config or DrivingConfig()
        self.on_action = on_action
        """None: actions wait in order for ``actions()``; else each goes there as it is made."""
        self._outbox: list[DriverAction] = []
        self.lf = LfConfig()
        """The robot's calibration: the belt's datasheet curve."""
        self.pattern = wake_pattern(robot_id)
        self.owner: str | None = None
        self.fix: UserFix | None = None
        self.fix_at = -math.inf
        self.reliable_at = -math.inf
        """When the robot last had a reliable LF fix (inside the valid range), or ended a turn-about."""
        self.activity = Activity(Movement.STOP, False, 0.0, 0.0)
        self.side = SideCheck()
        self._side_assumed = False
        self._side_refuted_at: float | None = None
        """Whether the user is on the side the mode assumes, checked by moving after the side was assumed."""
        self.sensors: OwnSensors | None = None
        """The latest own-body sample (AHRS yaw, odometry, ultrasonic ring)."""
        self.command = MotorCommand()
        self.intent = MotorCommand()
        """What the controller wants before the safety stage: what the master broadcasts, so slaves ahead
        of it (leading) move on at the user's pace instead of waiting for a master they block."""
        self.mode = Mode.FOLLOWING
        self.side_chosen = False
        """Whether the user chose following or leading since pairing: until then the robot stands as he placed
        it, and ``mode`` says nothing of which way it faces; after, it faces its user when following and away
        from him when leading, and every change between them is a turn-about."""
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
        self.drive_state_msg: m.DriveState | None = None
        self.drive_state_at = -math.inf
        self.tracker = RelativeTracker()
        self._echoes = EchoRanges(strict=True)
        self.opening_rate: float | None = None
        """How fast the LF distance to the user grows (m/s, smoothed over fixes)."""
        self.turn_to: float | None = None
        """AHRS yaw a turn-about is turning to."""
        self._fix_seen: float | None = None
        self._seq = 0
        self._lf_seq = 0
        self._lf_right: bytes | None = None
        """The data of a tracking burst whose right antenna is still to fire."""
        self._last_control = now
        self._ticks = 0
        self._timers: dict[str, tuple[float, int] | None] = {LF: None, CONTROL: None, BROADCAST_TIMER: None}
        """Per timer: (due, the order it was set in), so timers due at one instant run first set, first run."""
        self._timer_order = 0
        self.counters = {"wake_bursts": 0, "track_bursts": 0, "lf_fixes": 0, "lf_rejected": 0, "drive_states": 0}

    # -- actions and timers ----------------------------------------------------------------------

    def actions(self) -> list[DriverAction]:
        """The actions made since the last call, in order (empty when ``on_action`` takes them)."""
        out, self._outbox = self._outbox, []
        return out

    def start(self, now: float) -> None:
        """Start the periodic work: an LF burst at once, the control step and the broadcast one period on."""
        self._set_timer(LF, now)
        self._set_timer(CONTROL, now + CONTROL_PERIOD_S)
        self._set_timer(BROADCAST_TIMER, now + BROADCAST_PERIOD_S)

    def timer(self, name: str) -> float | None:
        """When timer ``name`` is due (None: not armed, e.g. the broadcast while its DriveState is in flight)."""
        entry = self._timers[name]
        return None if entry is None else entry[0]

    def next_timer(self) -> float | None:
        """When the core next wants ``handle_timer`` (None: nothing armed)."""
        due = [entry[0] for entry in self._timers.values() if entry is not None]
        return min(due, default=None)

    def handle_timer(self, now: float) -> None:
        """Run every timer due at ``now``, earliest first (at one instant, first set first)."""
        while True:
            due = [(entry, name) for name, entry in self._timers.items() if entry is not None and entry[0] <= now]
            if not due:
                return
            self.fire(min(due)[1], now)

    def fire(self, name: str, now: float) -> None:
        """Run timer ``name`` (a runtime with one waiter per timer calls this when that one is due)."""
        self._timers[name] = None
        if name == LF:
            self._lf_timer(now)
        elif name == CONTROL:
            self._control_timer(now)
        elif name == BROADCAST_TIMER:
            self._broadcast_timer(now)
        else:
            raise ValueError(f"no timer {name!r}")

    def _set_timer(self, name: str, when: float) -> None:
        self._timer_order += 1
        self._timers[name] = (when, self._timer_order)

    def _emit(self, action: DriverAction) -> None:
        if self.on_action is None:
            self._outbox.append(action)
        else:
            self.on_action(action)

    def _record(self, kind: str, **detail: Any) -> None:
        self._emit(Log(kind, detail))

    # -- LF --------------------------------------------------------------------------------------

    def _lf_timer(self, now: float) -> None:
        if self._lf_right is not None:  # the antennas fire in turn
            data, self._lf_right = self._lf_right, None
            self._emit(LfBurst("right", self.pattern, data))
            self._set_timer(LF, now + (TRACK_PERIOD_S - ANTENNA_GAP_S))
            return
        state = self.sequence.state
        self._lf_seq = (self._lf_seq + 1) & 0xFF
        if state == RobotState.WAITING and self.owner is None:
            self.counters["wake_bursts"] += 1
            challenge = self._challenge(self.counters["wake_bursts"])
            self._challenges.append(challenge)
            self._emit(LfBurst("left", self.pattern, user_link.lf_data(self.robot_id, challenge, user_link.LF_WAKE)))
            self._set_timer(LF, now + WAKE_PERIOD_S)
        elif self.owner is not None and self._tracking(state):
            self.counters["track_bursts"] += 1
            data = user_link.lf_data(self.robot_id, self._lf_seq, user_link.LF_TRACK)
            self._emit(LfBurst("left", self.pattern, data))
            self._lf_right = data
            self._set_timer(LF, now + ANTENNA_GAP_S)
        else:
            self._set_timer(LF, now + TRACK_PERIOD_S)

    def _tracking(self, state: RobotState) -> bool:
        return state in (
            RobotState.FOLLOWING,
            RobotState.LEADING,
            RobotState.EMERGENCY,
            RobotState.MASTER_DRIVING,
            RobotState.REMOTE_CONTROL,
            RobotState.COMMAND_WAITING,
        ) or (state == RobotState.ORGANIZING and self.sequence.previous_driving is not None)

    # -- the wearables ---------------------------------------------------------------------------

    def ble_message(self, src: str, payload: bytes, now: float) -> None:
        """A BLE message from ``src`` (a belt or a watch); bad or refused ones are logged and dropped."""
        try:
            self._on_ble(src, user_link.decode(payload), now)
        except (ValueError, KeyError, TypeError, TransitionError) as err:
            self._record("ble_refused", src=src, error=f"{type(err).__name__}: {err}")

    def sensors_sample(self, sensors: OwnSensors, now: float) -> None:
        """The robot's own body sensors (read by the next control step, the turn-about and the broadcast)."""
        self.sensors = sensors

    def _challenge(self, burst: int) -> int:
        """The sequence byte of wake burst number ``burst``: unpredictable without the robot's key, so only a belt
        that heard the burst (LF carries about 1 m) can echo it. The LF data section has 4 bytes, two of them the
        robot's id and one the purpose: this byte is the challenge (docs/SECURITY.md)."""
        return hashlib.blake2b(burst.to_bytes(8, "big"), key=self._pairing_key, digest_size=1).digest()[0]

    def _on_ble(self, src: str, body: dict[str, Any], now: float) -> None:
        kind = body["k"]
        if kind == "owner":
            self._on_owner(src, float(body["d"]), body.get("seq"))
        elif src != self.owner:
            self.unpaired += 1
            self._record("ble_ignored", src=src, message=kind)  # only the owner's wearables count
        elif kind == "lf":
            self.lf_sample(float(body["dl"]), float(body["dr"]), now)
        elif kind == "activity":
            self.activity = Activity.from_dict({k: v for k, v in body.items() if k not in ("k", "t")})
        elif kind == "request":
            self.user_request(body, now)

    def _on_owner(self, src: str, distance: float, echoed: Any) -> None:
        if self.owner is not None or self.sequence.state != RobotState.WAITING or distance > self.lf.wake_range_m:
            if src != self.owner:
                self.unpaired += 1
            return
        if echoed not in self._challenges:
            # a claim that heard no wake burst of ours: refused, and every pending challenge with it, so a guesser
            # gets one try per burst (one in 256) however many ids it sends from
            self.unpaired += 1
            self._challenges.clear()
            self._record("owner_refused", src=src)
            return
        self._challenges.clear()
        self.owner = src
        self._emit(SetUser(user_id(src)))
        self.sequence.transition(RobotState.COMMAND_WAITING, owner=src, distance=round(distance, 3))
        self._tell_owner()

    def lf_sample(self, d_left: float, d_right: float, now: float) -> None:
        """The owner's belt measured the two antennas' last bursts at these distances (m)."""
        fix = locate(d_left, d_right, self.lf, behind=self._user_behind())
        if fix is None:
            self.counters["lf_rejected"] += 1
            return
        self.counters["lf_fixes"] += 1
        if self.fix is not None and 0 < now - self.fix_at < RATE_WINDOW_S:
            rate = (fix.distance_m - self.fix.distance_m) / (now - self.fix_at)
            self.opening_rate = rate if self.opening_rate is None else 0.5 * (self.opening_rate + rate)
        else:
            self.opening_rate = None
        self.fix, self.fix_at = fix, now
        self._check_side(fix, now)
        if self._announce_on_fix:  # a new master's first fix: the belt has re-paired with us by now
            self._announce_on_fix = False
            self._record("owner_tracked", distance=round(fix.distance_m, 3), lf_fixes=self.counters["lf_fixes"])
            self._tell_owner()

    def _check_side(self, fix: UserFix, now: float) -> None:
        """A fix while the side is assumed: judged only while the user stands (then only the robot's motion
        changes the distance). A user found on the other side is put where the mode wants him by a turn-about,
        once the belt has had time to report a walk the verdict may have mistaken for the robot's own motion."""
        if not self.side.armed or self.sequence.state not in STEERED or self.turn_to is not None:
            return
        if self.activity.movement != Movement.STOP:  # (turning on the spot moves no belt)
            self.side.restart()
            return
        verdict = self.side.judge(fix)
        if verdict is not None:
            self._record("side_checked", confirmed=verdict, distance=round(fix.distance_m, 3))
        if verdict is False:
            self._side_refuted_at = now

    def _side_refuted(self, now: float) -> bool:
        """Whether a refuted side holds the robot still: until the belt could have reported a walk (then the
        verdict is dropped and the check starts over), then it turns round and checks again."""
        if self._side_refuted_at is None:
            return False
        if self.activity.movement != Movement.STOP:
            self._side_refuted_at = None
            self._record("side_check_dropped", reason="the user walks")
            self.side.arm(self.fix)
            return False
        if now - self._side_refuted_at < ACTIVITY_LAG_S:
            return True
        self._side_refuted_at = None
        self._side_assumed = True  # checked again once turned
        self._start_turn_about()
        return True

    def _user_behind(self) -> bool:
        # leading: the user walks behind the robot (front/back is ambiguous for LF)
        state = self.sequence.state
        if state == RobotState.LEADING or (state == RobotState.REMOTE_CONTROL and self.exception_from):
            return True
        return state == RobotState.MASTER_DRIVING and self.mode == Mode.LEADING

    def user_request(self, body: dict[str, Any], now: float) -> None:
        """A request from the owner's watch (``user_link``'s ``request`` map). Raises ``TransitionError``,
        ``ValueError`` or ``KeyError`` on one that Fig. 4 or the protocol refuses (``ble_message`` logs those)."""
        request = body["request"]
        self._record("watch_request", **{k: v for k, v in body.items() if k != "k"})
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
            self.gesture(Gesture(body["gesture"]), now)
        elif request == "organize":
            self.shape = str(body.get("shape", self.shape))
            self.spacing = float(body.get("spacing", self.spacing))
            self.kept = None
            self._emit(Organize(int(body.get("robots", 1))))
        elif request == "disperse":
            # The swarm's geometry, before it ends, and set before the dispersal: it restores the driving
            # state midway (then answers the members and moves PAN), and the control step judges the user at
            # once; set after it, a user 2.4 m behind a leading master counted as lost in that gap.
            self._far_limit_m = self._target_distance_of(self.mode) + FAR_MARGIN_M
            self._emit(Disperse())
        elif request == "mode":
            self._change_mode(Mode(body["mode"]), bool(body.get("change_master", False)))
        self._tell_owner()

    def _select(self, target: RobotState) -> None:
        state = self.sequence.state
        turning_round = state in (RobotState.FOLLOWING, RobotState.LEADING) and target in STEERED
        if state == RobotState.MASTER_DRIVING or turning_round:
            self._change_mode(Mode.LEADING if target == RobotState.LEADING else Mode.FOLLOWING, False)
            return
        if state != target:
            self.sequence.transition(target, cause="watch")  # refused: nothing else changes
        if target in STEERED:  # (remote control keeps the side the robot faces)
            self._change_side(Mode.LEADING if target == RobotState.LEADING else Mode.FOLLOWING)
            # chosen while the robot stood: the user may have walked round it meanwhile
            self._side_assumed = True
            if self.turn_to is None:
                self.side.arm(self.fix)

    def _change_side(self, mode: Mode) -> None:
        """Following or leading chosen outside a driving state (waiting for a command, remote control, an
        emergency): the robot faces its user in one, away in the other, so a change of side turns it round
        here too, as in ``_change_mode``; the first choice after pairing turns nothing (the robot stands as
        the user placed it)."""
        if self.side_chosen and mode != self.mode:
            self._start_turn_about()
            self._record("mode_change", frm=str(self.mode), to=str(mode))
        self.mode, self.side_chosen = mode, True

    def gesture(self, gesture: Gesture, now: float) -> None:
        """A watch gesture: in remote control it moves the robot for ``REMOTE_HOLD_S``; a circle cancels."""
        if gesture == Gesture.CIRCLE:
            if self.sequence.state in (RobotState.FOLLOWING, RobotState.LEADING, RobotState.REMOTE_CONTROL):
                self.sequence.transition(RobotState.COMMAND_WAITING, cause="cancel")
            return
        vx_sign, vy_sign, turn_deg = combine([gesture])
        omega = math.radians(turn_deg) / REMOTE_HOLD_S
        self.remote = MotorCommand(vx_sign * REMOTE_SPEED_MPS, vy_sign * REMOTE_SPEED_MPS, omega)
        self.remote_until = now + REMOTE_HOLD_S

    def _tell_owner(self) -> None:
        if self.owner is not None:
            self._emit(BleSend(self.owner, user_link.encode("state", state=self.sequence.state.label)))

    # -- Table 3 ---------------------------------------------------------------------------------

    def _change_mode(self, mode: Mode, change_master: bool) -> None:
        """Table 3 as the master applies it. No change: the master keeps its role and the slots are mirrored
        to its other side. Change (``change_master``): the robot ``mode_change`` chooses takes the master's
        role (a ``HandOver`` action) and every robot keeps its place; when Table 3 chooses the master itself,
        or the handover fails, the No-change column applies."""
        state = self.sequence.state
        if mode == self.mode or (not self.side_chosen and state == RobotState.COMMAND_WAITING):
            self.mode, self.side_chosen = mode, True  # (no side chosen yet: the robot stands as placed)
            return
        self._start_turn_about()
        swarm = self.formation.swarm
        target = RobotState.LEADING if mode == Mode.LEADING else RobotState.FOLLOWING
        if state == RobotState.MASTER_DRIVING and swarm is not None:
            self._change_swarm_mode(swarm, mode, change_master)
        else:
            self._record("mode_change", frm=str(self.mode), to=str(mode))
            if state in (RobotState.FOLLOWING, RobotState.LEADING):
                self.sequence.transition(target, cause="mode")
            elif self.exception_from is not None:  # remote control or an emergency: "return" / "user found"
                self.exception_from = target  # comes back to the side the robot now faces
        self.mode, self.side_chosen = mode, True

    def _change_swarm_mode(self, swarm: SwarmInfo, mode: Mode, change_master: bool) -> None:
        chain = (swarm.master, *swarm.members)
        layout = self._reference(chain, self.shape, self.spacing, self.mirrored, self.kept is not None)
        distances = self._user_distances(layout)
        outcome = mode_change(self.mode, mode, change_master, list(range(len(chain))), distances, layout)
        handing_over = change_master and outcome.new_master != 0
        self._record(
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
            flags = int(self.mirrored), int(self.kept is not None)
            self._emit(HandOver(new_chain, str(mode), self.shape, self.spacing, *flags, self.owner or ""))
        else:
            self.mirrored = not self.mirrored
        # dispersing restores the driving state the user has now chosen, not the one before the swarm
        self.sequence.previous_driving = RobotState.LEADING if mode == Mode.LEADING else RobotState.FOLLOWING

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

    def handover(self, old_chain: tuple[int, ...], msg: m.MasterHandover | None, now: float) -> None:
        """The master's role moved (the formation's notification): turn every slot into the new master's
        frame, each robot keeping its place; the new master takes the owner and the mode, the old one gives
        them up and re-pairs the user's belt with the new master (over BLE: the project's choice, the paper
        has none)."""
        swarm = self.formation.swarm
        if swarm is None:
            return
        ds = self.drive_state_msg
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
        self.tracker, self._fix_seen, self.drive_state_msg = RelativeTracker(), None, None
        if msg is not None:
            self.mode, self.side_chosen = Mode(msg.mode), True
        if swarm.number == 0 and msg is not None:
            self.owner = msg.owner or None
            self._emit(SetUser(user_id(msg.owner)))
            self.fix, self.opening_rate, self.exception_from = None, None, None
            self._start_turn_about()
            self._announce_on_fix = True
            self._tell_owner()
        elif swarm.number and self.owner is not None:
            self._emit(BleSend(self.owner, user_link.encode("pair", robot=swarm.master)))
            self._record("owner_handed_over", owner=self.owner, to=swarm.master)
            self.owner, self.fix, self.turn_to, self.exception_from = None, None, None, None

    def _start_turn_about(self) -> None:
        """Following and leading face opposite ways relative to the user: a mode change that comes with
        the user's turn-about first turns the robot round (on its AHRS), and forgets its LF fix, which was
        taken with the user on the other side (LF cannot tell front from back)."""
        sensors = self.sensors
        if sensors is None:
            return
        self.turn_to = wrap(sensors.yaw_rad + math.pi)
        self._record("turn_about", from_yaw=round(sensors.yaw_rad, 3), to_yaw=round(self.turn_to, 3))

    def _turning(self, now: float) -> MotorCommand | None:
        """The in-place turn of a turn-about, or None when there is none (any more)."""
        sensors = self.sensors
        if self.turn_to is None or sensors is None:
            return None
        error = wrap(self.turn_to - sensors.yaw_rad)
        if abs(error) < TURN_DONE_RAD:
            self.turn_to, self.fix, self.fix_at, self.opening_rate = None, None, now, None
            if self._side_assumed:
                self.side.arm(self.fix)
            self.reliable_at = now  # the lost-user time runs from here for the first fix facing the new way
            self._record("turn_about_done")
            return None
        limit = self.config.pet.limits.max_omega
        return MotorCommand(0.0, 0.0, max(-limit, min(limit, TURN_GAIN * error)))

    # -- outcomes of the formation's work --------------------------------------------------------

    def organized(self, members: Any, error: str | None, now: float) -> None:
        """The organize the core asked for ended: ``members`` as the formation answered, or ``error``."""
        if error is None:
            self._record("watch_organized", members=members)
        else:
            self._record("watch_organize_failed", error=error)
        self._tell_owner()

    def dispersed(self, error: str | None, now: float) -> None:
        """The dispersal the core asked for ended (``error``: it failed)."""
        if error is not None:
            self._record("watch_disperse_failed", error=error)
        self.mirrored, self.kept = False, None
        self._tell_owner()

    def handed_over(self, done: bool, error: str | None, now: float) -> None:
        """The handover the core asked for ended: ``done`` when the new master accepted; else, still master,
        Table 3's No-change column applies."""
        if error is not None:
            self._record("handover_refused", error=error)
        if not done and self.sequence.state == RobotState.MASTER_DRIVING:
            self.mirrored = not self.mirrored
            self._record("mode_change_fallback", applied="no-change")

    # -- control ---------------------------------------------------------------------------------

    def _control_timer(self, now: float) -> None:
        dt, self._last_control = now - self._last_control, now
        self.command = self._decide(now, dt)
        self._emit(Drive(self.command))
        self._set_timer(CONTROL, now + CONTROL_PERIOD_S)
        self._ticks += 1
        if self._ticks % TELEMETRY_EVERY == 0:
            self._emit(self._telemetry())

    def _decide(self, now: float, dt: float) -> MotorCommand:
        state = self.sequence.state
        if self.sensors is not None:  # the echoes' history grows every tick, read or not
            self._echoes.observe(self.sensors)
        self.intent = MotorCommand()
        if state == RobotState.SLAVE_DRIVING:
            return self._slave(now, dt, self._ranges())
        if state in (RobotState.REMOTE_CONTROL, RobotState.COMMAND_WAITING):
            turn = self._turning(now)  # a change of side asked for here turns the robot round at once
            if turn is not None:
                self.intent = turn
                return turn
        if state == RobotState.REMOTE_CONTROL:
            return safety(self.remote if now < self.remote_until else MotorCommand(), self._ranges(), self.config.pet)
        if not self._tracking(state) or state in (RobotState.COMMAND_WAITING, RobotState.ORGANIZING):
            return MotorCommand()
        turn = self._turning(now)
        if turn is not None:
            self.intent = turn
            return turn
        if state in STEERED and self._side_refuted(now):
            return MotorCommand()
        if self.sensors is not None and state in STEERED:
            self.side.moved(float(self.sensors.odometry[0]), float(self.sensors.odometry[1]), self.fix, dt)
        observation = self._observation(now)
        if self._lost(now, state):
            return MotorCommand()
        if state == RobotState.EMERGENCY:
            return MotorCommand()
        ranges = self._ranges()  # read only when driving: an idle robot computes no arrays (issue 13)
        leading = self._user_behind()
        target = self._target_distance_of(self.mode) if state == RobotState.MASTER_DRIVING else None
        if leading and state == RobotState.LEADING and obstacle_ahead(ranges, self.config.pet):
            self.exception_from = state
            self.sequence.transition(RobotState.REMOTE_CONTROL, cause="obstacle ahead")
            self._tell_owner()
            return MotorCommand()
        control = lead if leading else follow
        self.intent = control(observation, Ranges(), self.config.pet, target)
        if self.side.armed and state in STEERED and self.activity.movement == Movement.STOP:
            self.intent = _capped(self.intent, UNSURE_SPEED_MPS)  # not sure of the user's side: slowly
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
        sensors = self.sensors
        if self.opening_rate is None or sensors is None:
            return ACTIVITY_SPEED_MPS[self.activity.movement]
        own = sensors.odometry[0]
        along = own - self.opening_rate if self._user_behind() else own + self.opening_rate
        return max(0.0, min(MAX_USER_SPEED_MPS, along))

    def _lost(self, now: float, state: RobotState) -> bool:
        """Emergency per the spec: no reliable LF fix for LOST_AFTER_S; back when one comes again."""
        # lost = too far (the LF fix's valid range is 2 m) or no fix at all, for LOST_AFTER_S; a user off the axis
        # is not lost, and neither is one a fix or two puts just outside the range (a robot that overshot as its
        # user stopped drives back meanwhile)
        if self.fix is not None and self.fix.distance_m <= LF_VALID_RANGE_M:
            self._far_limit_m = None  # back inside the LF's valid range: the single robot's rule again
        limit = max(LF_VALID_RANGE_M, self._far_limit_m or 0.0)
        reliable = self.fix is not None and self.fix.distance_m <= limit
        if reliable:
            self.reliable_at = max(self.reliable_at, self.fix_at)
        fresh = now - self.reliable_at < LOST_AFTER_S
        if state in (RobotState.FOLLOWING, RobotState.LEADING) and not fresh and self.fix_at > -math.inf:
            self.exception_from = state
            self.sequence.transition(RobotState.EMERGENCY, cause="user lost")
            if self.owner is not None:
                self._emit(BleSend(self.owner, user_link.encode("alert", reason="user lost")))
            return True
        if state == RobotState.EMERGENCY and reliable and fresh:  # found only by a fix
            back, self.exception_from = self.exception_from or RobotState.FOLLOWING, None
            self.sequence.transition(back, cause="user found")
        return False

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
        return Ranges() if self.sensors is None else self._echoes.ranges(self.sensors)

    # -- the swarm -------------------------------------------------------------------------------

    def _broadcast_timer(self, now: float) -> None:
        swarm = self.formation.swarm
        # no owner found over LF (a master connected by the control channel's stand-in): nobody to
        # accompany, so the swarm holds still and slaves, hearing no DriveState, stay where they are
        if self.sequence.state != RobotState.MASTER_DRIVING or swarm is None or self.owner is None:
            self._set_timer(BROADCAST_TIMER, now + BROADCAST_PERIOD_S)
            return
        self._seq += 1
        fix, activity, cmd = self.fix, self.activity, self.intent
        yaw = self.sensors.yaw_rad if self.sensors is not None else 0.0
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
        self._emit(SendSwarm(BROADCAST, state, ack=False))  # the next one a period after this one has left

    def drive_state_sent(self, now: float, error: str | None = None) -> None:
        """The DriveState the broadcast timer sent has left (or failed: ``error``); the next is due a period on."""
        if error is not None:
            self._record("error", where="drive_state", error=error)
        self._set_timer(BROADCAST_TIMER, now + BROADCAST_PERIOD_S)

    def drive_state(self, sender: int, msg: m.SwarmMessage, now: float) -> None:
        """A DriveState heard on the air; only our master's, of our session, counts."""
        swarm = self.formation.swarm
        if swarm is None or not isinstance(msg, m.DriveState) or msg.session != swarm.session:
            return
        if sender != swarm.master:
            return
        self.counters["drive_states"] += 1
        last = self.drive_state_msg
        if last is None or msg.movement != last.movement or (msg.user_rate != 0) != (last.user_rate != 0):
            self._record("user_activity_heard", movement=msg.movement, user_rate=round(msg.user_rate, 3))
        self.drive_state_msg, self.drive_state_at = msg, now

    def _slave(self, now: float, dt: float, ranges: Ranges) -> MotorCommand:
        swarm, state = self.formation.swarm, self.drive_state_msg
        if swarm is None or state is None or now - self.drive_state_at > MASTER_SILENT_S:
            return MotorCommand()  # no word from the master: stop safely
        own_yaw = self.sensors.yaw_rad if self.sensors is not None else 0.0
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
        chain = (swarm.master, *swarm.members)
        number = swarm.number
        if number >= len(chain):
            # the JoinNotice gave our number but no roster has come yet (lost): without the members before us
            # neither our slot nor our neighbour is known, so hold still until the next roster (every 0.25 s)
            return MotorCommand()
        pose = (self.tracker.pose[0], self.tracker.pose[1], heading_rel)
        layout = self._reference(chain, state.shape, state.spacing, bool(state.mirrored), bool(state.kept))
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

    def _telemetry(self) -> Telemetry:
        swarm = self.formation.swarm
        state = self.sequence.state
        role, master, slot = "", "", None
        if swarm is None and self.owner is not None:
            role = "single"  # driving with its user, no swarm: the metrics' reaction counts it as the master
        if swarm is not None and state in (RobotState.MASTER_DRIVING, RobotState.SLAVE_DRIVING):
            role = "master" if swarm.number == 0 else "slave"
            master = user_link.robot_node(swarm.master)
            chain = (swarm.master, *swarm.members)
            if role == "slave" and self.drive_state_msg is not None and swarm.number < len(chain):
                ds = self.drive_state_msg
                slot = self._reference(chain, ds.shape, ds.spacing, bool(ds.mirrored), bool(ds.kept))[swarm.number]
        return Telemetry(state.label, role, master, slot, str(self.mode))


class EchoRanges:
    """The ultrasonic ring as the safety stage reads it: each echo's range and how fast it moves away.

    In plain floats: a ring is eight sensors, read on every control step, where numpy's per-call overhead
    is most of the cost (the same IEEE operations in the same order, so the same bits as the arrays gave)."""

    def __init__(self, strict: bool = False) -> None:
        self.strict = strict
        """Range rates as the driving law reads them: unknown over a turn wider than a cone's half-width
        (``RATE_TURN_RAD``), and inside the stop distance not counted below the noise (``RATE_NOISE_M``). The
        surround laws keep the plain rates their figures were measured with (their robots stand closer than the
        stop distance to their neighbours, where the noise rule tore the paper's swarm)."""
        self._history: deque[list[Any]] = deque(maxlen=6)
        """[t_us, sensors, ranges as floats (None until first read)] of the latest samples: a robot that only
        drives in formation keeps them without reading them (and so without importing numpy)."""
        self._ring: Any = None
        self._ring_trig: tuple[list[float], list[float], list[float]] = ([], [], [])

    def ranges(self, sensors: OwnSensors) -> Ranges:
        """The latest readings (nan = no echo) with their receding speeds."""
        angles, ranges, receding = self.floats(sensors)
        readings = tuple((a, None if math.isnan(r) else r) for a, r in zip(angles, ranges, strict=True))
        return Ranges(readings, receding_mps=receding)

    def floats(
        self, sensors: OwnSensors, ranges: list[float] | None = None
    ) -> tuple[list[float], list[float], tuple[float, ...]]:
        """What ``ranges`` reads, in plain floats: the ring's angles, the latest ranges (nan = no echo) and their
        receding speeds (empty when unknown), for ``pet_controller.SafetyStage``. ``ranges``: ``sensors``'
        ranges as floats when the caller has them already (``sensors.ranges_m.tolist()``)."""
        self.observe(sensors, ranges)
        ranges = _ranges_of(self._history[-1])
        angles, cos, sin = self._trig(sensors.angles_rad)
        return angles, ranges, self._receding(sensors, ranges, cos, sin)

    @staticmethod
    def floats_all(
        rings: list[EchoRanges], samples: list[OwnSensors], ranges: list[list[float]]
    ) -> tuple[list[list[float]], np.ndarray, np.ndarray, np.ndarray]:
        """``floats`` of many robots' rings (all of one size) at once, bit for bit as each alone: their angles,
        latest ranges (n, s), receding speeds (n, s) and whether each robot has them (n,)."""
        angles, latest, oldest, spans, cos, sin, velocity, known, lags = [], [], [], [], [], [], [], [], []
        for ring, sensors, given in zip(rings, samples, ranges, strict=True):
            ring.observe(sensors, given)
            now = _ranges_of(ring._history[-1])
            ring_angles, ring_cos, ring_sin = ring._trig(sensors.angles_rad)
            first = ring._history[0]
            span = (sensors.t_us - first[0]) / 1e6
            old = _ranges_of(first) if span >= 0.1 else now
            angles.append(ring_angles)
            latest.append(now)
            known.append(span >= 0.1 and len(old) == len(now) and (not ring.strict or _steady(first[1], sensors)))
            oldest.append(old if known[-1] else now)
            spans.append(span if known[-1] else 1.0)
            lags.append(_braking_lag(span, len(ring._history)) if ring.strict and known[-1] else 0.0)
            cos.append(ring_cos)
            sin.append(ring_sin)
            velocity.append(_own_velocity(first[1], sensors, ring.strict))
        now_m, old_m, moving = np.array(latest), np.array(oldest), np.array(velocity, dtype=float)
        rate = (now_m - old_m) / np.array(spans)[:, None]
        along = moving[:, 0:1] * np.array(cos) + moving[:, 1:2] * np.array(sin)
        away = np.where(np.isnan(rate), 0.0, rate + along - np.array(lags)[:, None])
        strict = np.array([ring.strict for ring in rings])[:, None]
        counted = ~strict | (away > RATE_NOISE_M / np.array(spans)[:, None]) | (now_m > STOP_DISTANCE_M)
        receding = np.where(counted, away, 0.0)
        return angles, now_m, receding, np.array(known)

    def holds(self, t_us: int) -> bool:
        """Whether the latest sample kept is of ``t_us``: ``observe`` would not take another of that instant, and
        ``floats`` would read the one held (a hub whose clock went back and on again)."""
        history = self._history
        return bool(history) and history[-1][0] == t_us

    def observe(self, sensors: OwnSensors, ranges: list[float] | None = None) -> None:
        """Keep ``sensors`` in the history the range rates are taken over (once per sample); ``ranges``: its
        ranges as floats, if the caller has them."""
        history = self._history
        if not history or history[-1][0] != sensors.t_us:
            history.append([sensors.t_us, sensors, ranges])

    def _trig(self, angles_rad: Any) -> tuple[list[float], list[float], list[float]]:
        """The ring's angles, their cosines and sines, worked out again only when the ring changes."""
        if self._ring is not angles_rad:
            self._ring = angles_rad
            angles = np.asarray(angles_rad, dtype=float)
            self._ring_trig = (angles.tolist(), np.cos(angles).tolist(), np.sin(angles).tolist())
        return self._ring_trig

    def _receding(
        self, sensors: OwnSensors, ranges: list[float], cos: list[float], sin: list[float]
    ) -> tuple[float, ...]:
        """Each echo's range rate over the last ~0.2 s (one 25 Hz step would turn 1 cm of ranging noise
        into 0.35 m/s) plus the robot's own speed along the beam."""
        first = self._history[0]
        dt = (sensors.t_us - first[0]) / 1e6
        if dt < 0.1 or (self.strict and not _steady(first[1], sensors)):
            return ()
        oldest = _ranges_of(first)
        if len(oldest) != len(ranges):
            return ()
        vx, vy = _own_velocity(first[1], sensors, self.strict)
        lag = _braking_lag(dt, len(self._history)) if self.strict else 0.0
        receding = []
        for r, o, c, s in zip(ranges, oldest, cos, sin, strict=True):
            rate = (r - o) / dt
            away = 0.0 if math.isnan(rate) else rate + (vx * c + vy * s) - lag
            receding.append(away if not self.strict or away > RATE_NOISE_M / dt or r > STOP_DISTANCE_M else 0.0)
        return tuple(receding)


RATE_NOISE_M = 0.04
"""What two ranges of one still echo may differ by through noise alone: three sigma of the difference of two
readings of an HC-SR04-like sensor (1 cm each, ``WorldConfig.ultrasonic_noise_m``: 1.4 cm). An echo counts as
receding (the safety stage then lets a robot follow it) only faster than that over the rate's span (0.2 m/s over
0.2 s): a robot 1 cm from a standing one read it receding at 0.1 m/s from noise and drove into it (seed 1 case
193); a leader driving on is followed as before."""
STOP_DISTANCE_M = PetControllerConfig().stop_distance_m
"""Inside it only an echo's receding speed lets the safety stage move a robot toward it: there, and only there,
a receding speed noise could fake is not counted."""
RATE_TURN_RAD = math.radians(15.0)
"""A ring that turned more than this (an ultrasonic cone's half-width) between two samples points each beam at
another patch: the range's change then compares two echoes, not one echo's motion, and says nothing of how fast
an obstacle moves away (a robot turning on the spot saw the user it left as a robot receding at its own speed)."""


LEADER_BRAKE_MPS2 = 2.0
"""The hardest a Pet-Bot ahead can brake: its base's ramp (the motor controller's 2 m/s^2), reached by a robot
whose command drops to zero at once (dispersed, stopped by its watchdog)."""


def _braking_lag(span_s: float, samples: int) -> float:
    """What to take off a range rate's receding speed (m/s) so it bounds the echo's speed now from below: a rate over
    ``span_s`` is the echo's mean speed then, at most ``LEADER_BRAKE_MPS2 * span_s / 2`` above its speed at the
    latest reading whatever its braking, and the robot acts up to one ring period (``span_s / (samples - 1)``)
    after that reading. (A follower that took the mean for the speed drove at a braking robot's speed of 0.2 s
    before and ran into it: seed 2 case 84.)"""
    return LEADER_BRAKE_MPS2 * (span_s / 2 + span_s / max(1, samples - 1))


def _own_velocity(before: OwnSensors, now: OwnSensors, strict: bool) -> tuple[float, float]:
    """The robot's own velocity (vx, vy) to add to a range rate taken from ``before`` to ``now``: the span's mean
    (odometry's two ends; exact at a constant acceleration) for a strict ring, the latest for the others. A range
    rate is an average over the span, so adding the latest speed of a robot that sped up credits the echo with the
    speed gained: a slave accelerating to 1.1 m/s behind a braking master read it receding at 1.1 m/s, not 0.5
    (seed 1 case 117)."""
    vx, vy = float(now.odometry[0]), float(now.odometry[1])
    if not strict:
        return vx, vy
    return 0.5 * (vx + float(before.odometry[0])), 0.5 * (vy + float(before.odometry[1]))


def _steady(before: OwnSensors, now: OwnSensors) -> bool:
    """Whether the ring turned little enough between two samples for its range rates to mean motion."""
    return abs(wrap(now.yaw_rad - before.yaw_rad)) <= RATE_TURN_RAD


def _ranges_of(sample: list[Any]) -> list[float]:
    """A history entry's ranges as floats, converted once."""
    if sample[2] is None:
        sample[2] = _floats(sample[1].ranges_m)
    return sample[2]


def _floats(values: Any) -> list[float]:
    """A sequence of numbers as Python floats (one conversion for the whole array, not one per value)."""
    return np.asarray(values, dtype=float).tolist()


def _capped(command: MotorCommand, speed: float) -> MotorCommand:
    """``command`` with its translation scaled down to at most ``speed`` (m/s); the turn kept."""
    now = math.hypot(command.vx, command.vy)
    if now <= speed:
        return command
    return MotorCommand(command.vx * speed / now, command.vy * speed / now, command.omega)
