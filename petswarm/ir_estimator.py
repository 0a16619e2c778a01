"""Relative location from one sweep of the 12 IR readings: bearing and distance of the transmitter.

Pure and vectorised over sweeps. Two estimators, chosen by name:

- ``paper``: the swarm paper's equations (1)-(3) (spec section 4) on the strongest receiver n and its
  neighbours n+1 and n-1; exact on noise-free cosine responses.
- ``lsq``: a weighted least-squares fit of strength and bearing to the clipped cosine response of every
  receiver that faces the source (five or six of them instead of three), weighted by each reading's
  noise variance; also exact on noise-free input, and more accurate under noise.

Both first subtract the module's known ambient level, and turn the strength into a distance with the
inverse of the module's strength-distance law. The estimator is given the module's calibration (an
``IrConfig``), never the truth. No signal (the strongest receiver within ``detection_sigmas`` noise
sigmas of ambient) gives no estimate. Saturated readings are handled, and flagged, rather than trusted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from radio_hub.light import RECEIVER_AXES_RAD, RECEIVERS, IrConfig

METHODS = ("paper", "lsq")
"""Estimator names accepted by ``estimate``."""
SECTOR_RAD = np.pi / 6
LSQ_ITERATIONS = 4
"""Reweighting rounds of the ``lsq`` fit: from the paper's start it settles in two or three."""
LSQ_MIN_RECEIVERS = 3
"""Unsaturated receivers facing the source that the ``lsq`` fit needs; with fewer, it falls back."""
_COS = np.cos(RECEIVER_AXES_RAD)
_SIN = np.sin(RECEIVER_AXES_RAD)


@dataclass(frozen=True)
class IrEstimate:
    """Where one sweep puts the transmitter, relative to the receiving robot.

    ``bearing_rad`` in [0, 2 pi), counter-clockwise from the robot's heading; ``distance_m``; ``strength``
    (R of equation (3): the on-axis strength above ambient, in counts). ``saturated`` means at least one
    reading was at full scale: the bearing is still usable, but when too few receivers were below full
    scale the distance is only an upper bound (the transmitter is at most that far).
    """

    bearing_rad: float
    distance_m: float
    strength: float
    saturated: bool = False


@dataclass(frozen=True)
class IrEstimates:
    """The estimates of many sweeps at once (arrays of one length); ``valid`` is False where no signal."""

    bearing_rad: np.ndarray
    distance_m: np.ndarray
    strength: np.ndarray
    valid: np.ndarray
    saturated: np.ndarray

    def __len__(self) -> int:
        return len(self.valid)

    def at(self, i: int) -> IrEstimate | None:
        """Sweep ``i`` as an ``IrEstimate``, or None where there was no signal."""
        if not self.valid[i]:
            return None
        return IrEstimate(
            float(self.bearing_rad[i]), float(self.distance_m[i]), float(self.strength[i]), bool(self.saturated[i])
        )


def estimate(readings: ArrayLike, config: IrConfig, method: str = "lsq") -> IrEstimate | None:
    """Bearing, distance and strength of the transmitter from one sweep of 12 readings (counts).

    Returns None when no receiver rises above the no-signal threshold (no transmitter in range).
    """
    sweep = np.asarray(readings, dtype=float)
    if sweep.shape != (RECEIVERS,):
        raise ValueError(f"one sweep is {RECEIVERS} readings, got shape {sweep.shape}")
    return estimate_many(sweep[None, :], config, method).at(0)


def estimate_many(readings: ArrayLike, config: IrConfig, method: str = "lsq") -> IrEstimates:
    """``estimate`` for an array of sweeps, shape (N, 12), vectorised."""
    if method not in METHODS:
        raise ValueError(f"unknown IR estimator {method!r}; known: {', '.join(METHODS)}")
    raw = np.asarray(readings, dtype=float).reshape(-1, RECEIVERS)
    strengths = raw - config.ambient_counts
    saturated = raw >= config.saturation_counts
    fit = paper_fit if method == "paper" else lsq_fit
    strength, bearing, fallback = fit(strengths, saturated, config)
    clipped_strength = np.full_like(strength, config.saturation_counts - config.ambient_counts)
    strength = np.where(fallback, clipped_strength, strength)
    bearing = np.where(fallback, saturated_bearing(saturated), bearing)
    return IrEstimates(
        bearing_rad=wrap_bearing(bearing),
        distance_m=distance_from_strength(strength, config),
        strength=strength,
        valid=strengths.max(axis=1) > config.detection_threshold_counts,
        saturated=saturated.any(axis=1),
    )


def wrap_bearing(bearing_rad: ArrayLike) -> np.ndarray:
    """Angles into [0, 2 pi) (np.mod alone gives 2 pi for tiny negative angles)."""
    wrapped = np.mod(np.asarray(bearing_rad, dtype=float), 2 * np.pi)
    return np.where(wrapped >= 2 * np.pi, 0.0, wrapped)


def distance_from_strength(strength: ArrayLike, config: IrConfig) -> np.ndarray:
    """Inverse of the module's law strength = P / d^2: d = sqrt(P / R), kept within the near field and range.

    Strengths at or below 0 give the maximum range (the weakest signal the module can mean).
    """
    r = np.asarray(strength, dtype=float)
    with np.errstate(divide="ignore"):
        d = np.sqrt(config.power_counts_at_1m / np.maximum(r, 0.0))
    return np.clip(d, config.near_field_m, config.max_range_m)


def paper_fit(
    strengths: np.ndarray, saturated: np.ndarray, config: IrConfig
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Equations (1)-(3) per sweep: (R, phi, fallback), fallback where the strongest reading saturated.

    n is the strongest receiver, r0 its strength, r1 and r-1 those of receivers n+1 and n-1 (mod 12);
    a = (r1 + r-1 + 2 r0) / (2 cos(pi/6) + 2), b = (r1 - r-1) / (2 sin(pi/6)), theta = atan(b / a)
    (as atan2, equal while a > 0, which holds when r0 is the strongest), R = sqrt(a^2 + b^2),
    phi = n pi/6 + theta.
    """
    rows = np.arange(len(strengths))
    n = np.argmax(strengths, axis=1)
    r0 = strengths[rows, n]
    r1 = strengths[rows, (n + 1) % RECEIVERS]
    r_1 = strengths[rows, (n - 1) % RECEIVERS]
    a = (r1 + r_1 + 2 * r0) / (2 * np.cos(SECTOR_RAD) + 2)
    b = (r1 - r_1) / (2 * np.sin(SECTOR_RAD))
    theta = np.arctan2(b, a)
    return np.hypot(a, b), n * SECTOR_RAD + theta, saturated[rows, n]


def lsq_fit(
    strengths: np.ndarray, saturated: np.ndarray, config: IrConfig
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted least squares of the clipped cosine response: (R, phi, fallback) per sweep.

    On the receivers k facing the source (cos(axis_k - phi) > 0) the response is linear in
    (a, b) = R (cos phi, sin phi): r_k = a cos(axis_k) + b sin(axis_k). Each round picks those receivers
    from the current bearing, leaves out saturated ones, weights each by the inverse variance of its
    reading (noise floor plus relative noise of its predicted strength) and solves the 2x2 normal
    equations. It starts from the paper's estimate; with fewer than LSQ_MIN_RECEIVERS usable receivers
    it falls back (see ``saturated_bearing``).
    """
    strength, bearing, paper_saturated = paper_fit(strengths, saturated, config)
    bearing = np.where(paper_saturated, saturated_bearing(saturated), bearing)
    usable_count = np.zeros(len(strengths), dtype=int)
    for _ in range(LSQ_ITERATIONS):
        gain = np.cos(RECEIVER_AXES_RAD - bearing[:, None])
        usable = (gain > 0) & ~saturated
        usable_count = usable.sum(axis=1)
        weight = usable / _reading_variance(strength[:, None] * np.clip(gain, 0, None), config)
        solved = _weighted_solve(weight, strengths)
        ok = usable_count >= LSQ_MIN_RECEIVERS
        strength = np.where(ok, np.hypot(*solved), strength)
        bearing = np.where(ok, np.arctan2(solved[1], solved[0]), bearing)
    return strength, bearing, usable_count < LSQ_MIN_RECEIVERS


def saturated_bearing(saturated: np.ndarray) -> np.ndarray:
    """Fallback bearing when full-scale readings hide the strength: the circular mean of the saturated
    receivers' axes (they form an arc centred on the source, so this is within 15 degrees of it)."""
    return np.arctan2(saturated @ _SIN, saturated @ _COS)


def _reading_variance(predicted: np.ndarray, config: IrConfig) -> np.ndarray:
    if config.noiseless:
        return np.ones_like(predicted)
    return config.noise_floor_counts**2 + (config.relative_noise * predicted) ** 2


def _weighted_solve(weight: np.ndarray, strengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(a, b) minimising sum_k w_k (r_k - a cos_k - b sin_k)^2 per row; NaN where singular."""
    s_cc = weight @ (_COS * _COS)
    s_cs = weight @ (_COS * _SIN)
    s_ss = weight @ (_SIN * _SIN)
    y_c = (weight * strengths) @ _COS
    y_s = (weight * strengths) @ _SIN
    det = s_cc * s_ss - s_cs**2
    with np.errstate(divide="ignore", invalid="ignore"):
        return (s_ss * y_c - s_cs * y_s) / det, (s_cc * y_s - s_cs * y_c) / det
