"""Watch gestures (petswarm/wearables/gestures.py): synthesis, recognition, commands and combination."""

from __future__ import annotations

import numpy as np
import pytest

from petswarm.wearables.gestures import COMMANDS, GRAVITY_MPS2, Gesture, combine, match_scores, recognize, synthesize

RUNS = 200


def accuracy(gesture: Gesture, runs: int = RUNS, seed: int = 0) -> float:
    """Share of ``runs`` seeded synthesized ``gesture`` traces recognised as that gesture."""
    rng = np.random.default_rng([seed, list(Gesture).index(gesture)])
    return sum(recognize(synthesize(gesture, rng)) is gesture for _ in range(runs)) / runs


@pytest.mark.parametrize("gesture", list(Gesture))
def test_each_gesture_is_recognised_at_least_95_percent_of_the_time(gesture):
    assert accuracy(gesture) >= 0.95


@pytest.mark.parametrize("sigma", [0.2, 1.0, 3.0])
def test_white_noise_of_any_level_is_no_gesture(sigma):
    rng = np.random.default_rng(11)
    traces = [np.array([0, 0, GRAVITY_MPS2]) + sigma * rng.standard_normal((100, 3)) for _ in range(RUNS)]
    assert all(recognize(trace) is None for trace in traces)


def test_a_still_watch_and_a_slow_drift_are_no_gesture():
    rng = np.random.default_rng(12)
    still = np.array([0, 0, GRAVITY_MPS2]) + 0.05 * rng.standard_normal((150, 3))
    assert match_scores(still) == {} and recognize(still) is None
    drift = still + np.linspace(0, 0.5, 150)[:, None] * [1, 0, 0]  # slowly tilting the arm
    assert recognize(drift) is None


def test_smooth_random_hand_motion_is_rejected():
    rng = np.random.default_rng(13)
    kernel = np.hanning(15)
    rejected = 0
    for _ in range(RUNS):
        wander = np.column_stack([np.convolve(rng.standard_normal(100), kernel, "same") for _ in range(3)])
        wander *= rng.uniform(0.5, 3.0) / wander.std()
        rejected += recognize(wander + np.array([0, 0, GRAVITY_MPS2])) is None
    assert rejected / RUNS >= 0.95


def test_synthesis_is_seeded_varied_and_physical():
    a = synthesize(Gesture.FORWARD, np.random.default_rng(5))
    b = synthesize(Gesture.FORWARD, np.random.default_rng(5))
    c = synthesize(Gesture.FORWARD, np.random.default_rng(6))
    assert np.array_equal(a, b) and (a.shape != c.shape or not np.allclose(a, c))
    assert a.shape[1] == 3
    # gravity dominates the mean (tilted at most 15 degrees), and a push then brake shows on x
    assert np.linalg.norm(a.mean(axis=0)) == pytest.approx(GRAVITY_MPS2, abs=0.1)
    assert a.mean(axis=0)[2] > GRAVITY_MPS2 * np.cos(np.radians(22))
    x = a[:, 0] - a[:, 0].mean()
    assert np.argmax(x) < np.argmin(x)
    up = synthesize(Gesture.UP, np.random.default_rng(5))
    assert np.ptp(up[:, 2]) > np.ptp(up[:, 1])


def test_recognition_works_at_another_sample_rate():
    rng = np.random.default_rng(7)
    for gesture in Gesture:
        assert recognize(synthesize(gesture, rng, rate_hz=100), rate_hz=100) is gesture


def test_commands_follow_the_spec_table():
    assert set(COMMANDS) == set(Gesture)
    assert COMMANDS[Gesture.CIRCLE] == "cancel"
    assert COMMANDS[Gesture.UP] == "rotate counter-clockwise 90 degrees"
    assert COMMANDS[Gesture.DOWN] == "rotate clockwise 90 degrees"
    assert COMMANDS[Gesture.RIGHT] == "move right"


def test_gestures_combine():
    assert combine([Gesture.FORWARD, Gesture.RIGHT]) == (1, -1, 0.0)
    assert combine(["backward", "left"]) == (-1, 1, 0.0)
    assert combine([Gesture.FORWARD, Gesture.FORWARD]) == (1, 0, 0.0)
    assert combine([Gesture.FORWARD, Gesture.BACKWARD]) == (0, 0, 0.0)
    assert combine([Gesture.UP, Gesture.UP, Gesture.DOWN]) == (0, 0, 90.0)
    assert combine([Gesture.FORWARD, Gesture.UP, Gesture.CIRCLE, Gesture.LEFT]) == (0, 1, 0.0)
    assert combine([]) == (0, 0, 0.0)


def test_bad_input_is_refused_clearly():
    with pytest.raises(ValueError, match="trace"):
        recognize(np.zeros((10, 2)))
    with pytest.raises(ValueError, match="trace"):
        recognize(np.full((10, 3), np.nan))
    with pytest.raises(ValueError, match="rate_hz"):
        synthesize(Gesture.UP, np.random.default_rng(0), rate_hz=0)
    with pytest.raises(ValueError, match="wave"):
        combine(["wave"])
