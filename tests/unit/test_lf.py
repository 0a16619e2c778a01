"""The LF field (radio_hub/physics/lf.py) and the user's fix from it (petswarm/wearables/lf_location.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from petswarm.wearables.lf_location import UserFix, locate, locate_from_rssi, rssi_to_distance
from radio_hub.physics.lf import LfConfig, antenna_positions, lf_rssi, mean_rssi_dbm, wake_pattern, wakes

CONFIG = LfConfig()
CLEAN = CONFIG.noise_free()


def _belt_at(pose: tuple[float, float, float], distance: float, bearing: float) -> np.ndarray:
    """World xy of a belt at ``distance`` and robot-frame ``bearing`` from a robot at ``pose``."""
    x, y, yaw = pose
    return np.array([x + distance * math.cos(yaw + bearing), y + distance * math.sin(yaw + bearing)])


def _fix(pose, belt, config: LfConfig, rng: np.random.Generator, behind: bool = False) -> UserFix | None:
    left, right = antenna_positions(pose, config.antenna_baseline_m)
    return locate_from_rssi(lf_rssi(left, belt, config, rng), lf_rssi(right, belt, config, rng), config, behind)


def _angle_error(a: float, b: float) -> float:
    return (a - b + math.pi) % (2 * math.pi) - math.pi


# == the field ========================================================================================


def test_antennas_sit_on_the_body_y_axis_left_then_right():
    left, right = antenna_positions((1.0, 2.0, math.pi / 2))  # facing north: left is west
    assert left == pytest.approx([0.9, 2.0])
    assert right == pytest.approx([1.1, 2.0])
    left, right = antenna_positions((0.0, 0.0, 0.0), baseline_m=0.4)
    assert left == pytest.approx([0.0, 0.2]) and right == pytest.approx([0.0, -0.2])


def test_rssi_falls_60_db_per_decade_and_is_heard_to_about_3_m():
    rng = np.random.default_rng(0)
    assert lf_rssi((0, 0), (1, 0), CLEAN, rng) == pytest.approx(CONFIG.rssi_at_1m_dbm)
    assert lf_rssi((0, 0), (0, 0.1), CLEAN, rng) - lf_rssi((0, 0), (0, 1.0), CLEAN, rng) == pytest.approx(60.0)
    assert 2.9 <= CONFIG.range_m <= 3.1
    assert lf_rssi((0, 0), (2.9, 0), CLEAN, rng) is not None
    assert lf_rssi((0, 0), (3.1, 0), CLEAN, rng) is None
    assert float(mean_rssi_dbm(0.01, CONFIG)) == float(mean_rssi_dbm(CONFIG.near_field_m, CONFIG))


def test_noise_is_seeded_gaussian_and_blurs_the_edge():
    samples = [lf_rssi((0, 0), (1, 0), CONFIG, np.random.default_rng(7)) for _ in range(2)]
    assert samples[0] == samples[1]
    rng = np.random.default_rng(1)
    values = np.array([lf_rssi((0, 0), (1, 0), CONFIG, rng) for _ in range(4000)])
    assert values.mean() == pytest.approx(CONFIG.rssi_at_1m_dbm, abs=0.05)
    assert values.std() == pytest.approx(CONFIG.noise_db, rel=0.05)
    heard = [lf_rssi((0, 0), (CONFIG.range_m, 0), CONFIG, rng) is not None for _ in range(2000)]
    assert 0.4 < np.mean(heard) < 0.6


def test_wake_patterns_are_16_bit_distinct_and_only_the_owners_wakes():
    patterns = [wake_pattern(i) for i in range(1 << 16)]
    assert len(set(patterns)) == 1 << 16 and min(patterns) >= 0 and max(patterns) < 1 << 16
    assert wake_pattern(0) != 0
    assert wakes(wake_pattern(3), wake_pattern(3))
    assert not any(wakes(wake_pattern(3), wake_pattern(i)) for i in range(1000) if i != 3)
    # neighbouring ids differ in several bits, not one
    assert min(bin(wake_pattern(i) ^ wake_pattern(i + 1)).count("1") for i in range(1000)) >= 2


def test_bad_input_is_refused_clearly():
    with pytest.raises(ValueError, match="robot_id"):
        wake_pattern(-1)
    with pytest.raises(ValueError, match="burst_pattern"):
        wakes(1, 1 << 16)
    with pytest.raises(ValueError, match="belt_xy"):
        lf_rssi((0, 0), (math.nan, 0), CONFIG, np.random.default_rng(0))
    with pytest.raises(ValueError, match="pose"):
        antenna_positions((0, 0))
    with pytest.raises(ValueError, match="d_left"):
        locate(0.0, 1.0, CONFIG)
    with pytest.raises(ValueError, match="baseline"):
        locate(1.0, 1.0, -0.2)
    with pytest.raises(ValueError, match="rssi_dbm"):
        rssi_to_distance(math.inf, CONFIG)


def test_config_loads_validates_and_round_trips():
    assert LfConfig.from_dict(CONFIG.to_dict()) == CONFIG
    assert LfConfig.from_dict({"noise_db": 1.5}).noise_db == 1.5
    with pytest.raises(ValueError, match="unknown key "):
        LfConfig.from_dict({"noise": 1})
    for field, value in (
        ("noise_db", -1),
        ("decade_loss_db", 0),
        ("sensitivity_dbm", -40),
        ("antenna_baseline_m", 0),
        ("wake_range_m", 5),
    ):
        with pytest.raises(ValueError, match=field):
            LfConfig.from_dict({field: value})


def test_wake_threshold_is_the_mean_rssi_at_the_wake_range():
    assert rssi_to_distance(CONFIG.wake_threshold_dbm, CONFIG) == pytest.approx(CONFIG.wake_range_m)


# == the fix ==========================================================================================


def test_calibration_curve_inverts_the_mean_curve():
    for d in (0.1, 0.25, 1.0, 2.0, 2.9):
        assert rssi_to_distance(float(mean_rssi_dbm(d, CONFIG)), CONFIG) == pytest.approx(d)


def test_the_spec_equations_by_hand():
    # user 1 m straight ahead: d_l = d_r = sqrt(1 + 0.1^2)
    fix = locate(math.hypot(1, 0.1), math.hypot(1, 0.1), 0.2)
    assert (fix.forward_m, fix.left_m, fix.bearing_rad) == pytest.approx((1.0, 0.0, 0.0), abs=1e-12)
    # user 1 m ahead and 0.5 m to the right: closer to the right antenna, paper's x = +0.5, bearing negative
    fix = locate(math.hypot(1, 0.6), math.hypot(1, 0.4), 0.2)
    assert (fix.forward_m, fix.left_m) == pytest.approx((1.0, -0.5))
    assert fix.bearing_rad == pytest.approx(-math.atan(0.5))
    assert not fix.reliable  # 26.6 degrees off the axis


def test_no_triangle_no_fix():
    assert locate(1.0, 1.3, 0.2) is None  # the difference exceeds the baseline
    assert locate(1.0, 1.2, 0.2) is None  # degenerate: on the antenna line
    assert locate(0.05, 0.05, 0.2) is None  # both antennas closer than half the baseline: impossible
    assert locate_from_rssi(None, -50.0, CONFIG) is None


@pytest.mark.parametrize("pose", [(0.0, 0.0, 0.0), (3.0, -2.0, 2.3)])
@pytest.mark.parametrize("behind", [False, True])
def test_noise_free_fix_is_exact_to_1_cm_and_1_degree_in_the_reliable_region(pose, behind):
    rng = np.random.default_rng(0)
    for distance in np.linspace(0.25, 1.99, 15):
        for offset_deg in np.arange(-24, 24.1, 4):
            bearing = math.radians(offset_deg) + (math.pi if behind else 0.0)
            fix = _fix(pose, _belt_at(pose, distance, bearing), CLEAN, rng, behind)
            assert fix is not None and fix.reliable
            assert abs(fix.distance_m - distance) < 0.01
            assert abs(math.degrees(_angle_error(fix.bearing_rad, bearing))) < 1.0
            assert math.hypot(fix.forward_m, fix.left_m) == pytest.approx(fix.distance_m)


def test_fixes_outside_the_region_are_flagged_unreliable():
    rng = np.random.default_rng(0)
    pose = (0.0, 0.0, 0.0)
    assert not _fix(pose, _belt_at(pose, 2.5, 0.0), CLEAN, rng).reliable
    assert not _fix(pose, _belt_at(pose, 1.0, math.radians(40)), CLEAN, rng).reliable
    assert _fix(pose, _belt_at(pose, 1.0, math.radians(20)), CLEAN, rng).reliable
    ahead_read_as_behind = _fix(pose, _belt_at(pose, 1.0, 0.3), CLEAN, rng, behind=True)
    assert ahead_read_as_behind.bearing_rad == pytest.approx(math.pi - 0.3)  # the ambiguity, mirrored


def test_lf_passes_through_obstacles_so_only_geometry_matters():
    # nothing but the two positions enters: the same geometry anywhere in the world gives the same RSSI
    a = lf_rssi((0, 0), (1, 1), CONFIG, np.random.default_rng(4))
    b = lf_rssi((10, -5), (11, -4), CONFIG, np.random.default_rng(4))
    assert a == b


# == the paper's protocol: RMSE at 25-200 cm, 50 samples per point ===================================

STUDY_DISTANCES_M = np.arange(0.25, 2.001, 0.25)
STUDY_BEARINGS_DEG = (-20.0, 0.0, 20.0)


def rmse_study(config: LfConfig = CONFIG, samples: int = 50, seed: int = 2016) -> list[dict[str, float]]:
    """Per distance: RMSE of forward, left, distance (m) and bearing (deg) over the bearings, and the share of
    rounds that gave no fix. Each sample is one LF round (one burst per antenna), unaveraged."""
    rng = np.random.default_rng(seed)
    pose = (0.0, 0.0, 0.0)
    rows = []
    for distance in STUDY_DISTANCES_M:
        errors, missing = [], 0
        for bearing in np.radians(STUDY_BEARINGS_DEG):
            belt = _belt_at(pose, distance, bearing)
            for _ in range(samples):
                fix = _fix(pose, belt, config, rng)
                if fix is None:
                    missing += 1
                    continue
                errors.append(
                    (
                        fix.forward_m - belt[0],
                        fix.left_m - belt[1],
                        fix.distance_m - distance,
                        math.degrees(_angle_error(fix.bearing_rad, bearing)),
                    )
                )
        rmse = np.sqrt(np.mean(np.square(errors), axis=0))
        total = samples * len(STUDY_BEARINGS_DEG)
        rows.append(
            dict(
                distance_m=float(distance),
                forward_m=rmse[0],
                left_m=rmse[1],
                distance_rmse_m=rmse[2],
                bearing_deg=rmse[3],
                no_fix=missing / total,
            )
        )
    return rows


def test_rmse_study_stays_within_the_documented_accuracy():
    rows = {round(r["distance_m"], 2): r for r in rmse_study()}
    # distance error is ~1.2 % per burst: a few cm up to 2 m
    assert all(r["distance_rmse_m"] < 0.02 * r["distance_m"] + 0.005 for r in rows.values())
    # bearing degrades with distance (the distance difference shrinks against the noise) but stays usable
    assert rows[1.0]["bearing_deg"] < 7.0
    assert rows[0.5]["bearing_deg"] < rows[2.0]["bearing_deg"]
    assert rows[1.0]["no_fix"] < 0.02
    # and noise is what drives it: a quieter belt does better
    quiet = {round(r["distance_m"], 2): r for r in rmse_study(LfConfig(noise_db=0.1))}
    assert quiet[1.0]["bearing_deg"] < 0.6 * rows[1.0]["bearing_deg"]
