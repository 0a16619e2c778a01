"""Kinematics of the holonomic base: exact arcs, frames, limits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from petswarm.controllers.motion import (
    STOP,
    DriveLimits,
    MotorCommand,
    accelerate,
    compose,
    integrate,
    point_velocity,
    relative,
    rotate,
    wrap,
)


def test_integrate_one_long_step_matches_many_small_steps() -> None:
    cmd = MotorCommand(0.8, -0.3, 0.9)
    exact = integrate((1.0, 2.0, 0.4), cmd, 2.0)
    pose = (1.0, 2.0, 0.4)
    for _ in range(20000):
        pose = integrate(pose, cmd, 1e-4)
    assert exact == pytest.approx(pose, abs=1e-6)


def test_integrate_turning_in_place_on_an_arc_round_a_point() -> None:
    # vy = omega * R with the robot facing away from a centre R behind it: a circle round that centre
    radius, omega = 1.0, 0.7
    pose = integrate((0.0, 0.0, 0.0), MotorCommand(0.0, omega * radius, omega), math.pi / 2 / omega)
    assert pose == pytest.approx((-1.0, 1.0, math.pi / 2), abs=1e-9)


def test_integrate_straight_without_rotation() -> None:
    assert integrate((0.0, 0.0, math.pi / 2), MotorCommand(1.0, 0.5, 0.0), 2.0) == pytest.approx(
        (-1.0, 2.0, math.pi / 2)
    )


def test_relative_undoes_compose() -> None:
    rng = np.random.default_rng(5)
    for _ in range(50):
        base = (*rng.normal(size=2), rng.uniform(-3, 3))
        other = (*rng.normal(size=2), rng.uniform(-3, 3))
        back = compose(base, relative(base, other))
        assert back[:2] == pytest.approx(other[:2])
        assert wrap(back[2] - other[2]) == pytest.approx(0.0, abs=1e-12)


def test_wrap_and_rotate() -> None:
    assert wrap(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert -math.pi <= wrap(math.pi) < math.pi
    assert rotate((1.0, 0.0), math.pi / 2) == pytest.approx((0.0, 1.0))


def test_limited_keeps_the_direction_and_bounds_omega() -> None:
    limits = DriveLimits()
    cmd = MotorCommand(3.0, 4.0, -9.0).limited(limits)
    assert cmd.speed == pytest.approx(limits.max_speed)
    assert cmd.vy / cmd.vx == pytest.approx(4.0 / 3.0)
    assert cmd.omega == -limits.max_omega


def test_accelerate_reaches_the_command_no_faster_than_the_limits() -> None:
    limits = DriveLimits()
    cmd, steps = STOP, 0
    while cmd != MotorCommand(1.2, 0.0, 1.5):
        nxt = accelerate(cmd, MotorCommand(5.0, 0.0, 5.0), 0.05, limits)
        assert math.hypot(nxt.vx - cmd.vx, nxt.vy - cmd.vy) <= limits.max_accel * 0.05 + 1e-12
        assert abs(nxt.omega - cmd.omega) <= limits.max_alpha * 0.05 + 1e-12
        cmd, steps = MotorCommand(round(nxt.vx, 12), round(nxt.vy, 12), round(nxt.omega, 12)), steps + 1
    assert steps == math.ceil(1.2 / (1.5 * 0.05))


def test_point_velocity_of_a_rotating_frame() -> None:
    assert point_velocity(MotorCommand(1.0, 0.0, 0.5), (-2.0, 1.0)) == pytest.approx((0.5, -1.0))


@pytest.mark.parametrize("field", ["max_speed", "max_omega", "max_accel", "max_alpha"])
def test_drive_limits_must_be_positive(field: str) -> None:
    with pytest.raises(ValueError, match=field):
        DriveLimits(**{field: 0.0})


def test_negative_time_step_is_refused() -> None:
    with pytest.raises(ValueError, match="dt"):
        integrate((0.0, 0.0, 0.0), STOP, -0.1)
