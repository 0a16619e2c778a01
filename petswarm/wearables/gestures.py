"""The watch's gestures: synthesis of accelerometer traces, recognition, and what they command.

Pure and seeded. The watch frame is x forward (along the forearm, towards the hand), y left, z up: the
forearm held level and pointing ahead, as when gesturing at the robot. An accelerometer reads specific
force, so a watch at rest reads +9.81 m/s^2 on z.

Synthesis (``synthesize``). A stroke gesture (forward, backward, left, right, up, down) moves the hand
``D`` metres along one axis from rest to rest with the minimum-jerk-like profile
s(tau) = D (tau - sin(2 pi tau) / 2 pi), whose acceleration is one sine period: a push, then a brake. A
circle moves the hand once round a circle of radius R in the y-z plane (facing the robot), from rest to
rest with the same profile on the angle, clockwise or counter-clockwise, starting near the bottom. A
person's variation: duration 0.4-0.8 s, stroke 0.20-0.45 m, radius 0.10-0.20 m, an uneven tempo (a
power-law time warp, exponent 0.8-1.25), the forearm tilted up to 15 degrees about each axis, the
circle's start +-30 degrees off the bottom, 0.2-0.6 s of stillness either side, and 0.2 m/s^2 of
sensor noise and tremor per sample.

Recognition (``recognize``), template matching: remove gravity (the trace's mean: a gesture starts
and ends at rest, so its own acceleration averages to zero); find the active segment (smoothed
magnitude above a floor and a quarter of its peak); resample it to ``TEMPLATE_SAMPLES`` points,
normalise it to unit energy, and correlate with noise-free templates of every gesture (circles at
several start angles, both ways round). The best template wins if its correlation reaches
``MIN_CORRELATION``; a trace whose motion never rises above ``MIN_MOTION_MPS2`` is no gesture.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable
from enum import StrEnum
from typing import TYPE_CHECKING

from radio_hub.values import lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)


GRAVITY_MPS2 = 9.81
GRAVITY_READING = (0.0, 0.0, GRAVITY_MPS2)
"""What a level, still watch reads (specific force: up)."""
TEMPLATE_SAMPLES = 40
"""Points a segment is resampled to: 10 per quarter of a circle, ample for one-period strokes."""
MIN_MOTION_MPS2 = 0.8
"""Smoothed acceleration magnitude a gesture must exceed: 2.5 x that of the noise (~0.32), under half the weakest
stroke's ~2 peak."""
MIN_CORRELATION = 0.75
"""Correlation with the best template needed to accept; white noise of any level scores at most ~0.35."""
SMOOTHING_S = 0.1
"""Window of the magnitude's moving average used to find the active segment."""
SEGMENT_MARGIN_S = 0.06
"""Kept either side of the active segment, so its quiet start and end are not cut off."""
NOISE_MPS2 = 0.2
MAX_TILT_RAD = math.radians(15)
CIRCLE_START_JITTER_RAD = math.radians(30)


class Gesture(StrEnum):
    """The seven watch gestures of the spec."""

    CIRCLE = "circle"
    FORWARD = "forward"
    BACKWARD = "backward"
    UP = "up"
    DOWN = "down"
    LEFT = "left"
    RIGHT = "right"


COMMANDS: dict[Gesture, str] = {
    Gesture.CIRCLE: "cancel",
    Gesture.FORWARD: "move forward",
    Gesture.BACKWARD: "move backward",
    Gesture.UP: "rotate counter-clockwise 90 degrees",
    Gesture.DOWN: "rotate clockwise 90 degrees",
    Gesture.LEFT: "move left",
    Gesture.RIGHT: "move right",
}
"""The spec's table: what each gesture asks of the robot (circle cancels: back to command-waiting)."""

_STROKE_AXES: dict[Gesture, tuple[int, float]] = {
    Gesture.FORWARD: (0, 1.0),
    Gesture.BACKWARD: (0, -1.0),
    Gesture.LEFT: (1, 1.0),
    Gesture.RIGHT: (1, -1.0),
    Gesture.UP: (2, 1.0),
    Gesture.DOWN: (2, -1.0),
}


def _profile(tau: np.ndarray) -> np.ndarray:
    """Rest-to-rest progress 0 -> 1 with zero speed at both ends."""
    return tau - np.sin(2 * np.pi * tau) / (2 * np.pi)


def _path(gesture: Gesture, tau: np.ndarray, size: float, circle_start: float, circle_sign: float) -> np.ndarray:
    """Hand position (n x 3, metres) along the gesture at normalised times ``tau``."""
    position = np.zeros((len(tau), 3))
    progress = _profile(tau)
    if gesture is Gesture.CIRCLE:
        angle = circle_start + circle_sign * 2 * np.pi * progress
        position[:, 1] = size * (np.cos(angle) - np.cos(circle_start))
        position[:, 2] = size * (np.sin(angle) - np.sin(circle_start))
    else:
        axis, sign = _STROKE_AXES[gesture]
        position[:, axis] = sign * size * progress
    return position


def _acceleration(position: np.ndarray, dt: float) -> np.ndarray:
    return np.gradient(np.gradient(position, dt, axis=0), dt, axis=0)


def _rotation(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def synthesize(gesture: Gesture | str, rng: np.random.Generator, rate_hz: float = 50) -> np.ndarray:
    """A watch accelerometer trace (n x 3, m/s^2, gravity included) of one person making ``gesture``."""
    gesture = Gesture(gesture)
    _check_rate(rate_hz)
    dt = 1.0 / rate_hz
    duration = rng.uniform(0.4, 0.8)
    size = rng.uniform(0.10, 0.20) if gesture is Gesture.CIRCLE else rng.uniform(0.20, 0.45)
    warp = rng.uniform(0.8, 1.25)
    circle_start = -np.pi / 2 + rng.uniform(-CIRCLE_START_JITTER_RAD, CIRCLE_START_JITTER_RAD)
    circle_sign = rng.choice([-1.0, 1.0])
    tau = np.linspace(0.0, 1.0, max(round(duration * rate_hz), 8)) ** warp
    motion = _acceleration(_path(gesture, tau, size, circle_start, circle_sign), dt)
    before, after = (round(rng.uniform(0.2, 0.6) * rate_hz) for _ in range(2))
    world = np.vstack([np.zeros((before, 3)), motion, np.zeros((after, 3))]) + np.array(GRAVITY_READING)
    tilt = _rotation(*rng.uniform(-MAX_TILT_RAD, MAX_TILT_RAD, size=3))
    return world @ tilt + NOISE_MPS2 * rng.standard_normal(world.shape)


@functools.cache
def _templates() -> list[tuple[Gesture, np.ndarray]]:
    """Noise-free, untilted, unit-energy traces of every gesture at nominal speed, resampled."""
    tau = np.linspace(0.0, 1.0, TEMPLATE_SAMPLES)
    dt = 1.0 / (TEMPLATE_SAMPLES - 1)
    out = []
    for gesture in Gesture:
        if gesture is Gesture.CIRCLE:
            starts = -np.pi / 2 + np.radians(np.arange(-30, 31, 15))
            variants = [(start, sign) for start in starts for sign in (-1.0, 1.0)]
        else:
            variants = [(0.0, 1.0)]
        for start, sign in variants:
            out.append((gesture, _normalised(_acceleration(_path(gesture, tau, 1.0, start, sign), dt))))
    return out


def _normalised(trace: np.ndarray) -> np.ndarray:
    centred = trace - trace.mean(axis=0)
    return centred / max(float(np.linalg.norm(centred)), 1e-12)


def _active_segment(dynamic: np.ndarray, rate_hz: float) -> np.ndarray | None:
    """The part of a gravity-free trace where the hand moves, or None when it never really does."""
    width = max(round(SMOOTHING_S * rate_hz), 1)
    envelope = np.convolve(np.linalg.norm(dynamic, axis=1), np.ones(width) / width, mode="same")
    peak = float(envelope.max())
    if peak < MIN_MOTION_MPS2:
        return None
    active = np.flatnonzero(envelope > max(MIN_MOTION_MPS2, 0.25 * peak))
    margin = round(SEGMENT_MARGIN_S * rate_hz)
    first, last = max(active[0] - margin, 0), min(active[-1] + margin, len(dynamic) - 1)
    return dynamic[first : last + 1] if last - first >= 4 else None


def _resample(segment: np.ndarray) -> np.ndarray:
    source = np.linspace(0.0, 1.0, len(segment))
    target = np.linspace(0.0, 1.0, TEMPLATE_SAMPLES)
    return np.column_stack([np.interp(target, source, segment[:, axis]) for axis in range(3)])


def match_scores(trace: np.ndarray, rate_hz: float = 50) -> dict[Gesture, float]:
    """Best correlation of ``trace`` with each gesture's templates (empty when there is no motion)."""
    trace = np.asarray(trace, dtype=float)
    if trace.ndim != 2 or trace.shape[1] != 3 or len(trace) < 2 or not np.all(np.isfinite(trace)):
        raise ValueError(f"trace must be a finite n x 3 array, got shape {trace.shape}")
    _check_rate(rate_hz)
    segment = _active_segment(trace - trace.mean(axis=0), rate_hz)
    if segment is None:
        return {}
    shape = _normalised(_resample(segment))
    scores: dict[Gesture, float] = {}
    for gesture, template in _templates():
        scores[gesture] = max(scores.get(gesture, -1.0), float(np.sum(shape * template)))
    return scores


def recognize(trace: np.ndarray, rate_hz: float = 50) -> Gesture | None:
    """The gesture in a watch accelerometer trace (n x 3, m/s^2), or None for noise or no gesture."""
    scores = match_scores(trace, rate_hz)
    if not scores:
        return None
    best = max(scores, key=scores.__getitem__)
    return best if scores[best] >= MIN_CORRELATION else None


def combine(gestures: Iterable[Gesture | str]) -> tuple[int, int, float]:
    """The motion a sequence of gestures asks for: (vx_sign, vy_sign, turn_deg) in the robot frame.

    Moves add up per axis and are clipped to a sign, so forward then right is the diagonal (1, -1) and
    forward then backward cancels; turns add (up: +90, counter-clockwise; down: -90). A circle cancels
    everything before it.
    """
    vx = vy = 0
    turn = 0.0
    for raw in gestures:
        gesture = Gesture(raw)
        if gesture is Gesture.CIRCLE:
            vx = vy = 0
            turn = 0.0
        elif gesture is Gesture.UP:
            turn += 90.0
        elif gesture is Gesture.DOWN:
            turn -= 90.0
        else:
            axis, sign = _STROKE_AXES[gesture]
            if axis == 0:
                vx = int(np.clip(vx + sign, -1, 1))
            else:
                vy = int(np.clip(vy + sign, -1, 1))
    return vx, vy, turn


def _check_rate(rate_hz: float) -> None:
    if not (math.isfinite(rate_hz) and rate_hz >= 10):
        raise ValueError(f"rate_hz must be >= 10 Hz, got {rate_hz}")
