"""The slave-role controller (swarm paper Fig. 12, 13) and the dead reckoning that feeds it. Pure code.

IR gives a robot the master's (and a neighbour's) distance and bearing only once per token round, so a
``RelativeTracker`` carries the master's pose in this robot's frame between fixes by dead-reckoning both
motions: this robot's own command and the velocity the master broadcasts. ``slave_decision`` then turns the
gap between the reference slot and the estimated location into (vx, vy), adds the master's motion as
feed-forward (which also hides the delay of the sequential IR process), aligns the heading with the
master's, and corrects a twisted heading from the bearings to the master and a neighbour (Fig. 13).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from petswarm.controllers.formation_shapes import Mode
from petswarm.controllers.motion import (
    DriveLimits,
    MotorCommand,
    Pose,
    Vec,
    integrate,
    point_velocity,
    relative,
    rotate,
    wrap,
)

Velocity = MotorCommand | tuple[float, float, float]
"""A body's twist (vx, vy, omega) in its own frame."""


@dataclass(frozen=True)
class RelativeFix:
    """Another robot seen from this one at time ``t``: distance and bearing from IR, in this robot's frame.

    ``heading_rad`` is the other's heading minus this robot's, from the heading exchange; None when not
    known (the compass-free case of the paper: the formation's parallel headings are then assumed, and the
    twist correction removes the error).
    """

    distance_m: float
    bearing_rad: float
    heading_rad: float | None
    t: float

    def __post_init__(self) -> None:
        if not self.distance_m >= 0:
            raise ValueError(f"RelativeFix.distance_m must not be negative, got {self.distance_m!r}")

    @property
    def position(self) -> Vec:
        """The other robot's position in this robot's frame."""
        return (self.distance_m * math.cos(self.bearing_rad), self.distance_m * math.sin(self.bearing_rad))


@dataclass(frozen=True)
class SlaveControllerConfig:
    """Gains of the slave controller. The paper gives the structure, not the numbers: these are the project's."""

    k_position: float = 1.0
    """Location gain (1/s): a 0.3 m error asks 0.3 m/s on top of the feed-forward, slow enough that a 0.5 s
    old, 3 cm noisy fix does not make the robot jitter, fast enough to settle in a few seconds."""
    k_heading: float = 1.5
    """Heading-alignment gain (1/s) on the relative heading from the heading exchange."""
    k_twist: float = 0.6
    """Gain (1/s) of the twisted-heading correction on the heading error the twist implies."""
    twist_tolerance_rad: float = math.radians(5)
    """|twist| accepted without correction: above the scatter of two 3 degree IR bearings."""
    settled_m: float = 0.2
    """The twist means a twisted heading only once the robot is near its reference; farther out a location
    error also makes bearings differ, so the correction waits."""
    min_twist_sensitivity: float = 0.25
    """How much a heading twist must move the neighbour's bearing (rad per rad) for the twist to be trusted
    (``twist_sensitivity``): 1 for a column's neighbour between this robot and the master; 0 for a neighbour
    on the circle whose diameter joins this robot and the master, or the master itself."""
    rotation_threshold_rps: float = 0.05
    """User yaw rates (rad/s) below this are gyro noise, not a rotation."""
    limits: DriveLimits = field(default_factory=DriveLimits)

    def __post_init__(self) -> None:
        for name in ("k_position", "k_heading", "min_twist_sensitivity", "settled_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"SlaveControllerConfig.{name} must be positive, got {getattr(self, name)!r}")
        for name in ("k_twist", "twist_tolerance_rad", "rotation_threshold_rps"):
            if getattr(self, name) < 0:
                raise ValueError(f"SlaveControllerConfig.{name} must not be negative, got {getattr(self, name)!r}")


def _twist_of(velocity: Velocity) -> MotorCommand:
    return velocity if isinstance(velocity, MotorCommand) else MotorCommand(*velocity)


class RelativeTracker:
    """Another robot's pose in this robot's frame, refreshed by IR fixes and dead-reckoned in between."""

    def __init__(self) -> None:
        self._pose: Pose | None = None
        self._t: float | None = None

    @property
    def pose(self) -> Pose | None:
        """The estimate ``(x, y, relative heading)``, or None before the first fix."""
        return self._pose

    @property
    def t(self) -> float | None:
        """The time the estimate is for: the last fix's time plus the predicted steps since."""
        return self._t

    def fix(self, fix: RelativeFix) -> Pose:
        """Take a fresh IR fix; without heading information the headings are taken as parallel."""
        x, y = fix.position
        heading = 0.0 if fix.heading_rad is None else wrap(fix.heading_rad)
        self._pose, self._t = (x, y, heading), fix.t
        return self._pose

    def predict(self, dt: float, own_cmd: MotorCommand, master_velocity: Velocity) -> Pose | None:
        """Advance ``dt`` seconds: the other body moves with ``master_velocity`` (its own frame), this one with
        ``own_cmd``; the estimate is the other's new pose seen from this body's new pose."""
        if dt < 0:
            raise ValueError(f"dt must not be negative, got {dt!r}")
        if self._pose is None:
            return None
        mine = integrate((0.0, 0.0, 0.0), own_cmd, dt)
        theirs = integrate(self._pose, _twist_of(master_velocity), dt)
        self._pose = relative(mine, theirs)
        self._t = (self._t or 0.0) + dt
        return self._pose


@dataclass(frozen=True)
class SlaveDecision:
    """A slave's command with the figures behind it, for the run's log."""

    command: MotorCommand
    location_error_m: float
    """Distance from the estimated location to the reference slot."""
    heading_error_rad: float
    """The master's heading minus this robot's, as estimated."""
    twist_rad: float | None
    """Fig. 13's d_theta = d_theta_m - d_theta_s; None without an informative neighbour fix."""
    twist_corrected: bool
    """True when the twist was outside the tolerance and omega was adjusted for it."""


def twist(master_pose_rel: Pose, neighbour_fix: RelativeFix, reference_slot: Vec, neighbour_reference: Vec) -> float:
    """Fig. 13's twist: the gap of the bearing to the master from its reference bearing, minus the same gap
    for the neighbour. Zero at the reference; a pure heading error shifts both bearings alike, so what is left
    is the robot's swing round the master that a wrongly believed heading causes."""
    rx, ry = reference_slot
    nx, ny = neighbour_reference
    d_theta_m = wrap(math.atan2(-ry, -rx) - math.atan2(master_pose_rel[1], master_pose_rel[0]))
    d_theta_s = wrap(math.atan2(ny - ry, nx - rx) - neighbour_fix.bearing_rad)
    return wrap(d_theta_m - d_theta_s)


def twist_sensitivity(reference_slot: Vec, neighbour_reference: Vec) -> float:
    """d(twist)/d(heading error) near the reference, for a robot that keeps its bearing to the master right.

    Swinging round the master by delta (with the heading wrong by delta) turns the neighbour's bearing by
    -(v . q) / |v|^2 * delta, with q the neighbour's slot and v = q - r its offset from this robot's slot.
    """
    vx, vy = neighbour_reference[0] - reference_slot[0], neighbour_reference[1] - reference_slot[1]
    norm2 = vx * vx + vy * vy
    if norm2 == 0:
        raise ValueError("neighbour_reference must differ from reference_slot")
    return -(vx * neighbour_reference[0] + vy * neighbour_reference[1]) / norm2


def _arc_twist(master_velocity: MotorCommand, omega: float, centre: Vec | None) -> MotorCommand:
    """The master frame's motion during a leading-mode rotation: rotation at the user's rate about ``centre``
    (the user, in the master's frame) plus the master's forward speed; without a centre, the master's own
    broadcast twist with the user's real-time rate."""
    if centre is None:
        return MotorCommand(master_velocity.vx, master_velocity.vy, omega)
    return MotorCommand(master_velocity.vx + omega * centre[1], -omega * centre[0], omega)


def slave_decision(
    master_pose_rel: Pose,
    neighbour_fix: RelativeFix | None,
    reference_slot: Vec,
    neighbour_reference: Vec | None,
    master_velocity: Velocity,
    mode: Mode | str,
    user_rotation_rps: float,
    cfg: SlaveControllerConfig,
    rotation_centre: Vec | None = None,
) -> SlaveDecision:
    """The slave controller: (vx, vy) from the location error plus the reference point's feed-forward velocity,
    omega from heading alignment plus the twisted-heading correction.

    ``master_pose_rel`` is the master's pose in this robot's frame (a ``RelativeTracker`` estimate);
    ``reference_slot`` and ``neighbour_reference`` are slots in the master's frame; ``master_velocity`` the
    master's broadcast twist. In leading mode during a user rotation the formation turns about the user at the
    user's real-time rate, so each slave's feed-forward grows with its distance from the rotation centre
    (``rotation_centre``, the user in the master's frame; see ``_arc_twist``). In following mode a rotation
    changes nothing here: the robot keeps driving to its slot as the master turns.
    """
    mx, my, heading_error = master_pose_rel
    motion = _twist_of(master_velocity)
    if Mode(mode) is Mode.LEADING and abs(user_rotation_rps) >= cfg.rotation_threshold_rps:
        motion = _arc_twist(motion, user_rotation_rps, rotation_centre)
    slot_x, slot_y = rotate(reference_slot, heading_error)
    ex, ey = mx + slot_x, my + slot_y
    ffx, ffy = rotate(point_velocity(motion, reference_slot), heading_error)
    location_error = math.hypot(ex, ey)
    omega = motion.omega + cfg.k_heading * heading_error
    twist_value, corrected = None, False
    if neighbour_fix is not None and neighbour_reference is not None:
        sensitivity = twist_sensitivity(reference_slot, neighbour_reference)
        if abs(sensitivity) >= cfg.min_twist_sensitivity:
            twist_value = twist(master_pose_rel, neighbour_fix, reference_slot, neighbour_reference)
            if abs(twist_value) > cfg.twist_tolerance_rad and location_error <= cfg.settled_m:
                omega -= cfg.k_twist * twist_value / sensitivity
                corrected = True
    cmd = MotorCommand(ffx + cfg.k_position * ex, ffy + cfg.k_position * ey, omega).limited(cfg.limits)
    return SlaveDecision(cmd, location_error, heading_error, twist_value, corrected)


def slave_command(
    master_pose_rel: Pose,
    neighbour_fix: RelativeFix | None,
    reference_slot: Vec,
    neighbour_reference: Vec | None,
    master_velocity: Velocity,
    mode: Mode | str,
    user_rotation_rps: float,
    cfg: SlaveControllerConfig,
    rotation_centre: Vec | None = None,
) -> MotorCommand:
    """``slave_decision``'s command alone."""
    return slave_decision(
        master_pose_rel,
        neighbour_fix,
        reference_slot,
        neighbour_reference,
        master_velocity,
        mode,
        user_rotation_rps,
        cfg,
        rotation_centre,
    ).command
