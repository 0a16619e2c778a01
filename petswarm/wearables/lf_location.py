"""Where the user is, from the LF RSSI the belt measured of the robot's two antennas.

Pure. The belt turns each RSSI into a distance with its calibration curve (``rssi_to_distance``); the
robot solves the triangle of the two distances and the antenna baseline (``locate``), with the
equations of the Pet-Bot paper (spec pet-bot-wearable.md, "Locating the user"):

    alpha = acos((d_l^2 + d_W^2 - d_r^2) / (2 d_l d_W));  x = d_l cos(alpha) - d_W/2;  y = d_l sin(alpha)
    d = sqrt(x^2 + y^2);  theta = atan(x / y)

The paper's frame has its origin midway between the antennas, x along the baseline from the left
antenna to the right one, and y away from the robot (y >= 0: a triangle cannot tell front from back).
In the robot frame (x forward, y left) that is forward = y, left = -x when the user is ahead, and
forward = -y, left = -x when the user is behind (the mirror image through the antenna line, which does
not swap left and right). So the paper's theta is the bearing measured to the right, and the robot-frame
bearing is -theta ahead (pi + theta behind).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from radio_hub.datasheet import LfConfig

RELIABLE_DISTANCE_M = 2.0
"""Spec: the fix is reliable within 2 m ..."""
RELIABLE_HALF_ANGLE_RAD = math.radians(25.0)
"""... and within +-25 degrees of the robot's axis (ahead, or behind in leading mode)."""


def rssi_to_distance(rssi_dbm: float, config: LfConfig) -> float:
    """The belt's calibration curve: the distance at which the mean RSSI equals ``rssi_dbm``.

    The exact inverse of the field's mean curve (the belt was calibrated against it), so the only error
    left is the burst's noise. Readings above the near-field plateau map to the plateau's distance.
    """
    if not math.isfinite(rssi_dbm):
        raise ValueError(f"rssi_dbm must be finite, got {rssi_dbm}")
    distance = 10 ** ((config.rssi_at_1m_dbm - rssi_dbm) / config.decade_loss_db)
    return max(distance, config.near_field_m)


@dataclass(frozen=True)
class UserFix:
    """The user's position relative to the robot (robot frame: x forward, y left), from one LF round."""

    forward_m: float
    left_m: float
    distance_m: float
    """From the robot's centre (midway between the antennas)."""
    bearing_rad: float
    """atan2(left, forward): 0 straight ahead, positive to the left, +-pi straight behind."""
    reliable: bool
    """Within ``RELIABLE_DISTANCE_M`` and ``RELIABLE_HALF_ANGLE_RAD`` of the axis the fix was taken on."""

    @property
    def off_axis_rad(self) -> float:
        """Angle from the nearer end of the robot's axis (ahead or behind), in [0, pi/2]."""
        return min(abs(self.bearing_rad), math.pi - abs(self.bearing_rad))


def locate(d_left: float, d_right: float, config_or_baseline: LfConfig | float, behind: bool = False) -> UserFix | None:
    """Solve the spec's triangle for the user's position; None when the three lengths make no triangle.

    ``d_left``/``d_right``: the belt's distances to the left and right antennas. ``behind``: put the fix
    behind the robot (leading mode, where the user walks behind it) instead of ahead; the triangle
    alone cannot tell. A degenerate triangle (the user on the antenna line) is refused too: it carries
    no direction.
    """
    baseline = config_or_baseline.antenna_baseline_m if isinstance(config_or_baseline, LfConfig) else config_or_baseline
    if not baseline > 0:
        raise ValueError(f"antenna baseline must be > 0, got {baseline}")
    for name, value in (("d_left", d_left), ("d_right", d_right)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite distance > 0, got {value}")
    sides = sorted((d_left, d_right, baseline))
    if sides[2] >= sides[0] + sides[1]:
        return None
    alpha = math.acos((d_left**2 + baseline**2 - d_right**2) / (2 * d_left * baseline))
    x = d_left * math.cos(alpha) - baseline / 2
    y = d_left * math.sin(alpha)
    forward = -y if behind else y
    left = -x
    distance = math.hypot(x, y)
    theta = math.atan(x / y)  # the paper's direction: to the right of the axis, |theta| < pi/2
    reliable = distance <= RELIABLE_DISTANCE_M and abs(theta) <= RELIABLE_HALF_ANGLE_RAD
    return UserFix(forward, left, distance, math.atan2(left, forward), reliable)


def locate_from_rssi(
    rssi_left: float | None, rssi_right: float | None, config: LfConfig, behind: bool = False
) -> UserFix | None:
    """``locate`` on the belt's two readings of one round; None when either burst was not heard."""
    if rssi_left is None or rssi_right is None:
        return None
    return locate(rssi_to_distance(rssi_left, config), rssi_to_distance(rssi_right, config), config, behind)
