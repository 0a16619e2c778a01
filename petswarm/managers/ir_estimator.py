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

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

from radio_hub.datasheet import RECEIVERS, IrConfig, receiver_axes_rad
from radio_hub.values import lazy_numpy

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import ArrayLike
else:
    np = lazy_numpy(__name__)

METHODS = ("paper", "lsq")
"""Estimator names accepted by ``estimate``."""
SECTOR_RAD = math.pi / 6  # the same float as np.pi / 6
LSQ_ITERATIONS = 4
"""Reweighting rounds of the ``lsq`` fit: from the paper's start it settles in two or three."""
LSQ_MIN_RECEIVERS = 3
"""Unsaturated receivers facing the source that the ``lsq`` fit needs; with fewer, it falls back."""


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


def estimate_many(
    readings: ArrayLike,
    config: IrConfig,
    method: str = "lsq",
    brightness: ArrayLike | None = None,
    groups: Sequence[int] | None = None,
) -> IrEstimates:
    """``estimate`` for an array of sweeps, shape (N, 12), vectorised.

    ``brightness``: per sweep, how many times brighter than ``config``'s emitter its source is (default 1
    for all): sweep i is read with the calibration ``config.brighter(brightness[i])``, so sources of
    different brightness go through one call. ``groups``: the sizes of the blocks of consecutive rows that
    are separate calls' worth (several robots' sweeps in one call); every row's estimate is then, bit for
    bit, what the call of its block alone gives (see ``saturated_bearing``)."""
    if method not in METHODS:
        raise ValueError(f"unknown IR estimator {method!r}; known: {', '.join(METHODS)}")
    raw = np.asarray(readings, dtype=float).reshape(-1, RECEIVERS)
    strengths = raw - config.ambient_counts
    saturated = raw >= config.saturation_counts
    fit = paper_fit if method == "paper" else lsq_fit
    strength, bearing, fallback = fit(strengths, saturated, config, groups)
    # (ufuncs and count_nonzero rather than the array methods: these arrays are small, the calls many)
    if np.count_nonzero(fallback):
        strength = np.where(fallback, config.saturation_counts - config.ambient_counts, strength)
        bearing = np.where(fallback, _grouped_saturated_bearing(saturated, fallback, groups), bearing)
    return IrEstimates(
        bearing_rad=wrap_bearing(bearing),
        distance_m=distance_from_strength(strength, config, brightness),
        strength=strength,
        valid=np.maximum.reduce(strengths, axis=1) > config.detection_threshold_counts,
        saturated=np.logical_or.reduce(saturated, axis=1),
    )


def wrap_bearing(bearing_rad: ArrayLike) -> np.ndarray:
    """Angles into [0, 2 pi) (np.mod alone gives 2 pi for tiny negative angles)."""
    wrapped = np.mod(np.asarray(bearing_rad, dtype=float), 2 * np.pi)
    full_turn = wrapped >= 2 * np.pi
    return np.where(full_turn, 0.0, wrapped) if np.count_nonzero(full_turn) else wrapped


def distance_from_strength(strength: ArrayLike, config: IrConfig, brightness: ArrayLike | None = None) -> np.ndarray:
    """Inverse of the module's law strength = P / d^2: d = sqrt(P / R), kept within the near field and range.

    Strengths at or below 0 give the maximum range (the weakest signal the module can mean). ``brightness``
    (per strength, default 1): read each with the calibration ``config.brighter(brightness)``.
    """
    r = np.asarray(strength, dtype=float)
    power, max_range = config.power_counts_at_1m, config.max_range_m
    if brightness is not None:
        power, max_range = _brighter(config, brightness)
    positive = np.maximum(r, 0.0)
    if np.count_nonzero(positive) == positive.size:
        d = np.sqrt(power / positive)
    else:
        with np.errstate(divide="ignore"):
            d = np.sqrt(power / positive)
    return np.minimum(np.maximum(d, config.near_field_m), max_range)  # np.clip, without its overhead


def _brighter(config: IrConfig, brightness: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Per factor, the power and range of ``config.brighter(factor)``: P f and R sqrt(f) (``brighter`` takes
    f ** 0.5, equal to sqrt(f) for the beacon gains times the person's power, and within an ulp for any f)."""
    factors = np.asarray(brightness, dtype=float).reshape(-1)
    if len(factors) and not np.minimum.reduce(factors) > 0:
        raise ValueError(f"brightness must be > 0, got {sorted(set(factors.tolist()))}")
    return config.power_counts_at_1m * factors, config.max_range_m * np.sqrt(factors)


def paper_fit(
    strengths: np.ndarray, saturated: np.ndarray, config: IrConfig, groups: Sequence[int] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Equations (1)-(3) per sweep: (R, phi, fallback), fallback where the strongest reading saturated.

    n is the strongest receiver, r0 its strength, r1 and r-1 those of receivers n+1 and n-1 (mod 12);
    a = (r1 + r-1 + 2 r0) / (2 cos(pi/6) + 2), b = (r1 - r-1) / (2 sin(pi/6)), theta = atan(b / a)
    (as atan2, equal while a > 0, which holds when r0 is the strongest), R = sqrt(a^2 + b^2),
    phi = n pi/6 + theta.
    """
    strength, theta, n, fallback = _paper(strengths, saturated)
    return strength, n * SECTOR_RAD + theta, fallback


def _paper(strengths: np.ndarray, saturated: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The paper's R and theta, with n (the strongest receiver) and where it saturated."""
    rows = np.arange(len(strengths))
    n = strengths.argmax(axis=1)
    # r-1, r0, r1 in one gather: the sweep with its ends wrapped round, then three receivers from n - 1 on
    r_1, r0, r1 = strengths[:, _tables().wrapped][rows[:, None], n[:, None] + _tables().trio].T
    a = (r1 + r_1 + 2 * r0) / (2 * np.cos(SECTOR_RAD) + 2)
    b = (r1 - r_1) / (2 * np.sin(SECTOR_RAD))
    strongest_saturated = saturated[rows, n] if np.count_nonzero(saturated) else np.zeros(len(rows), dtype=bool)
    return np.hypot(a, b), np.arctan2(b, a), n, strongest_saturated


class _Tables(NamedTuple):
    """The receivers' geometry as the fits use it, built at the first estimate (importing this module
    imports no numpy)."""

    cos: np.ndarray
    sin: np.ndarray
    wrapped: np.ndarray
    """Receiver indices 11, 0, 1, ..., 11, 0: receiver n's neighbours are columns n and n + 2 of a wrapped sweep."""
    trio: np.ndarray
    axes: np.ndarray
    """(2, 12): a source (a, b) = R (cos phi, sin phi) gives receiver k the response a cos_k + b sin_k."""
    normal: np.ndarray
    """(12, 3): weights @ this = the normal equations' sums (s_cc, s_cs, s_ss)."""
    cross: np.ndarray
    facing_zero: np.ndarray
    """The receivers a source at bearing 0 faces."""


@functools.cache
def _tables() -> _Tables:
    """The fits' tables, computed once."""
    cos = np.cos(receiver_axes_rad())
    sin = np.sin(receiver_axes_rad())
    return _Tables(
        cos=cos,
        sin=sin,
        wrapped=np.r_[RECEIVERS - 1, np.arange(RECEIVERS), 0],
        trio=np.arange(3),
        axes=np.stack([cos, sin]),
        normal=np.stack([cos * cos, cos * sin, sin * sin], axis=1),
        cross=np.array([2, 0]),
        facing_zero=np.cos(receiver_axes_rad()) > 0,
    )


def lsq_fit(
    strengths: np.ndarray, saturated: np.ndarray, config: IrConfig, groups: Sequence[int] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted least squares of the clipped cosine response: (R, phi, fallback) per sweep.

    On the receivers k facing the source (cos(axis_k - phi) > 0) the response is linear in
    (a, b) = R (cos phi, sin phi): r_k = a cos(axis_k) + b sin(axis_k). Each round picks those receivers
    from the current estimate, leaves out saturated ones, weights each by the inverse variance of its
    reading (noise floor plus relative noise of its predicted strength) and solves the 2x2 normal
    equations. It starts from the paper's estimate; with fewer than LSQ_MIN_RECEIVERS usable receivers
    it falls back (see ``saturated_bearing``). ``groups``: as ``estimate_many``'s.

    The estimate is carried as (a, b): receiver k's predicted strength R max(cos(axis_k - phi), 0) is
    max(a cos_k + b sin_k, 0), which faces the source exactly where it is positive.
    """
    strength, theta, n, paper_saturated = _paper(strengths, saturated)
    bearing = n * SECTOR_RAD + theta
    any_saturated = np.count_nonzero(saturated) > 0
    if any_saturated and np.count_nonzero(paper_saturated):
        bearing = np.where(paper_saturated, _grouped_saturated_bearing(saturated, paper_saturated, groups), bearing)
    noiseless = config.noiseless
    floor2, relative = config.noise_floor_counts**2, config.relative_noise
    # the first round goes from the start's bearing as a bearing: the saturated fallback's is an axis or
    # between two, and receivers at exactly 90 degrees from it are in or out by the rounding of their cosine
    gain = np.cos(receiver_axes_rad() - bearing[:, None])
    start_usable = gain > 0
    start_predicted = strength[:, None] * gain
    if not any_saturated and (noiseless or floor2 > 0) and np.count_nonzero(np.isfinite(strengths)) == strengths.size:
        return _lsq_unsaturated(strengths, start_usable, start_predicted, noiseless, floor2, relative)
    unsaturated = ~saturated
    ab = start_predicted  # replaced by the first round's solution (below) before it is used as (a, b)
    fitted = None  # rows the fit has solved at least once (None: all of them)
    usable_count = np.zeros(len(strengths), dtype=int)
    with np.errstate(divide="ignore", invalid="ignore"):
        for round_ in range(LSQ_ITERATIONS):
            if round_ == 0:
                usable, predicted = start_usable, start_predicted
            else:
                predicted = ab @ _tables().axes
                usable = predicted > 0
                if not ab.all():  # a fit of exactly (0, 0) has bearing atan2(0, 0) = 0, and faces as that does
                    zero = ~ab.any(axis=1)
                    usable = np.where(zero[:, None], _tables().facing_zero, usable)
                if fitted is not None:  # rows still at their start stay on its receivers
                    usable = np.where(fitted[:, None], usable, start_usable)
                    predicted = np.where(fitted[:, None], predicted, start_predicted)
            if any_saturated:
                usable = usable & unsaturated
            usable_count = usable.view(np.uint8).sum(axis=1)
            if noiseless:
                weight = usable.astype(float)
            elif floor2 > 0:  # a receiver left out has weight 0 whatever its predicted strength
                weight = usable / (floor2 + (relative * predicted) ** 2)
            else:
                weight = usable / (floor2 + (relative * np.maximum(predicted, 0.0)) ** 2)
            solved = _solve(weight, strengths)
            ok = usable_count >= LSQ_MIN_RECEIVERS
            if round_ == 0 and not ok.all():
                ab = strength[:, None] * np.stack([np.cos(bearing), np.sin(bearing)], axis=1)  # the start
                fitted = ok
            elif fitted is not None:
                fitted = fitted | ok
            ab = solved if ok.all() else np.where(ok[:, None], solved, ab)
    a, b = ab.T
    return np.hypot(a, b), np.arctan2(b, a), usable_count < LSQ_MIN_RECEIVERS


def _lsq_unsaturated(
    strengths: np.ndarray,
    usable: np.ndarray,
    predicted: np.ndarray,
    noiseless: bool,
    floor2: float,
    relative: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``lsq_fit``'s rounds when no reading saturated and all are finite, from the start's receivers and
    predicted strengths: every round then has at least five usable receivers for every sweep (a half plane
    through the source holds five or six of the twelve axes), so none falls back and nothing is counted."""

    def weights(usable: np.ndarray, predicted: np.ndarray) -> np.ndarray:
        return usable.astype(float) if noiseless else usable / (floor2 + (relative * predicted) ** 2)

    ab = _solve(weights(usable, predicted), strengths)
    for _ in range(LSQ_ITERATIONS - 1):
        predicted = ab @ _tables().axes
        usable = predicted > 0
        if np.count_nonzero(ab) != ab.size:  # a fit of exactly (0, 0) has bearing atan2(0, 0) = 0, and faces
            usable = np.where(~ab.any(axis=1)[:, None], _tables().facing_zero, usable)  # as that one does
        ab = _solve(weights(usable, predicted), strengths)
    a, b = ab.T
    return np.hypot(a, b), np.arctan2(b, a), np.zeros(len(strengths), dtype=bool)


def _solve(weight: np.ndarray, strengths: np.ndarray) -> np.ndarray:
    """(a, b) per row (N, 2) minimising sum_k w_k (r_k - a cos_k - b sin_k)^2: the 2x2 normal equations."""
    sums = weight @ _tables().normal  # s_cc, s_cs, s_ss
    y = (weight * strengths) @ _tables().axes.T  # y_c, y_s
    s_cs = sums[:, 1:2]
    det = sums[:, :1] * sums[:, 2:] - s_cs * s_cs
    # (a, b) = (s_ss y_c - s_cs y_s, s_cc y_s - s_cs y_c) / det
    return (sums[:, _tables().cross] * y - s_cs * y[:, ::-1]) / det


def saturated_bearing(saturated: np.ndarray) -> np.ndarray:
    """Fallback bearing when full-scale readings hide the strength: the circular mean of the saturated
    receivers' axes (they form an arc centred on the source, so this is within 15 degrees of it).

    Its products of a matrix and a vector go through BLAS's gemv, whose rounding of a row depends on how
    many rows the matrix has and where the row sits among them (the fits' matrix-matrix products, gemm, do
    not, except for a single row); so rows from several calls' blocks are worked out block by block
    (``_grouped_saturated_bearing``)."""
    return np.arctan2(saturated @ _tables().sin, saturated @ _tables().cos)


def _grouped_saturated_bearing(saturated: np.ndarray, wanted: np.ndarray, groups: Sequence[int] | None) -> np.ndarray:
    """``saturated_bearing`` of each block of ``groups`` alone (all rows as one block when None), for the
    blocks holding a ``wanted`` row; the other blocks' rows are 0."""
    if groups is None:
        return saturated_bearing(saturated)
    bearing = np.zeros(len(saturated))
    start = 0
    for size in groups:
        end = start + size
        if np.count_nonzero(wanted[start:end]):
            bearing[start:end] = saturated_bearing(saturated[start:end])
        start = end
    return bearing
