"""Kinematics of the holonomic (mecanum) base: motor commands, their limits, poses and their integration.

Pure scalar code, shared by the controllers, dead reckoning and the tests' kinematic simulation.
Conventions (issue 5): SI units; world frame x east, y north, yaw counter-clockwise from +x; robot frame
x forward, y left. A pose is ``(x, y, yaw)``. A motor command is ``(vx, vy, omega)`` in the robot's own
frame. Angles are wrapped into [-pi, pi) by ``wrap``; ``petswarm.managers.ir_estimator.wrap_bearing`` is the
[0, 2 pi) form the IR estimator reports bearings in, kept as it is for that reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from petswarm.angles import wrap

Pose = tuple[float, float, float]
"""``(x, y, yaw)``: a body's position and heading in some frame."""
Vec = tuple[float, float]

_STRAIGHT_OMEGA = 1e-9
"""Below this yaw rate (rad/s) the arc formula divides by almost zero: use the straight-line limit."""


@dataclass(frozen=True)
class DriveLimits:
    """What the base can do. The papers give none of these; the values are the project's choices.

    ``max_speed`` 1.2 m/s: a brisk walk (1.0 m/s) plus room to close a gap. ``max_omega`` 1.5 rad/s:
    a 90 degree turn in about a second, faster than a walking person turns. ``max_accel`` 1.5 m/s^2 and
    ``max_alpha`` 4 rad/s^2: a small mecanum base reaches walking speed in under a second without slipping.
    """

    max_speed: float = 1.2
    max_omega: float = 1.5
    max_accel: float = 1.5
    max_alpha: float = 4.0

    def __post_init__(self) -> None:
        for name in ("max_speed", "max_omega", "max_accel", "max_alpha"):
            if not getattr(self, name) > 0:
                raise ValueError(f"DriveLimits.{name} must be positive, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class MotorCommand:
    """Velocity command in the robot's own frame: ``vx`` forward and ``vy`` left (m/s), ``omega`` CCW (rad/s)."""

    vx: float = 0.0
    vy: float = 0.0
    omega: float = 0.0

    @property
    def speed(self) -> float:
        """Translational speed, m/s."""
        return math.hypot(self.vx, self.vy)

    def limited(self, limits: DriveLimits) -> MotorCommand:
        """Bounded to the base's limits; the translation is scaled, not clipped per axis, so it keeps its direction."""
        scale = min(1.0, limits.max_speed / self.speed) if self.speed > 0 else 1.0
        omega = max(-limits.max_omega, min(limits.max_omega, self.omega))
        return MotorCommand(self.vx * scale, self.vy * scale, omega)


STOP = MotorCommand()
"""Stand still."""


def accelerate(previous: MotorCommand, wanted: MotorCommand, dt: float, limits: DriveLimits) -> MotorCommand:
    """The command actually reached after ``dt`` seconds from ``previous`` toward ``wanted`` (speed-limited first).

    The change of translation is bounded in size by ``max_accel * dt`` (keeping its direction), the change of
    yaw rate by ``max_alpha * dt``: what a real base does with a command it cannot reach at once.
    """
    if dt < 0:
        raise ValueError(f"dt must not be negative, got {dt!r}")
    target = wanted.limited(limits)
    dvx, dvy = target.vx - previous.vx, target.vy - previous.vy
    change = math.hypot(dvx, dvy)
    step = limits.max_accel * dt
    scale = min(1.0, step / change) if change > 0 else 1.0
    dw = max(-limits.max_alpha * dt, min(limits.max_alpha * dt, target.omega - previous.omega))
    return MotorCommand(previous.vx + dvx * scale, previous.vy + dvy * scale, previous.omega + dw)


def rotate(vec: Vec, angle: float) -> Vec:
    """``vec`` rotated counter-clockwise by ``angle``."""
    c, s = math.cos(angle), math.sin(angle)
    return (c * vec[0] - s * vec[1], s * vec[0] + c * vec[1])


def compose(base: Pose, local: Pose) -> Pose:
    """A pose given in ``base``'s frame, expressed in the frame ``base`` itself is given in."""
    dx, dy = rotate((local[0], local[1]), base[2])
    return (base[0] + dx, base[1] + dy, wrap(base[2] + local[2]))


def relative(base: Pose, other: Pose) -> Pose:
    """``other`` expressed in ``base``'s frame (both given in one common frame): the inverse of ``compose``."""
    dx, dy = rotate((other[0] - base[0], other[1] - base[1]), -base[2])
    return (dx, dy, wrap(other[2] - base[2]))


def integrate(pose: Pose, cmd: MotorCommand, dt: float) -> Pose:
    """The pose after holding ``cmd`` for ``dt`` seconds: exact for a constant body-frame twist.

    A constant (vx, vy, omega) moves the body along a circular arc; the displacement in the starting body
    frame is the body velocity integrated through the rotation, so no small-step error accumulates when the
    caller uses long steps (dead reckoning over a whole IR token round).
    """
    if dt < 0:
        raise ValueError(f"dt must not be negative, got {dt!r}")
    turn = cmd.omega * dt
    if abs(cmd.omega) < _STRAIGHT_OMEGA:
        local = (cmd.vx * dt, cmd.vy * dt)
    else:
        sin_t, one_minus_cos = math.sin(turn), 1.0 - math.cos(turn)
        local = (
            (cmd.vx * sin_t - cmd.vy * one_minus_cos) / cmd.omega,
            (cmd.vx * one_minus_cos + cmd.vy * sin_t) / cmd.omega,
        )
    return compose(pose, (local[0], local[1], turn))


def point_velocity(twist: MotorCommand, point: Vec) -> Vec:
    """Velocity, in the body's frame, of a point fixed to a body that moves with ``twist`` (v + omega x r)."""
    return (twist.vx - twist.omega * point[1], twist.vy + twist.omega * point[0])
