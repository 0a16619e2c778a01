"""The belt's IMU, emulated from the user's motion: vertical acceleration and yaw rate.

Pure and seeded: time and the user's true speed and yaw rate go in, readings come out; noise comes
from a numpy Generator the caller seeds. The paper gives no gait data, so the gait is a documented
model (``GaitModel`` below, numbers from common biomechanics figures):

- Standing (below ``standing_speed_mps``): no gait at all, only sensor noise around gravity.
- Walking: the pelvis rises and falls once per step. Cadence grows with speed, 1.0 Hz + 0.667 Hz per
  m/s (1.8 Hz at 1.2 m/s, ~1.3 Hz for a 0.4 m/s stroll, 2.5 Hz at the walk-run transition), and the
  vertical acceleration amplitude grows as 1.8 v^1.5 m/s^2 (0.3 at 0.3 m/s, 2.4 at 1.2 m/s): a stroll
  gives a small periodic motion, a brisk walk a large one.
- Running (above ``run_speed_mps`` = 2.2 m/s, where people switch gait): cadence 2.6 Hz + 0.1 Hz per
  m/s (~2.8 Hz), amplitude 9 m/s^2 + 2 per m/s above 2.2 (flight and landing: about 1 g).
- A heel-strike second harmonic of a quarter of the amplitude, and a per-person cadence factor (drawn
  once, 3 % spread) so two users do not step in lock-step.

The phase of the gait is integrated over time, so a change of speed changes the frequency without a
jump in the signal: ``accel_z`` must be called with non-decreasing times.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from radio_hub.datasheet import build_config
from radio_hub.values import lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

GRAVITY_MPS2 = 9.81
ACCEL_PERIOD_S = 0.02
"""The belt samples its accelerometer at 50 Hz: ten samples per step even when running."""
GYRO_PERIOD_S = 0.07
"""Spec: the gyro is sampled every 70 ms."""


@dataclass
class ImuConfig:
    """Gait model and sensor noise of the emulated belt IMU (see the module docstring for the why)."""

    standing_speed_mps: float = 0.05
    """Below it the user stands: no gait oscillation."""
    run_speed_mps: float = 2.2
    """At and above it the user runs (the human walk-run transition is at about 2.0-2.2 m/s)."""
    walk_cadence_hz: float = 1.0
    walk_cadence_per_mps: float = 0.667
    walk_amplitude_gain: float = 1.8
    """Walking vertical acceleration amplitude is ``gain * v**1.5`` (m/s^2)."""
    run_cadence_hz: float = 2.6
    run_cadence_per_mps: float = 0.1
    run_amplitude_mps2: float = 9.0
    run_amplitude_per_mps: float = 2.0
    harmonic_ratio: float = 0.25
    """Second harmonic (heel strike) relative to the fundamental."""
    cadence_spread: float = 0.03
    """Standard deviation of the per-person cadence factor."""
    accel_noise_mps2: float = 0.05
    """Accelerometer noise plus body tremor per sample (a MEMS part alone is ~0.01 m/s^2 at 50 Hz)."""
    gyro_noise_rps: float = 0.02
    """Gyro noise plus trunk sway per sample (about 1 degree/s)."""
    gyro_bias_rps: float = 0.01
    """Uncalibrated gyro offset (about 0.6 degree/s, typical of a consumer MEMS gyro after warm-up)."""

    def validate(self) -> ImuConfig:
        """Raise ValueError naming the field on a non-physical setting; returns self."""
        if not 0 <= self.standing_speed_mps < self.run_speed_mps:
            raise ValueError("standing_speed_mps must be in [0, run_speed_mps)")
        for name in ("walk_cadence_hz", "run_cadence_hz", "walk_amplitude_gain", "run_amplitude_mps2"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("harmonic_ratio", "cadence_spread", "accel_noise_mps2", "gyro_noise_rps"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        return self

    def to_dict(self) -> dict[str, Any]:
        """Plain dict, as accepted by ``from_dict``."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ImuConfig:
        """Build from a table; unknown keys raise ValueError naming them."""
        return build_config(cls, data, "imu.").validate()


def step_frequency_hz(speed_mps: float, config: ImuConfig) -> float:
    """Steps per second at ``speed_mps`` (0 when standing), before the per-person factor."""
    if speed_mps < config.standing_speed_mps:
        return 0.0
    if speed_mps < config.run_speed_mps:
        return config.walk_cadence_hz + config.walk_cadence_per_mps * speed_mps
    return config.run_cadence_hz + config.run_cadence_per_mps * speed_mps


def gait_amplitude_mps2(speed_mps: float, config: ImuConfig) -> float:
    """Amplitude of the vertical acceleration's fundamental at ``speed_mps`` (0 when standing)."""
    if speed_mps < config.standing_speed_mps:
        return 0.0
    if speed_mps < config.run_speed_mps:
        return config.walk_amplitude_gain * speed_mps**1.5
    return config.run_amplitude_mps2 + config.run_amplitude_per_mps * (speed_mps - config.run_speed_mps)


class BeltImu:
    """One belt's IMU. Stateful only in the gait phase (integrated so speed changes are smooth)."""

    def __init__(self, rng: np.random.Generator, config: ImuConfig | None = None) -> None:
        self.config = (config or ImuConfig()).validate()
        self._rng = rng
        self.cadence_factor = float(1.0 + self.config.cadence_spread * rng.standard_normal())
        """This person's cadence relative to the model's (drawn once)."""
        self._phase = float(rng.uniform(0, 2 * math.pi))
        self._last_t: float | None = None

    def accel_z(self, t: float, speed_mps: float) -> float:
        """Vertical acceleration (m/s^2, gravity included) at time ``t`` for a user moving at ``speed_mps``."""
        if not (math.isfinite(speed_mps) and speed_mps >= 0):
            raise ValueError(f"speed_mps must be a finite speed >= 0, got {speed_mps}")
        if self._last_t is not None and t < self._last_t:
            raise ValueError(f"t must not go backwards: {t} after {self._last_t}")
        frequency = step_frequency_hz(speed_mps, self.config) * self.cadence_factor
        if self._last_t is not None:
            self._phase = (self._phase + 2 * math.pi * frequency * (t - self._last_t)) % (2 * math.pi)
        self._last_t = t
        amplitude = gait_amplitude_mps2(speed_mps, self.config)
        gait = amplitude * (math.sin(self._phase) + self.config.harmonic_ratio * math.sin(2 * self._phase))
        return GRAVITY_MPS2 + gait + self.config.accel_noise_mps2 * float(self._rng.standard_normal())

    def gyro_z(self, t: float, yaw_rate: float) -> float:
        """Yaw rate reading (rad/s, counter-clockwise positive) for a true ``yaw_rate``: plus bias and noise."""
        if not math.isfinite(yaw_rate):
            raise ValueError(f"yaw_rate must be finite, got {yaw_rate}")
        return yaw_rate + self.config.gyro_bias_rps + self.config.gyro_noise_rps * float(self._rng.standard_normal())
