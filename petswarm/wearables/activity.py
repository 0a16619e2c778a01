"""The belt's activity recognition: movement (stop / rest / walk / run) and rotation, from its IMU.

Pure: samples with their times go in, the recognised activity comes out. Per the Pet-Bot paper (spec
pet-bot-wearable.md, "User activity"):

- Movement. Over a sliding window of the vertical acceleration with gravity removed (the window's
  mean), count sign changes; a gait is periodic, standing still is not. Samples inside a small dead
  band around zero are skipped when counting, so sensor noise at rest does not flip the sign (a
  hysteresis the paper does not mention but any real implementation needs). If periodic, the signal
  magnitude area (SMA, the mean absolute value over the window; one axis, since only z is sensed for
  this) grades it: run above ``sma_run_mps2``, walk above ``sma_walk_mps2``, rest (a slow periodic
  sway or stroll) below. Not periodic: stop.
- Rotation. The gyro's yaw rate (every 70 ms) is moving-average filtered; a rotation starts when the
  filtered rate exceeds ``rotation_start_rps`` and ends when it falls below ``rotation_stop_rps``
  (hysteresis, so a turn is not split). The accumulated angle counts from the start of the rotation:
  when a rotation is declared, the samples in the filter window (which contain its onset) are added, so
  the part of the turn before detection is not lost. After the rotation ends the angle keeps the
  turn's total until the next rotation starts.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from dataclasses import dataclass
from enum import IntEnum
from typing import TYPE_CHECKING, Any

from petswarm.wearables.imu import GYRO_PERIOD_S
from radio_hub.datasheet import build_config
from radio_hub.values import lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)


class Movement(IntEnum):
    """The paper's movement grades (the numbers are its codes)."""

    STOP = 0
    REST = 1
    WALK = 2
    RUN = 3


@dataclass
class Activity:
    """What the belt reports over BLE about its user."""

    movement: Movement = Movement.STOP
    rotating: bool = False
    angular_speed_rps: float = 0.0
    """Filtered yaw rate, counter-clockwise positive."""
    accumulated_angle_rad: float = 0.0
    """Turned since the start of the current (or, when not rotating, the last) rotation; CCW positive."""

    def to_dict(self) -> dict[str, Any]:
        """Plain dict for a message; the movement as its paper code."""
        return {
            "movement": int(self.movement),
            "rotating": self.rotating,
            "angular_speed_rps": self.angular_speed_rps,
            "accumulated_angle_rad": self.accumulated_angle_rad,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Activity:
        """Inverse of ``to_dict``; a missing or bad field raises ValueError naming it."""
        try:
            movement = Movement(data["movement"])
        except (KeyError, ValueError):
            raise ValueError(f"activity.movement must be one of {[int(m) for m in Movement]}") from None
        rotating = data.get("rotating")
        if not isinstance(rotating, bool):
            raise ValueError("activity.rotating must be true or false")
        numbers = {}
        for name in ("angular_speed_rps", "accumulated_angle_rad"):
            value = data.get(name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise ValueError(f"activity.{name} must be a finite number")
            numbers[name] = float(value)
        return cls(movement, rotating, **numbers)


@dataclass
class ActivityConfig:
    """Thresholds of the recogniser, chosen against the gait model of petswarm/wearables/imu.py (see there)."""

    window_s: float = 2.0
    """Movement window: at least two steps even for a slow stroll (1.2 Hz), yet a change shows within ~1 s."""
    dead_band_mps2: float = 0.2
    """Half-width of the band around zero that sign counting ignores: 4 sigma of the accelerometer noise,
    yet below the 0.3 m/s^2 sway of a 0.3 m/s stroll."""
    min_sign_changes: int = 3
    """Periodic needs at least this many sign changes in the window (1.5 cycles)."""
    max_sign_changes: int = 20
    """More than this (above 5 Hz in a 2 s window) is vibration, not a gait."""
    sma_walk_mps2: float = 0.65
    """SMA of the gait model at 0.7 m/s, the boundary between a stroll (rest) and a walk."""
    sma_run_mps2: float = 4.7
    """Midway between the model's fastest walk (3.7 at 2.2 m/s) and slowest run (5.7)."""
    min_coverage: float = 0.75
    """Share of the window that must hold samples before a movement other than stop is reported."""
    gyro_window: int = 5
    """Moving-average length in gyro samples: 5 x 70 ms = 350 ms, one step, so trunk sway averages out."""
    rotation_start_rps: float = 0.35
    """About 20 degrees/s: far above the filtered noise and bias (~0.02 rad/s), well below a turn's peak."""
    rotation_stop_rps: float = 0.15
    """About 9 degrees/s: below it the turn is over."""

    def validate(self) -> ActivityConfig:
        """Raise ValueError naming the field on an inconsistent setting; returns self."""
        if self.window_s <= 0:
            raise ValueError(f"window_s must be > 0, got {self.window_s}")
        if self.dead_band_mps2 < 0:
            raise ValueError(f"dead_band_mps2 must be >= 0, got {self.dead_band_mps2}")
        if not 1 <= self.min_sign_changes <= self.max_sign_changes:
            raise ValueError("min_sign_changes must be in [1, max_sign_changes]")
        if not 0 < self.sma_walk_mps2 < self.sma_run_mps2:
            raise ValueError("sma_walk_mps2 must be in (0, sma_run_mps2)")
        if not 0 < self.min_coverage <= 1:
            raise ValueError(f"min_coverage must be in (0, 1], got {self.min_coverage}")
        if self.gyro_window < 1:
            raise ValueError(f"gyro_window must be >= 1, got {self.gyro_window}")
        if not 0 < self.rotation_stop_rps <= self.rotation_start_rps:
            raise ValueError("rotation_stop_rps must be in (0, rotation_start_rps]")
        return self

    def to_dict(self) -> dict[str, Any]:
        """Plain dict, as accepted by ``from_dict``."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ActivityConfig:
        """Build from a table; unknown keys raise ValueError naming them."""
        return build_config(cls, data, "activity.").validate()


def classify_movement(az: np.ndarray, config: ActivityConfig) -> Movement:
    """Grade one window of vertical acceleration (gravity included) by periodicity, then SMA."""
    dynamic = az - az.mean()
    outside = dynamic[np.abs(dynamic) > config.dead_band_mps2]
    sign_changes = int(np.count_nonzero(np.diff(np.sign(outside))))
    if not config.min_sign_changes <= sign_changes <= config.max_sign_changes:
        return Movement.STOP
    sma = float(np.mean(np.abs(dynamic)))
    if sma >= config.sma_run_mps2:
        return Movement.RUN
    if sma >= config.sma_walk_mps2:
        return Movement.WALK
    return Movement.REST


class ActivityRecognizer:
    """Recognises one belt's activity from its accelerometer and gyro samples, fed in time order."""

    def __init__(self, config: ActivityConfig | None = None) -> None:
        self.config = (config or ActivityConfig()).validate()
        self._accel: deque[tuple[float, float]] = deque()
        self._gyro: deque[tuple[float, float]] = deque(maxlen=self.config.gyro_window)
        self._last_gyro_t: float | None = None
        self.rotating = False
        self.angular_speed_rps = 0.0
        self.accumulated_angle_rad = 0.0
        self.rotation_started_at: float | None = None
        """Time of the gyro sample on which the current (or last) rotation was declared; None before any."""

    def add_accel(self, t: float, az: float) -> None:
        """One accelerometer z sample (m/s^2, gravity included) at time ``t`` (s)."""
        _check_sample("az", t, az)
        if self._accel and t < self._accel[-1][0]:
            raise ValueError(f"accel sample at t={t} is older than the last one")
        self._accel.append((t, az))
        while self._accel[0][0] < t - self.config.window_s:
            self._accel.popleft()

    def add_gyro(self, t: float, wz: float) -> None:
        """One gyro yaw-rate sample (rad/s, CCW positive) at time ``t`` (s); updates the rotation state."""
        _check_sample("wz", t, wz)
        if self._last_gyro_t is not None and t <= self._last_gyro_t:
            raise ValueError(f"gyro sample at t={t} is not newer than the last one")
        dt = GYRO_PERIOD_S if self._last_gyro_t is None else t - self._last_gyro_t
        self._last_gyro_t = t
        self._gyro.append((dt, wz))
        self.angular_speed_rps = sum(w for _, w in self._gyro) / len(self._gyro)
        if self.rotating:
            self.accumulated_angle_rad += wz * dt
            if abs(self.angular_speed_rps) < self.config.rotation_stop_rps:
                self.rotating = False
        elif abs(self.angular_speed_rps) > self.config.rotation_start_rps:
            self.rotating = True
            self.rotation_started_at = t
            self.accumulated_angle_rad = sum(w * d for d, w in self._gyro)

    def activity(self, now: float) -> Activity:
        """The activity as of ``now``: movement over the last window, rotation as of the last gyro sample."""
        return Activity(self.movement(now), self.rotating, self.angular_speed_rps, self.accumulated_angle_rad)

    def movement(self, now: float) -> Movement:
        """Movement grade over the window ending at ``now`` (stop until the window is mostly filled)."""
        start = now - self.config.window_s
        samples = [(t, az) for t, az in self._accel if start <= t <= now]
        if len(samples) < 2 or samples[-1][0] - samples[0][0] < self.config.min_coverage * self.config.window_s:
            return Movement.STOP
        return classify_movement(np.array([az for _, az in samples]), self.config)


def _check_sample(name: str, t: float, value: float) -> None:
    if not (math.isfinite(t) and math.isfinite(value)):
        raise ValueError(f"{name} sample must be finite, got t={t}, {name}={value}")
