"""The single Pet-Bot's controller (pet-bot-wearable spec, "Controller"), also the swarm master's.

Three stages, pure functions of the latest observation (time is in the observation's age):
1. distance/speed, like adaptive cruise control: near the target distance the robot matches the user's
   speed with a soft gap correction; far from it, a stiffer gain closes the gap;
2. direction: following turns (omega) to keep the user inside the LF field of view; leading drives an arc
   round the user when the user rotates, and side-steps (vy) when the user drifts out without rotating;
3. safety: slow down and stop before obstacles the ultrasonic sensors see ahead, bound every speed.
Frames and units per issue 5: robot frame x forward, y left; bearings CCW from the robot's heading.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from petswarm.controllers.motion import STOP, DriveLimits, MotorCommand, wrap
from radio_hub.values import lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

SENSOR_ANGLES_RAD = (math.radians(-30), 0.0, math.radians(30))
"""Default ultrasonic sensors ahead: a fan of three, 30 degrees apart (the paper shows them, not the angles)."""


@dataclass(frozen=True)
class PetControllerConfig:
    """Gains and distances of the controller. The paper gives the 1 m target and the +-25 degree field of view;
    the rest are the project's choices, each with its reason."""

    target_distance_m: float = 1.0
    fov_rad: float = math.radians(25)
    near_band_m: float = 0.4
    """Gap error (m) below which the distance stage matches speed: the LF fix scatters about 0.1 m, and the
    controller must not chase that scatter."""
    k_near: float = 0.5
    """Gap gain inside the band (1/s): a 0.2 m error adds 0.1 m/s to the user's speed."""
    k_far: float = 1.2
    """Gap gain outside the band (1/s): a 1 m gap closes at max speed less a walk, in about a second."""
    max_reverse_mps: float = 0.4
    """Backing off from a user who comes too close: slow, as the robot cannot see behind itself."""
    k_bearing: float = 1.5
    """Following: omega per radian of user bearing (1/s); doubled outside the field of view."""
    side_step_deadband_rad: float = math.radians(8)
    """Leading: the user's angle off the robot's back axis tolerated before side-stepping; well inside the
    field of view so the user never leaves it."""
    k_side: float = 1.2
    """Leading side-step gain (1/s) on the user's lateral offset."""
    max_age_s: float = 1.05
    """An observation older than three LF periods (350 ms) is stale: stop rather than steer on it."""
    stop_distance_m: float = 0.25
    """Range (from the sensor face at the rim) at which the robot has stopped before an obstacle."""
    k_approach: float = 1.5
    """Closing-speed gain (1/s) toward an obstacle: speed = k * (range - stop distance)..."""
    brake_decel_mps2: float = 1.0
    """...and never more than braking at this deceleration allows (below max_accel, so the base can do it)."""
    obstacle_distance_m: float = 0.6
    """Leading mode's exception: an obstacle this near ahead hands control to the user (remote control)."""
    obstacle_cone_rad: float = math.radians(30)
    """Sensors within this angle of the heading count for the leading exception."""
    limits: DriveLimits = field(default_factory=DriveLimits)

    def __post_init__(self) -> None:
        positive = ("target_distance_m", "fov_rad", "near_band_m", "k_near", "k_far", "k_bearing", "k_side")
        positive += ("max_age_s", "k_approach", "brake_decel_mps2", "obstacle_distance_m", "obstacle_cone_rad")
        for name in positive:
            if not getattr(self, name) > 0:
                raise ValueError(f"PetControllerConfig.{name} must be positive, got {getattr(self, name)!r}")
        for name in ("max_reverse_mps", "side_step_deadband_rad", "stop_distance_m"):
            if getattr(self, name) < 0:
                raise ValueError(f"PetControllerConfig.{name} must not be negative, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class UserObservation:
    """The user as the robot knows them: position in the robot frame from LF, motion from the belt's activity.

    ``angular_speed_rps`` is the belt gyro's yaw rate in rad/s, counter-clockwise positive; ``rotating`` the
    belt's rotation state; ``age_s`` how old the LF fix is.
    """

    distance_m: float
    bearing_rad: float
    user_speed_mps: float = 0.0
    rotating: bool = False
    angular_speed_rps: float = 0.0
    age_s: float = 0.0

    def __post_init__(self) -> None:
        if not self.distance_m >= 0:
            raise ValueError(f"UserObservation.distance_m must not be negative, got {self.distance_m!r}")
        if not self.user_speed_mps >= 0:
            raise ValueError(f"UserObservation.user_speed_mps must not be negative, got {self.user_speed_mps!r}")
        if not self.age_s >= 0:
            raise ValueError(f"UserObservation.age_s must not be negative, got {self.age_s!r}")


@dataclass(frozen=True)
class Ranges:
    """Ultrasonic readings: ``(angle_rad, range_m)`` per sensor, range from the sensor face, None = nothing seen
    within ``max_range_m`` (3 m: typical of hobby ultrasonic sensors)."""

    readings: tuple[tuple[float, float | None], ...] = ()
    max_range_m: float = 3.0
    receding_mps: tuple[float, ...] = ()
    """Per reading, how fast the thing seen moves away along the beam (m/s; from the echo's range rate
    and the robot's own motion); empty when unknown. A robot ahead that drives on may be followed closely."""

    def __post_init__(self) -> None:
        for angle, rng in self.readings:
            if rng is not None and not rng >= 0:
                raise ValueError(f"Ranges.readings: range at {angle!r} rad must not be negative, got {rng!r}")

    @classmethod
    def clear(cls, angles: tuple[float, ...] = SENSOR_ANGLES_RAD) -> Ranges:
        """Nothing seen by any sensor."""
        return cls(tuple((a, None) for a in angles))


def _is_stale(obs: UserObservation | None, cfg: PetControllerConfig) -> bool:
    return obs is None or obs.age_s > cfg.max_age_s


def cruise_speed(gap_error_m: float, user_speed_mps: float, cfg: PetControllerConfig) -> float:
    """The distance/speed stage: speed (m/s) along the direction of travel that keeps the gap, ACC-like.

    ``gap_error_m`` > 0 means the robot must go faster than the user (following: the user is too far ahead;
    leading: the user is too close behind). The gain grows from ``k_near`` at the target to
    ``k_far`` at the band's edge and beyond, so speed matching dominates near the target and gap control far
    from it, without a jump between the two.
    """
    weight = min(1.0, abs(gap_error_m) / cfg.near_band_m)
    gain = cfg.k_near + (cfg.k_far - cfg.k_near) * weight
    speed = user_speed_mps + gain * gap_error_m
    return max(-cfg.max_reverse_mps, min(cfg.limits.max_speed, speed))


def follow(
    obs: UserObservation | None, ranges: Ranges, cfg: PetControllerConfig, target_distance: float | None = None
) -> MotorCommand:
    """Following mode, the user ahead: drive along the line to the user to keep ``target_distance`` (default
    ``cfg.target_distance_m``) and turn to keep the user's bearing inside the field of view.

    The translation goes along the bearing (the base is holonomic), so the gap is kept even while the robot
    is still turning toward a user who stepped aside. No or a stale observation: stop.
    """
    if _is_stale(obs, cfg):
        return STOP
    target = cfg.target_distance_m if target_distance is None else target_distance
    bearing = wrap(obs.bearing_rad)
    speed = cruise_speed(obs.distance_m - target, obs.user_speed_mps, cfg)
    outside = max(0.0, abs(bearing) - cfg.fov_rad)
    omega = cfg.k_bearing * (bearing + math.copysign(outside, bearing))
    cmd = MotorCommand(speed * math.cos(bearing), speed * math.sin(bearing), omega)
    return safety(cmd, ranges, cfg)


def lead(
    obs: UserObservation | None, ranges: Ranges, cfg: PetControllerConfig, target_distance: float | None = None
) -> MotorCommand:
    """Leading mode, the user behind: keep about ``target_distance`` ahead of the user.

    While the user rotates, the robot moves as if rigidly attached to the user: omega = the user's angular
    speed and a sideways speed omega * (distance behind), so its path is an arc round the user and its heading
    turns with the user's (a forward speed alone would put the arc's centre beside the robot, not at the user).
    The forward speed keeps the gap, ACC-like. Not rotating, a user who drifts off the back axis is followed
    with a side-step (vy), leaving the heading alone: heading changes only when the user turns.
    """
    if _is_stale(obs, cfg):
        return STOP
    target = cfg.target_distance_m if target_distance is None else target_distance
    user_x = obs.distance_m * math.cos(obs.bearing_rad)
    user_y = obs.distance_m * math.sin(obs.bearing_rad)
    behind = -user_x
    vx = cruise_speed(target - behind, obs.user_speed_mps, cfg)
    if obs.rotating:
        omega = obs.angular_speed_rps
        vy = omega * behind
    else:
        omega = 0.0
        off_axis = abs(wrap(obs.bearing_rad - math.pi))
        vy = cfg.k_side * user_y if off_axis > cfg.side_step_deadband_rad else 0.0
    if obs.distance_m < target:
        vy = _sideways_room(vx, vy, cfg.limits)
    return safety(MotorCommand(vx, vy, omega), ranges, cfg)


def _sideways_room(vx: float, vy: float, limits: DriveLimits) -> float:
    """The sideways speed (arc or side-step), cut first when the base cannot do both and the user is nearer than
    the target: a robot that keeps its gap and lags sideways is only off to one side, and corrects it later; one
    that loses the gap is walked into. (A user farther than the target is no danger: both are scaled alike.)"""
    room = math.sqrt(max(0.0, limits.max_speed**2 - vx * vx))
    return max(-room, min(room, vy))


def allowed_approach_speed(range_m: float, cfg: PetControllerConfig) -> float:
    """Fastest speed (m/s) toward an obstacle ``range_m`` away that still stops ``stop_distance_m`` short of it."""
    gap = max(0.0, range_m - cfg.stop_distance_m)
    return min(cfg.k_approach * gap, math.sqrt(2 * cfg.brake_decel_mps2 * gap))


def safety(cmd: MotorCommand, ranges: Ranges, cfg: PetControllerConfig) -> MotorCommand:
    """The safety stage: the translation nearest the command whose component toward each obstacle seen is
    within ``allowed_approach_speed`` plus the speed at which that obstacle moves away (``receding_mps``:
    a robot may follow another that drives on), then every speed bounded.

    Only motion toward an obstacle is cut, so the robot may still slide past it sideways; and the nearest
    allowed velocity (not sensor-by-sensor cuts) adds no sideways motion of its own in front of a wall.
    """
    receding = ranges.receding_mps or (0.0,) * len(ranges.readings)
    constraints = [
        (math.cos(angle), math.sin(angle), allowed_approach_speed(rng, cfg) + max(0.0, away))
        for (angle, rng), away in zip(ranges.readings, receding, strict=True)
        if rng is not None
    ]
    vx, vy = _nearest_allowed((cmd.vx, cmd.vy), constraints)
    return MotorCommand(vx, vy, cmd.omega).limited(cfg.limits)


class SafetyStage:
    """``safety`` of a translation for one robot's ultrasonic ring in plain floats, bit for bit: no ``Ranges`` or
    ``MotorCommand`` is made, and each sensor's ``math.cos``/``math.sin`` is worked out once per ring (a surround
    pilot runs it on every control step, where building those objects was a third of its cost)."""

    def __init__(self, cfg: PetControllerConfig) -> None:
        self.cfg = cfg
        self._angles: list[float] | None = None
        self._trig: list[tuple[float, float]] = []

    def translation(
        self, vx: float, vy: float, angles: list[float], ranges: list[float], receding: Sequence[float]
    ) -> tuple[float, float]:
        """``safety(MotorCommand(vx, vy, 0.0), Ranges(readings, receding_mps=receding), cfg)``'s (vx, vy), where
        ``readings`` pairs ``angles`` with ``ranges`` (nan: nothing seen, as None); raises as ``Ranges`` does on a
        negative range."""
        cfg = self.cfg
        trig = self._ring_trig(angles)
        if len(ranges) != len(angles):
            raise ValueError(f"{len(ranges)} ranges for {len(angles)} sensors")
        if receding and len(receding) != len(ranges):
            raise ValueError(f"{len(receding)} receding speeds for {len(ranges)} sensors")
        stop, k_approach, brake = cfg.stop_distance_m, cfg.k_approach, cfg.brake_decel_mps2
        constraints = []
        for k, rng in enumerate(ranges):
            if rng != rng:  # nan: nothing seen
                continue
            if not rng >= 0:
                raise ValueError(f"Ranges.readings: range at {angles[k]!r} rad must not be negative, got {rng!r}")
            # allowed_approach_speed inline, with conditionals that pick as max(0.0, x) and min(a, b) do
            gap = rng - stop
            if not gap > 0.0:
                gap = 0.0
            approach, braking = k_approach * gap, math.sqrt(2 * brake * gap)
            allowed = braking if braking < approach else approach
            away = receding[k] if receding else 0.0
            c, s = trig[k]
            constraints.append((c, s, allowed + away if away > 0.0 else allowed + 0.0))
        return _limited(*_nearest_allowed((vx, vy), constraints), cfg.limits.max_speed)

    @staticmethod
    def translation_all(
        stages: list[SafetyStage],
        commands: np.ndarray,
        angles: list[list[float]],
        ranges: np.ndarray,
        receding: np.ndarray,
        has_receding: np.ndarray,
    ) -> list[tuple[float, float] | Exception]:
        """``translation`` of many robots' stages (of one config) at once, bit for bit as each alone: ``commands``
        (n, 2), their rings' ``angles``, ``ranges`` (n, s) with no negative one, ``receding`` (n, s) where
        ``has_receding``. Each sensor's limit is worked out elementwise; a command within every limit (the usual
        case) goes on as it is, the others through ``_nearest_allowed`` one by one. A robot whose own stage
        raises (``_nearest_allowed``'s ``** 2`` overflows on limits a hub's absurd odometry gives) has that error
        as its result: the others' go on."""
        cfg = stages[0].cfg  # every stage's (the caller's word)
        trig_rows = [stage._ring_trig(ring) for stage, ring in zip(stages, angles, strict=True)]
        trig = np.array(trig_rows, dtype=float).reshape(len(stages), -1, 2)  # (n, s, 2), s = 0 too
        gap = ranges - cfg.stop_distance_m
        gap = np.where(gap > 0.0, gap, 0.0)
        approach, braking = cfg.k_approach * gap, np.sqrt(2 * cfg.brake_decel_mps2 * gap)
        allowed = np.where(braking < approach, braking, approach)
        away = np.where(has_receding[:, None], receding, 0.0)
        limit = np.where(away > 0.0, allowed + away, allowed + 0.0)
        seen = ~np.isnan(ranges)
        vx, vy = commands[:, 0:1], commands[:, 1:2]
        within = ~seen | (trig[..., 0] * vx + trig[..., 1] * vy <= limit + 1e-12)
        out: list[tuple[float, float] | Exception] = []
        limits, seen_rows = limit.tolist(), seen.tolist()
        rows = zip(commands.tolist(), np.logical_and.reduce(within, axis=1).tolist(), strict=True)
        for i, ((x, y), free) in enumerate(rows):
            if not free:
                sensors = zip(trig_rows[i], limits[i], seen_rows[i], strict=True)
                try:
                    x, y = _nearest_allowed((x, y), [(c, s, lim) for (c, s), lim, ok in sensors if ok])
                except Exception as err:  # as that robot's own translation raises it
                    out.append(err)
                    continue
            out.append(_limited(x, y, cfg.limits.max_speed))
        return out

    def _ring_trig(self, angles: list[float]) -> list[tuple[float, float]]:
        """Each sensor's (cos, sin), worked out again only when the ring changes."""
        if self._angles is not angles:
            self._angles = angles
            self._trig = [(math.cos(a), math.sin(a)) for a in angles]
        return self._trig


def _limited(vx: float, vy: float, max_speed: float) -> tuple[float, float]:
    """``MotorCommand.limited``'s translation, in plain floats (the safety stage's last step)."""
    speed = math.hypot(vx, vy)
    scale = min(1.0, max_speed / speed) if speed > 0 else 1.0
    return vx * scale, vy * scale


def _nearest_allowed(v: tuple[float, float], constraints: list[tuple[float, float, float]]) -> tuple[float, float]:
    """The velocity nearest ``v`` with ``ux * vx + uy * vy <= limit`` for every ``(ux, uy, limit)``.

    A 2-D projection onto a few half-planes, solved exactly by trying the candidates: ``v`` itself, its
    projection onto each boundary, and each pair of boundaries' corner. Standing still is always allowed.
    """

    # (plain loops with early exits: the safety stage runs on every control step of every robot)
    vx, vy = v
    for ux, uy, limit in constraints:
        if not ux * vx + uy * vy <= limit + 1e-12:
            break
    else:
        return v  # nearest of all (the common case: nothing in the way)
    bounds = [(ux, uy, limit + 1e-12) for ux, uy, limit in constraints]

    def allowed(cx: float, cy: float) -> bool:
        for ux, uy, bound in bounds:  # noqa: SIM110 (a loop: all() of a generator costs twice as much here)
            if not ux * cx + uy * cy <= bound:
                return False
        return True

    candidates = [v, (0.0, 0.0)]
    for ux, uy, limit in constraints:
        excess = ux * vx + uy * vy - limit
        candidates.append((vx - excess * ux, vy - excess * uy))
    count = len(constraints)
    for i in range(count):
        ax, ay, a_lim = constraints[i]
        for j in range(i + 1, count):
            bx, by, b_lim = constraints[j]
            det = ax * by - ay * bx
            if det > 1e-9 or det < -1e-9:
                candidates.append(((a_lim * by - ay * b_lim) / det, (ax * b_lim - a_lim * bx) / det))
    # the nearest allowed one (the first in candidate order among equally near ones): try them nearest first
    distances = [(cx - vx) ** 2 + (cy - vy) ** 2 for cx, cy in candidates]
    for k in sorted(range(len(candidates)), key=distances.__getitem__):
        cx, cy = candidates[k]
        if allowed(cx, cy):
            return candidates[k]
    raise AssertionError("standing still is always allowed")  # every limit is >= 0


def obstacle_ahead(ranges: Ranges, cfg: PetControllerConfig) -> bool:
    """Leading mode's exception trigger: a sensor within the cone ahead sees something nearer than the limit."""
    return any(
        rng is not None and rng < cfg.obstacle_distance_m and abs(wrap(angle)) <= cfg.obstacle_cone_rad
        for angle, rng in ranges.readings
    )
