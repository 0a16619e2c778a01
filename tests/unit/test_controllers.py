"""The Pet-Bot controller, the slave controller and a small kinematic simulation of both.

Simulation bounds (``tests/unit/kinematic_sim.py``: fixes every 0.5 s with 3 cm / 3 degree noise, the
user walking 1 m/s then turning 90 degrees at 60 deg/s): a following swarm of four keeps a median formation
error below 0.15 m (measured 0.04-0.06 m over seeds 0-4) and no two bodies nearer than 2 robot radii.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from petswarm.controllers.formation_shapes import Mode, Shape, slots
from petswarm.controllers.motion import (
    STOP,
    DriveLimits,
    MotorCommand,
    Pose,
    accelerate,
    compose,
    integrate,
    relative,
    wrap,
)
from petswarm.controllers.pet_controller import (
    PetControllerConfig,
    Ranges,
    SafetyStage,
    UserObservation,
    allowed_approach_speed,
    follow,
    lead,
    obstacle_ahead,
    safety,
)
from petswarm.controllers.slave_controller import (
    RelativeFix,
    RelativeTracker,
    SlaveControllerConfig,
    slave_decision,
    twist,
    twist_sensitivity,
)
from tests.unit import kinematic_sim as sim

CFG = PetControllerConfig()
CLEAR = Ranges.clear()
FORMATION_ERROR_BOUND_M = 0.15
"""Median distance of a slave from its reference: five times the IR distance noise, a third of a body."""


# --- the Pet-Bot controller -------------------------------------------------------------------------------


def test_follow_matches_the_users_speed_at_the_target_distance() -> None:
    cmd = follow(UserObservation(1.0, 0.0, user_speed_mps=0.9), CLEAR, CFG)
    assert cmd == MotorCommand(pytest.approx(0.9), 0.0, 0.0)


def test_follow_closes_a_far_gap_with_the_stiffer_gain() -> None:
    near = follow(UserObservation(1.1, 0.0, user_speed_mps=0.5), CLEAR, CFG).vx - 0.5
    far = follow(UserObservation(1.5, 0.0, user_speed_mps=0.0), CLEAR, CFG).vx
    assert near == pytest.approx(CFG.k_near * 0.1 + (CFG.k_far - CFG.k_near) * 0.025, rel=1e-6)
    assert far == pytest.approx(CFG.k_far * 0.5)
    assert follow(UserObservation(3.0, 0.0, user_speed_mps=1.0), CLEAR, CFG).vx == CFG.limits.max_speed


def test_follow_backs_off_slowly_from_a_user_too_close() -> None:
    assert follow(UserObservation(0.3, 0.0), CLEAR, CFG).vx == -CFG.max_reverse_mps


def test_follow_turns_toward_the_user_harder_outside_the_field_of_view() -> None:
    inside = follow(UserObservation(1.0, math.radians(20)), CLEAR, CFG).omega
    outside = follow(UserObservation(1.0, math.radians(40)), CLEAR, CFG).omega
    right = follow(UserObservation(1.0, math.radians(-20)), CLEAR, CFG).omega
    assert inside > 0 > right
    assert outside > 2 * inside


def test_no_or_stale_observation_stops_the_robot() -> None:
    assert follow(None, CLEAR, CFG) == STOP
    assert lead(UserObservation(1.0, math.pi, 1.0, age_s=2.0), CLEAR, CFG) == STOP


def test_lead_keeps_ahead_of_a_walking_user() -> None:
    on_target = lead(UserObservation(1.0, math.pi, user_speed_mps=1.0), CLEAR, CFG)
    lagging = lead(UserObservation(1.3, math.pi, user_speed_mps=1.0), CLEAR, CFG)
    assert on_target == MotorCommand(pytest.approx(1.0), 0.0, 0.0)
    assert lagging.vx < 1.0 - 0.3 * CFG.k_near


def test_lead_side_steps_when_the_user_drifts_without_rotating() -> None:
    drift_left = lead(UserObservation(1.0, math.pi - math.radians(15), 1.0), CLEAR, CFG)
    within = lead(UserObservation(1.0, math.pi - math.radians(5), 1.0), CLEAR, CFG)
    assert drift_left.vy > 0 and drift_left.omega == 0
    assert within.vy == 0


def test_lead_drives_an_arc_round_a_rotating_user() -> None:
    cmd = lead(UserObservation(1.2, math.pi, 0.0, rotating=True, angular_speed_rps=-0.8), CLEAR, CFG)
    assert cmd.omega == pytest.approx(-0.8)
    assert cmd.vy == pytest.approx(-0.8 * 1.2)
    # the robot's path is a circle round the user: its distance to the user does not change
    robot = integrate((0.0, 0.0, 0.0), MotorCommand(0.0, cmd.vy, cmd.omega), 1.0)
    assert math.dist(robot[:2], (-1.2, 0.0)) == pytest.approx(1.2)


def test_observation_fields_are_checked() -> None:
    with pytest.raises(ValueError, match="distance_m"):
        UserObservation(-1.0, 0.0)
    with pytest.raises(ValueError, match="range"):
        Ranges(((0.0, -0.2),))
    with pytest.raises(ValueError, match="k_far"):
        PetControllerConfig(k_far=0.0)


def test_safety_cuts_only_the_part_of_the_motion_toward_the_obstacle() -> None:
    cmd = safety(MotorCommand(1.0, 0.5, 0.3), Ranges(((0.0, CFG.stop_distance_m),)), CFG)
    assert cmd.vx == pytest.approx(0.0, abs=1e-12)
    assert cmd.vy == 0.5 and cmd.omega == 0.3


def test_safety_before_a_wall_adds_no_sideways_motion() -> None:
    wall = Ranges(((math.radians(-30), 0.45), (0.0, 0.4), (math.radians(30), 0.45)))
    cmd = safety(MotorCommand(1.2, 0.0, 0.0), wall, CFG)
    assert cmd.vy == pytest.approx(0.0, abs=1e-12)
    assert cmd.vx == pytest.approx(CFG.k_approach * (0.4 - CFG.stop_distance_m))


def test_safety_never_exceeds_an_allowed_approach_speed() -> None:
    rng = np.random.default_rng(11)
    for _ in range(200):
        readings = tuple((a, float(rng.uniform(0.0, 2.0))) for a in (math.radians(-30), 0.0, math.radians(30)))
        wanted = MotorCommand(*rng.uniform(-1.2, 1.2, size=2), 0.0)
        cmd = safety(wanted, Ranges(readings), CFG)
        for angle, rng_m in readings:
            toward = cmd.vx * math.cos(angle) + cmd.vy * math.sin(angle)
            assert toward <= max(allowed_approach_speed(rng_m, CFG), 0.0) + 1e-9
        assert cmd.speed <= wanted.speed + 1e-9


def test_obstacle_ahead_only_within_the_cone_and_distance() -> None:
    assert obstacle_ahead(Ranges(((0.0, 0.4),)), CFG)
    assert not obstacle_ahead(Ranges(((0.0, 1.0), (math.radians(30), None))), CFG)
    assert not obstacle_ahead(Ranges(((math.radians(60), 0.2),)), CFG)


def _wall_ranges(pose: Pose, wall_x: float, radius: float) -> Ranges:
    readings = []
    for angle in (math.radians(-30), 0.0, math.radians(30)):
        heading = pose[2] + angle
        sensor_x = pose[0] + radius * math.cos(heading)
        along = (wall_x - sensor_x) / math.cos(heading) if math.cos(heading) > 0 else math.inf
        readings.append((angle, along if 0 <= along <= 3.0 else None))
    return Ranges(tuple(readings))


def test_a_following_robot_stops_before_a_wall() -> None:
    # the user walks on beyond a wall (LF passes through it); the robot must stop short of the wall
    wall_x, radius, dt = 3.0, sim.ROBOT_RADIUS_M, 0.05
    pose, velocity, gaps = (0.0, 0.0, 0.0), STOP, []
    for step in range(200):
        user_x = 1.0 + step * dt * 1.0
        obs = UserObservation(user_x - pose[0], 0.0, user_speed_mps=1.0)
        velocity = accelerate(velocity, follow(obs, _wall_ranges(pose, wall_x, radius), CFG), dt, DriveLimits())
        pose = integrate(pose, velocity, dt)
        gaps.append(wall_x - pose[0] - radius)
    assert min(gaps) > 0.1
    assert gaps[-1] == pytest.approx(CFG.stop_distance_m, abs=0.05)
    assert velocity.speed < 0.02


# --- the slave controller ---------------------------------------------------------------------------------


def test_tracker_dead_reckons_both_motions_exactly() -> None:
    me, master = (0.0, 0.0, 0.3), (1.5, 0.4, -0.2)
    my_cmd, master_cmd = MotorCommand(0.7, 0.2, 0.4), MotorCommand(1.0, -0.1, -0.6)
    tracker = RelativeTracker()
    x, y, heading = relative(me, master)
    tracker.fix(RelativeFix(math.hypot(x, y), math.atan2(y, x), heading, 0.0))
    for _ in range(10):
        tracker.predict(0.05, my_cmd, master_cmd)
        me, master = integrate(me, my_cmd, 0.05), integrate(master, master_cmd, 0.05)
    assert tracker.pose == pytest.approx(relative(me, master), abs=1e-9)
    assert tracker.t == pytest.approx(0.5)


def test_tracker_without_heading_assumes_parallel_headings() -> None:
    tracker = RelativeTracker()
    assert tracker.predict(0.1, STOP, STOP) is None
    assert tracker.fix(RelativeFix(2.0, math.pi, None, 1.0)) == pytest.approx((-2.0, 0.0, 0.0))


def _fix_of(observer: Pose, other: Pose, with_heading: bool = True) -> RelativeFix:
    x, y, heading = relative(observer, other)
    return RelativeFix(math.hypot(x, y), math.atan2(y, x), heading if with_heading else None, 0.0)


def test_slave_at_its_slot_moving_with_the_master_is_only_fed_forward() -> None:
    slot, master = (-1.0, 0.5), (0.0, 0.0, 0.0)
    me = compose(master, (*slot, 0.0))
    decision = slave_decision(
        relative(me, master), None, slot, None, (1.0, 0.0, 0.2), Mode.FOLLOWING, 0.0, SlaveControllerConfig()
    )
    assert decision.location_error_m == pytest.approx(0.0, abs=1e-12)
    # a point at the slot of a frame moving at (1, 0, 0.2) moves at (1 - 0.2 * 0.5, 0.2 * -1)
    assert (decision.command.vx, decision.command.vy, decision.command.omega) == pytest.approx((0.9, -0.2, 0.2))
    assert decision.twist_rad is None


def test_leading_rotation_turns_the_slot_about_the_user() -> None:
    cfg, slot, centre = SlaveControllerConfig(), (-1.0, 0.0), (-2.0, 0.0)
    decision = slave_decision((1.0, 0.0, 0.0), None, slot, None, STOP, Mode.LEADING, 0.5, cfg, rotation_centre=centre)
    # 1 m from the user, turning at 0.5 rad/s: 0.5 m/s sideways (the master, 2 m out, gets 1 m/s)
    assert (decision.command.vx, decision.command.vy, decision.command.omega) == pytest.approx((0.0, 0.5, 0.5))
    following = slave_decision((1.0, 0.0, 0.0), None, slot, None, STOP, Mode.FOLLOWING, 0.5, cfg)
    assert following.command == MotorCommand(0.0, 0.0, 0.0)


def test_twist_is_zero_at_the_reference_and_measures_a_swing_round_the_master() -> None:
    slot, neighbour_slot = (-2.0, 0.0), (-1.0, 0.6)
    master, neighbour = (0.0, 0.0, 0.0), (-1.0, 0.6, 0.0)
    at_ref = compose(master, (*slot, 0.0))
    assert twist(relative(at_ref, master), _fix_of(at_ref, neighbour), slot, neighbour_slot) == pytest.approx(0.0)
    delta = math.radians(0.5)
    swung = compose((0.0, 0.0, delta), (*slot, 0.0))  # on the circle round the master, heading off by delta
    value = twist(relative(swung, master), _fix_of(swung, neighbour), slot, neighbour_slot)
    assert value == pytest.approx(twist_sensitivity(slot, neighbour_slot) * delta, rel=0.05)


def _settle_compass_free(with_neighbour: bool, steps: int = 400, dt: float = 0.05) -> tuple[float, float | None]:
    """A slave with no heading information starts 20 degrees twisted; returns its final heading error and twist."""
    cfg = SlaveControllerConfig()
    formation = slots(Shape.COLUMN, 3, 1.0)
    slot = formation[2]
    master, neighbour = (0.0, 0.0, 0.0), compose((0.0, 0.0, 0.0), (*formation[1], 0.0))
    me, velocity, decision = (slot[0], slot[1], math.radians(20)), STOP, None
    neighbour_slot = formation[1]
    for _ in range(steps):
        decision = slave_decision(
            (*relative(me, master)[:2], 0.0),
            _fix_of(me, neighbour, with_heading=False) if with_neighbour else None,
            slot,
            neighbour_slot if with_neighbour else None,
            STOP,
            Mode.FOLLOWING,
            0.0,
            cfg,
        )
        velocity = accelerate(velocity, decision.command, dt, cfg.limits)
        me = integrate(me, velocity, dt)
    return wrap(me[2]), decision.twist_rad


def test_twisted_heading_is_corrected_from_the_neighbours_bearing() -> None:
    heading, final_twist = _settle_compass_free(with_neighbour=True)
    assert abs(final_twist) <= SlaveControllerConfig().twist_tolerance_rad
    assert abs(heading) < math.radians(8)
    uncorrected, _ = _settle_compass_free(with_neighbour=False)
    assert uncorrected == pytest.approx(math.radians(20), abs=1e-6)


# --- the kinematic simulation -----------------------------------------------------------------------------


@pytest.mark.parametrize("shape", list(Shape))
@pytest.mark.parametrize("seed", [0, 1])
def test_following_swarm_keeps_formation_through_a_90_degree_turn(shape: Shape, seed: int) -> None:
    trace = sim.run(shape, 4, Mode.FOLLOWING, np.random.default_rng(seed), sim.UserScript(), 16.0)
    errors = np.asarray(trace.formation_error)
    assert float(np.median(errors)) < FORMATION_ERROR_BOUND_M
    assert trace.min_separation > 2 * sim.ROBOT_RADIUS_M
    user_distance = np.asarray(trace.user_distance)
    assert user_distance.min() > 0.8 and user_distance.max() < 1.2
    # the master turned with the user
    assert wrap(trace.robot_yaw[-1][0]) == pytest.approx(math.pi / 2, abs=math.radians(10))


def test_following_swarm_without_heading_exchange_still_keeps_formation() -> None:
    sensing = sim.Sensing(heading_exchange=False)
    trace = sim.run(Shape.WEDGE, 4, Mode.FOLLOWING, np.random.default_rng(2), sim.UserScript(), 16.0, sensing=sensing)
    assert float(np.median(trace.formation_error)) < FORMATION_ERROR_BOUND_M
    assert trace.min_separation > 2 * sim.ROBOT_RADIUS_M


@pytest.mark.parametrize("turn_deg", [90, -90, 45, -45])
def test_leading_robot_drives_an_arc_when_the_user_rotates(turn_deg: int) -> None:
    script = sim.UserScript(speed_mps=0.0, turn_rad=math.radians(turn_deg))
    trace = sim.run(Shape.COLUMN, 1, Mode.LEADING, np.random.default_rng(3), script, 10.0)
    yaw_change = math.degrees(wrap(trace.robot_yaw[-1][0] - trace.robot_yaw[0][0]))
    assert yaw_change == pytest.approx(turn_deg, abs=15)
    assert min(trace.user_distance) > 0.8 and max(trace.user_distance) < 1.2


def test_safety_lets_a_robot_follow_closely_what_drives_away_but_not_what_stands():
    cfg = PetControllerConfig()
    ahead = ((0.0, 0.32),)  # 7 cm beyond the stop distance
    standing = safety(MotorCommand(0.8, 0.0, 0.0), Ranges(ahead), cfg)
    assert standing.vx == pytest.approx(allowed_approach_speed(0.32, cfg))
    driving_on = safety(MotorCommand(0.8, 0.0, 0.0), Ranges(ahead, receding_mps=(0.6,)), cfg)
    assert driving_on.vx == pytest.approx(allowed_approach_speed(0.32, cfg) + 0.6)
    coming = safety(MotorCommand(0.8, 0.0, 0.0), Ranges(ahead, receding_mps=(-0.5,)), cfg)
    assert coming.vx == pytest.approx(standing.vx)  # something approaching gives no extra room


def test_the_safety_stage_in_plain_floats_is_safety_bit_for_bit():
    """``SafetyStage.translation`` (the surround pilot's) against ``safety`` on random rings: echoes near and
    far, missing ones, receding speeds of both signs or none, commands inside and outside the limits."""
    rng = np.random.default_rng(12)
    angles = np.radians([0.0, 45.0, 90.0, 135.0, 180.0, -135.0, -90.0, -45.0]).tolist()
    for cfg in (PetControllerConfig(stop_distance_m=0.04), PetControllerConfig(stop_distance_m=0.04, k_approach=4.0)):
        stage = SafetyStage(cfg)
        cut = 0
        for _ in range(3000):
            ranges = rng.uniform(0.0, 0.6, 8)
            ranges[rng.random(8) < 0.4] = math.nan
            ranges[rng.random(8) < 0.1] = cfg.stop_distance_m  # exactly at the stop distance
            receding = tuple(rng.normal(0.0, 0.5, 8).tolist()) if rng.random() < 0.7 else ()
            vx, vy = rng.normal(0.0, 1.2, 2).tolist()
            readings = tuple((a, None if math.isnan(r) else r) for a, r in zip(angles, ranges.tolist(), strict=True))
            want = safety(MotorCommand(vx, vy, 0.0), Ranges(readings, receding_mps=receding), cfg)
            got = stage.translation(vx, vy, angles, ranges.tolist(), receding)
            assert got == (want.vx, want.vy)
            assert [math.copysign(1.0, v) for v in got] == [math.copysign(1.0, want.vx), math.copysign(1.0, want.vy)]
            cut += got != (vx, vy)
        assert cut > 1000  # the obstacles did cut most commands: the projections and corners were compared too


def test_the_safety_stage_in_plain_floats_refuses_a_negative_range_as_ranges_does():
    with pytest.raises(ValueError, match="must not be negative"):
        SafetyStage(PetControllerConfig()).translation(0.5, 0.0, [0.0, 1.0], [0.3, -0.1], ())
