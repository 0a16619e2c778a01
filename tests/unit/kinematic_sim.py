"""A small pure kinematic simulation for the controllers' tests: ideal bodies, sparse noisy sensing.

Every body moves exactly by ``petswarm.controllers.motion`` (acceleration-limited commands, exact arcs). The robots see
only what the real ones would: the user through an LF fix and the belt's activity, each other through IR
fixes with the relative heading; fixes come every ``fix_period_s`` with Gaussian noise, and the master's
broadcast velocity reaches the slaves one tick late. All randomness comes from the Generator passed in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from petswarm.controllers.formation_shapes import Mode, Shape, master_target_distance, neighbours, slots
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
from petswarm.controllers.pet_controller import PetControllerConfig, Ranges, UserObservation, follow, lead
from petswarm.controllers.slave_controller import RelativeFix, RelativeTracker, SlaveControllerConfig, slave_decision

DT = 0.05
ROBOT_RADIUS_M = 0.15


@dataclass(frozen=True)
class Sensing:
    """How the robots sense: the brief's 0.5 s fixes with 3 cm / 3 degree noise by default."""

    fix_period_s: float = 0.5
    distance_sigma_m: float = 0.03
    angle_sigma_rad: float = math.radians(3)
    speed_sigma_mps: float = 0.05
    gyro_sigma_rps: float = 0.03
    heading_exchange: bool = True


@dataclass(frozen=True)
class UserScript:
    """The user walks at ``speed`` after ``start_s``, turns by ``turn_rad`` at ``turn_rate`` from ``turn_at_s``."""

    speed_mps: float = 1.0
    start_s: float = 1.0
    turn_at_s: float = 7.0
    turn_rad: float = math.pi / 2
    turn_rate_rps: float = math.pi / 3
    walk_while_turning: bool = True

    def twist(self, t: float) -> MotorCommand:
        """The user's motion at time ``t`` in the user's own frame."""
        turning = self.turn_at_s <= t < self.turn_at_s + abs(self.turn_rad) / self.turn_rate_rps
        omega = math.copysign(self.turn_rate_rps, self.turn_rad) if turning else 0.0
        walking = t >= self.start_s and (self.walk_while_turning or not turning)
        ramp = min(1.0, max(0.0, t - self.start_s))
        return MotorCommand(self.speed_mps * ramp if walking else 0.0, 0.0, omega)


@dataclass
class Trace:
    """What the simulation records for the assertions."""

    times: list[float] = field(default_factory=list)
    formation_error: list[list[float]] = field(default_factory=list)
    """Per tick, each slave's distance from its true reference location."""
    min_separation: float = math.inf
    user_distance: list[float] = field(default_factory=list)
    robot_yaw: list[list[float]] = field(default_factory=list)


def _noisy_fix(observer: Pose, other: Pose, t: float, rng: np.random.Generator, sensing: Sensing) -> RelativeFix:
    x, y, heading = relative(observer, other)
    distance = math.hypot(x, y) + rng.normal(0.0, sensing.distance_sigma_m)
    bearing = math.atan2(y, x) + rng.normal(0.0, sensing.angle_sigma_rad)
    seen_heading = wrap(heading + rng.normal(0.0, sensing.angle_sigma_rad)) if sensing.heading_exchange else None
    return RelativeFix(max(distance, 0.0), bearing, seen_heading, t)


@dataclass
class _Robot:
    pose: Pose
    velocity: MotorCommand = STOP
    user: RelativeTracker = field(default_factory=RelativeTracker)
    master: RelativeTracker = field(default_factory=RelativeTracker)
    neighbour_fix: RelativeFix | None = None
    last_fix_t: float = -math.inf
    next_fix_t: float = 0.0


def run(
    shape: Shape,
    members: int,
    mode: Mode,
    rng: np.random.Generator,
    script: UserScript,
    seconds: float,
    spacing: float = 1.0,
    sensing: Sensing | None = None,
    slave_start_offset: Pose = (0.0, 0.0, 0.0),
) -> Trace:
    """Drive a swarm of ``members`` (1 = a single robot) with the user for ``seconds``; robots start at their
    slots, the master at its target distance from the user (ahead of the user when leading)."""
    sensing = sensing or Sensing()
    pet_cfg, slave_cfg, limits = PetControllerConfig(), SlaveControllerConfig(), DriveLimits()
    formation = slots(shape, members, spacing)
    target = master_target_distance(mode, formation)
    user: Pose = (target, 0.0, 0.0) if mode is Mode.FOLLOWING else (-target, 0.0, 0.0)
    robots = [_Robot(compose((0.0, 0.0, 0.0), (*slot, 0.0))) for slot in formation]
    for robot in robots[1:]:
        robot.pose = compose(robot.pose, slave_start_offset)
        # members hold the IR token in turn: each slave's fixes come at its own phase of the round
        robot.next_fix_t = float(rng.uniform(0.0, sensing.fix_period_s))
    user_velocity, broadcast, t, trace = STOP, STOP, 0.0, Trace()
    while t < seconds:
        user_velocity = script.twist(t)
        commands = [_master_command(robots[0], user, user_velocity, t, mode, target, pet_cfg, rng, sensing)]
        for k in range(1, members):
            commands.append(
                _slave_command(robots, k, shape, formation, broadcast, user_velocity, t, mode, slave_cfg, rng, sensing)
            )
        for robot, cmd in zip(robots, commands, strict=True):
            robot.velocity = accelerate(robot.velocity, cmd, DT, limits)
            robot.pose = integrate(robot.pose, robot.velocity, DT)
        for robot in robots:
            robot.user.predict(DT, robot.velocity, _belt_twist(user_velocity))
            robot.master.predict(DT, robot.velocity, broadcast)
        broadcast = robots[0].velocity
        user = integrate(user, user_velocity, DT)
        t += DT
        _record(trace, t, robots, formation, user)
    return trace


def _belt_twist(user_velocity: MotorCommand) -> MotorCommand:
    """What the robots know of the user's motion: speed and yaw rate (noise is added where they are read)."""
    return user_velocity


def _master_command(
    robot: _Robot,
    user: Pose,
    user_velocity: MotorCommand,
    t: float,
    mode: Mode,
    target: float,
    cfg: PetControllerConfig,
    rng: np.random.Generator,
    sensing: Sensing,
) -> MotorCommand:
    if t >= robot.next_fix_t:
        robot.next_fix_t += sensing.fix_period_s
        fix = _noisy_fix(robot.pose, user, t, rng, sensing)
        # LF gives no heading: the tracker takes the user's heading as the robot's own, which is right
        # for walking with (following) or ahead of (leading) the user
        robot.user.fix(RelativeFix(fix.distance_m, fix.bearing_rad, None, t))
        robot.last_fix_t = t
    x, y, _ = robot.user.pose
    gyro = user_velocity.omega + rng.normal(0.0, sensing.gyro_sigma_rps)
    obs = UserObservation(
        math.hypot(x, y),
        math.atan2(y, x),
        max(0.0, user_velocity.vx + rng.normal(0.0, sensing.speed_sigma_mps)),
        rotating=abs(gyro) > 0.2,
        angular_speed_rps=gyro,
        age_s=t - robot.last_fix_t,
    )
    drive = follow if mode is Mode.FOLLOWING else lead
    return drive(obs, Ranges.clear(), cfg, target_distance=target)


def _slave_command(
    robots: list[_Robot],
    k: int,
    shape: Shape,
    formation: list[tuple[float, float]],
    broadcast: MotorCommand,
    user_velocity: MotorCommand,
    t: float,
    mode: Mode,
    cfg: SlaveControllerConfig,
    rng: np.random.Generator,
    sensing: Sensing,
) -> MotorCommand:
    robot = robots[k]
    (neighbour,) = neighbours(shape, k)
    if robot.master.pose is None or t >= robot.next_fix_t:
        # the first fix comes from the IR round that precedes driving
        robot.next_fix_t += sensing.fix_period_s if robot.master.pose is not None else 0.0
        robot.master.fix(_noisy_fix(robot.pose, robots[0].pose, t, rng, sensing))
        robot.neighbour_fix = _noisy_fix(robot.pose, robots[neighbour].pose, t, rng, sensing)
    rotation = user_velocity.omega + rng.normal(0.0, sensing.gyro_sigma_rps)
    centre = (-master_target_distance(mode, formation), 0.0) if mode is Mode.LEADING else None
    decision = slave_decision(
        robot.master.pose,
        robot.neighbour_fix if neighbour else None,
        formation[k],
        formation[neighbour] if neighbour else None,
        broadcast,
        mode,
        rotation if abs(rotation) > 0.2 else 0.0,
        cfg,
        rotation_centre=centre,
    )
    return decision.command


def _record(trace: Trace, t: float, robots: list[_Robot], formation: list[tuple[float, float]], user: Pose) -> None:
    master = robots[0].pose
    errors = []
    for robot, slot in zip(robots[1:], formation[1:], strict=True):
        ref = compose(master, (*slot, 0.0))
        errors.append(math.hypot(robot.pose[0] - ref[0], robot.pose[1] - ref[1]))
    bodies = [r.pose for r in robots] + [user]
    for i, a in enumerate(bodies):
        for b in bodies[i + 1 :]:
            trace.min_separation = min(trace.min_separation, math.hypot(a[0] - b[0], a[1] - b[1]))
    trace.times.append(t)
    trace.formation_error.append(errors)
    trace.user_distance.append(math.hypot(master[0] - user[0], master[1] - user[1]))
    trace.robot_yaw.append([r.pose[2] for r in robots])
