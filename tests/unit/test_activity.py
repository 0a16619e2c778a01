"""The belt's IMU emulation (petswarm/wearables/imu.py) and activity recognition on it
(petswarm/wearables/activity.py)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from petswarm.wearables.activity import Activity, ActivityConfig, ActivityRecognizer, Movement
from petswarm.wearables.imu import ACCEL_PERIOD_S, GRAVITY_MPS2, GYRO_PERIOD_S, BeltImu, ImuConfig, step_frequency_hz

Profile = Callable[[float], float]
TURN_START_S = 3.0


def _run(
    speed: Profile,
    yaw_rate: Profile,
    until: float,
    seed: int = 0,
    probe: Callable[[ActivityRecognizer, float], None] | None = None,
) -> ActivityRecognizer:
    """Feed a recognizer with a belt's IMU samples, accel at 50 Hz and gyro every 70 ms, in time order."""
    imu = BeltImu(np.random.default_rng(seed))
    recognizer = ActivityRecognizer()
    accel_times = np.arange(0.0, until, ACCEL_PERIOD_S)
    gyro_times = np.arange(GYRO_PERIOD_S, until, GYRO_PERIOD_S)
    events = sorted([(t, 0) for t in accel_times] + [(t, 1) for t in gyro_times])
    for t, kind in events:
        if kind == 0:
            recognizer.add_accel(t, imu.accel_z(t, speed(t)))
        else:
            recognizer.add_gyro(t, imu.gyro_z(t, yaw_rate(t)))
            if probe:
                probe(recognizer, t)
    return recognizer


def _constant(value: float) -> Profile:
    return lambda t: value


def _turn(angle_rad: float, duration_s: float = 1.5, start_s: float = TURN_START_S) -> Profile:
    """Half-sine yaw rate: a person's smooth turn through ``angle_rad`` in ``duration_s``."""
    peak = angle_rad * math.pi / (2 * duration_s)

    def rate(t: float) -> float:
        return peak * math.sin(math.pi * (t - start_s) / duration_s) if start_s <= t <= start_s + duration_s else 0.0

    return rate


# == the IMU ==========================================================================================


def test_gait_frequency_and_amplitude_grow_with_speed():
    config = ImuConfig()
    assert step_frequency_hz(0.0, config) == 0.0
    assert step_frequency_hz(1.2, config) == pytest.approx(1.8, abs=0.01)
    assert step_frequency_hz(3.0, config) == pytest.approx(2.9, abs=0.01)
    peaks = []
    for speed in (0.0, 0.3, 1.2, 3.0):
        imu = BeltImu(np.random.default_rng(1))
        z = np.array([imu.accel_z(t, speed) for t in np.arange(0, 10, ACCEL_PERIOD_S)])
        assert z.mean() == pytest.approx(GRAVITY_MPS2, abs=0.1)
        peaks.append(np.ptp(z))
        spectrum = np.abs(np.fft.rfft(z - z.mean()))
        dominant = np.fft.rfftfreq(len(z), ACCEL_PERIOD_S)[np.argmax(spectrum)]
        if speed > 0:
            assert dominant == pytest.approx(step_frequency_hz(speed, config) * imu.cadence_factor, abs=0.15)
    assert peaks == sorted(peaks)
    assert peaks[0] < 0.5 and peaks[1] < 1.0 and peaks[3] > 15


def test_gyro_reads_rate_plus_bias_plus_noise_and_is_seeded():
    imu = BeltImu(np.random.default_rng(2))
    readings = np.array([imu.gyro_z(0.07 * i, 1.0) for i in range(5000)])
    assert readings.mean() == pytest.approx(1.0 + ImuConfig().gyro_bias_rps, abs=0.002)
    assert readings.std() == pytest.approx(ImuConfig().gyro_noise_rps, rel=0.05)
    again = BeltImu(np.random.default_rng(2))
    assert [again.gyro_z(0.0, 1.0) for _ in range(3)] == list(readings[:3])


def test_speed_change_keeps_the_signal_continuous():
    imu = BeltImu(np.random.default_rng(0), ImuConfig(accel_noise_mps2=0.0))
    times = np.arange(0, 4, ACCEL_PERIOD_S)
    z = np.array([imu.accel_z(t, 1.0 if t < 2 else 1.5) for t in times])
    # the largest sample-to-sample step is that of the faster gait's steepest slope, not a phase jump
    assert np.max(np.abs(np.diff(z))) < 1.25 * np.max(np.abs(np.diff(z[times >= 2])))


def test_imu_refuses_bad_input():
    imu = BeltImu(np.random.default_rng(0))
    imu.accel_z(1.0, 1.0)
    with pytest.raises(ValueError, match="t must not go backwards"):
        imu.accel_z(0.5, 1.0)
    with pytest.raises(ValueError, match="speed_mps"):
        imu.accel_z(2.0, -1.0)
    with pytest.raises(ValueError, match="yaw_rate"):
        imu.gyro_z(2.0, math.nan)
    with pytest.raises(ValueError, match="cadence_spread"):
        ImuConfig.from_dict({"cadence_spread": -1})


# == movement =========================================================================================


@pytest.mark.parametrize(
    ("speed", "expected"),
    [
        (0.0, Movement.STOP),
        (0.3, Movement.REST),
        (0.5, Movement.REST),
        (1.0, Movement.WALK),
        (1.2, Movement.WALK),
        (1.8, Movement.WALK),
        (2.8, Movement.RUN),
        (4.0, Movement.RUN),
    ],
)
@pytest.mark.parametrize("seed", range(4))
def test_movement_is_recognised_at_every_moment_once_the_window_is_full(speed, expected, seed):
    seen: list[Movement] = []
    _run(_constant(speed), _constant(0.0), 8.0, seed, lambda r, t: seen.append(r.movement(t)) if t > 2.1 else None)
    assert set(seen) == {expected}


def test_stop_until_the_window_is_filled_and_a_change_shows_within_a_window():
    seen: dict[float, Movement] = {}
    _run(lambda t: 1.2 if t < 6 else 0.0, _constant(0.0), 10.0, probe=lambda r, t: seen.update({t: r.movement(t)}))
    assert all(m == Movement.STOP for t, m in seen.items() if t < 1.4)
    assert all(m == Movement.WALK for t, m in seen.items() if 2.1 < t < 6)
    assert all(m == Movement.STOP for t, m in seen.items() if t > 6 + ActivityConfig().window_s)


# == rotation =========================================================================================


@pytest.mark.parametrize("angle_deg", [90, -90, 45])
@pytest.mark.parametrize("speed", [0.0, 1.2])
@pytest.mark.parametrize("seed", range(3))
def test_a_turn_is_detected_early_and_its_angle_accumulated_within_10_degrees(angle_deg, speed, seed):
    during: list[Activity] = []
    turn = _turn(math.radians(angle_deg))
    recognizer = _run(
        _constant(speed),
        turn,
        7.0,
        seed,
        lambda r, t: during.append(r.activity(t)) if TURN_START_S < t < TURN_START_S + 1.5 else None,
    )
    assert recognizer.rotation_started_at is not None
    latency = recognizer.rotation_started_at - TURN_START_S
    assert 0 < latency < 0.5
    assert not recognizer.rotating
    assert math.degrees(recognizer.accumulated_angle_rad) == pytest.approx(angle_deg, abs=10)
    assert any(a.rotating for a in during)
    assert all(math.copysign(1, a.angular_speed_rps) == math.copysign(1, angle_deg) for a in during if a.rotating)


def test_no_rotation_while_walking_straight_or_standing():
    for speed in (0.0, 1.2, 3.0):
        recognizer = _run(_constant(speed), _constant(0.0), 20.0, seed=5)
        assert recognizer.rotation_started_at is None and recognizer.accumulated_angle_rad == 0.0


def rotation_latencies(angle_deg: float = 90.0, runs: int = 20) -> np.ndarray:
    """Detection latency (s) of a half-sine turn over 1.5 s while walking at 1.2 m/s, per seed."""
    out = []
    for seed in range(runs):
        recognizer = _run(_constant(1.2), _turn(math.radians(angle_deg)), 5.0, seed)
        out.append(recognizer.rotation_started_at - TURN_START_S)
    return np.array(out)


def test_rotation_latency_is_a_few_gyro_samples():
    latencies = rotation_latencies(runs=10)
    assert np.median(latencies) < 0.4
    assert np.ptp(latencies) <= 2 * GYRO_PERIOD_S + 1e-9  # the detection moment varies by a sample or two


# == the report =======================================================================================


def test_activity_round_trips_and_refuses_bad_fields():
    activity = Activity(Movement.WALK, True, 0.8, 1.2)
    assert Activity.from_dict(activity.to_dict()) == activity
    assert activity.to_dict()["movement"] == 2
    with pytest.raises(ValueError, match="movement"):
        Activity.from_dict({**activity.to_dict(), "movement": 7})
    with pytest.raises(ValueError, match="rotating"):
        Activity.from_dict({**activity.to_dict(), "rotating": 1})
    with pytest.raises(ValueError, match="accumulated_angle_rad"):
        Activity.from_dict({**activity.to_dict(), "accumulated_angle_rad": "x"})


def test_recognizer_refuses_bad_samples_and_config():
    recognizer = ActivityRecognizer()
    recognizer.add_gyro(1.0, 0.0)
    with pytest.raises(ValueError, match="not newer"):
        recognizer.add_gyro(1.0, 0.0)
    with pytest.raises(ValueError, match="az"):
        recognizer.add_accel(1.0, math.nan)
    with pytest.raises(ValueError, match="rotation_stop_rps"):
        ActivityConfig.from_dict({"rotation_stop_rps": 1.0})
    assert ActivityConfig.from_dict(ActivityConfig().to_dict()) == ActivityConfig()
