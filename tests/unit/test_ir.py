"""IR light model and relative-location estimators: exactness, geometry, noise, superposition, accuracy."""

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from petswarm.managers.ir_estimator import METHODS, distance_from_strength, estimate, estimate_many
from radio_hub.physics.light import (
    RECEIVER_AXES_RAD,
    IrConfig,
    IrMode,
    OverlapCounter,
    incident_light,
    overlapping,
    receiver_readings,
    strength_at,
)

CONFIG = IrConfig()
CLEAN = CONFIG.noise_free()
SECTOR = math.pi / 6
SATURATION_DISTANCE_M = math.sqrt(CONFIG.power_counts_at_1m / (CONFIG.saturation_counts - CONFIG.ambient_counts))
"""Closer than this (about 0.25 m) the on-axis receiver reads full scale."""
RANGE_EDGE_M = CONFIG.max_range_m * (1 - 1e-12)
"""Just inside the range (placing a robot exactly at the edge by sin/cos can land a hair beyond it)."""

bearings = st.floats(0.0, 2 * math.pi, exclude_max=True)
headings = st.floats(-math.pi, math.pi)
distances = st.floats(0.3, RANGE_EDGE_M)


def _geometry(bearing: float, distance: float, heading: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """A receiver at (1, -2) with ``heading``, and a transmitter at ``bearing`` from it, ``distance`` away."""
    rx = np.array([[1.0, -2.0, heading]])
    world = heading + bearing
    tx = np.array([[1.0 + distance * math.cos(world), -2.0 + distance * math.sin(world), 0.7]])
    return tx, rx


def _sweep(bearing: float, distance: float, config: IrConfig = CLEAN, heading: float = 0.0, seed: int = 0):
    tx, rx = _geometry(bearing, distance, heading)
    return receiver_readings(tx, rx, config, np.random.default_rng(seed))[0]


def _angle_error(estimated, true):
    return np.abs(np.angle(np.exp(1j * (np.asarray(estimated) - np.asarray(true)))))


def _assert_exact(bearing: float, distance: float, method: str, heading: float = 0.0) -> None:
    est = estimate(_sweep(bearing, distance, heading=heading), CLEAN, method)
    assert est is not None
    assert _angle_error(est.bearing_rad, bearing) < 1e-9
    assert est.distance_m == pytest.approx(distance, rel=1e-9)
    assert est.strength == pytest.approx(float(strength_at(distance, CLEAN)), rel=1e-9)
    assert 0 <= est.bearing_rad < 2 * math.pi and not est.saturated


# == exact on noise-free input ========================================================================


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("sector", range(12))
@pytest.mark.parametrize("offset_deg", [0.0, 15.0, -15.0, 14.999999, -14.999999, 7.5])
def test_exact_at_every_sector_centre_and_edge(method, sector, offset_deg):
    bearing = (sector * SECTOR + math.radians(offset_deg)) % (2 * math.pi)
    for distance in (0.3, 0.4, 1.0, 2.0, RANGE_EDGE_M):
        _assert_exact(bearing, distance, method)


@pytest.mark.parametrize("method", METHODS)
@settings(max_examples=300, deadline=None)
@given(bearing=bearings, distance=distances, heading=headings)
def test_exact_on_noise_free_input_anywhere_in_range(method, bearing, distance, heading):
    _assert_exact(bearing, distance, method, heading)


def test_paper_equations_by_hand():
    """Equations (1)-(3) on a hand-made triple: receiver 4 strongest, source 10 degrees past its axis."""
    r_true, theta = 200.0, math.radians(10)
    readings = np.full(12, CLEAN.ambient_counts)
    for k, dk in ((4, 0), (5, 1), (3, -1)):
        readings[k] += r_true * math.cos(theta - dk * SECTOR)
    est = estimate(readings, CLEAN, "paper")
    assert est.bearing_rad == pytest.approx(4 * SECTOR + theta, abs=1e-12)
    assert est.strength == pytest.approx(r_true, rel=1e-12)
    assert est.distance_m == pytest.approx(math.sqrt(CLEAN.power_counts_at_1m / r_true), rel=1e-12)


# == the light model ==================================================================================


@settings(max_examples=200, deadline=None)
@given(bearing=bearings, distance=distances, heading=headings)
def test_nothing_from_behind_and_cosine_in_front(bearing, distance, heading):
    light = incident_light(*_geometry(bearing, distance, heading), CLEAN)[0]
    cosines = np.cos(bearing - RECEIVER_AXES_RAD)
    # a receiver exactly side-on (cosine 0 up to rounding of the geometry) may see a few 1e-13 counts
    behind = cosines < -1e-9
    assert np.all(light[behind] == 0.0)
    front = cosines > 1e-9
    np.testing.assert_allclose(light[front], strength_at(distance, CLEAN) * cosines[front], rtol=1e-12, atol=1e-9)
    assert np.all(np.abs(light[~behind & ~front]) < 1e-6)
    readings = _sweep(bearing, distance, heading=heading)
    assert np.all(readings[behind] == CLEAN.ambient_counts)


def test_strength_law_inverse_square_with_near_field_floor_and_range():
    s1 = float(strength_at(1.0, CONFIG))
    assert s1 == CONFIG.power_counts_at_1m
    assert float(strength_at(2.0, CONFIG)) == pytest.approx(s1 / 4)
    assert float(strength_at(0.01, CONFIG)) == float(strength_at(CONFIG.near_field_m, CONFIG))
    assert float(strength_at(CONFIG.max_range_m, CONFIG)) > 0
    assert float(strength_at(CONFIG.max_range_m + 1e-6, CONFIG)) == 0.0
    d = np.linspace(CONFIG.near_field_m, CONFIG.max_range_m, 50)
    np.testing.assert_allclose(distance_from_strength(strength_at(d, CONFIG), CONFIG), d, rtol=1e-12)


def test_defaults_keep_the_papers_experiment_in_the_working_range():
    assert SATURATION_DISTANCE_M < 0.3  # 40 cm never saturates
    edge = float(strength_at(CONFIG.max_range_m, CONFIG)) * math.cos(math.radians(15))
    assert edge > CONFIG.detection_threshold_counts  # seen at the range edge even between sectors
    assert float(strength_at(2.0, CONFIG)) > 8 * CONFIG.noise_floor_counts


def test_heading_of_the_transmitter_does_not_matter_and_own_module_adds_nothing():
    tx, rx = _geometry(1.0, 1.2)
    turned = tx.copy()
    turned[0, 2] += 2.0
    assert np.array_equal(incident_light(tx, rx, CLEAN), incident_light(turned, rx, CLEAN))
    assert np.all(incident_light(rx, rx, CLEAN) == 0.0)


def test_receivers_beyond_range_or_without_transmitters_read_ambient_only():
    tx, rx = _geometry(0.5, CONFIG.max_range_m + 0.01)
    assert np.all(receiver_readings(tx, rx, CLEAN, np.random.default_rng(0)) == CLEAN.ambient_counts)
    none = receiver_readings(np.zeros((0, 3)), rx, CLEAN, np.random.default_rng(0))
    assert none.shape == (1, 12) and np.all(none == CLEAN.ambient_counts)


def test_readings_saturate_at_full_scale():
    readings = _sweep(0.3, 0.12, CONFIG)
    assert readings.max() == CONFIG.saturation_counts
    assert readings.min() >= 0


def test_many_receivers_many_transmitters_shapes():
    rng = np.random.default_rng(3)
    tx = rng.uniform(-1, 1, (4, 3))
    rx = rng.uniform(-1, 1, (7, 3))
    readings = receiver_readings(tx, rx, CONFIG, rng)
    assert readings.shape == (7, 12)
    each = sum(incident_light(tx[i : i + 1], rx, CLEAN) for i in range(4))
    np.testing.assert_allclose(incident_light(tx, rx, CLEAN), each, rtol=1e-12)


# == superposition: only the schedule keeps the readings right ========================================


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("second", [(0.0, 1.2), (0.8, 0.8)], ids=["left", "ahead-left"])
def test_two_transmitters_at_once_give_wrong_estimates(method, second):
    rx = np.array([[0.0, 0.0, 0.0]])
    a = np.array([[1.0, 0.0, 0.0]])  # 1 m ahead
    b = np.array([[*second, 0.0]])
    both = np.vstack([a, b])
    light = incident_light(both, rx, CLEAN)
    np.testing.assert_allclose(light, incident_light(a, rx, CLEAN) + incident_light(b, rx, CLEAN))
    est = estimate(receiver_readings(both, rx, CLEAN, np.random.default_rng(0))[0], CLEAN, method)
    assert est is not None  # a plausible-looking estimate, even without noise ...
    where = est.distance_m * np.array([math.cos(est.bearing_rad), math.sin(est.bearing_rad)])
    for robot in (a, b):  # ... that puts the transmitter 30 cm or more from both robots
        assert np.hypot(*(where - robot[0, :2])) > 0.3


def test_overlapping_flags_samples_with_more_than_one_transmitter():
    on = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 1], [1, 1, 1]], dtype=bool)
    assert overlapping(on).tolist() == [False, False, True, True, True]
    assert overlapping([True, False]).tolist() == [False]


def test_overlap_counter_counts_episodes_and_time():
    counter = OverlapCounter()
    assert not counter.set_mode("r1", IrMode.TRANSMIT, 0)
    assert not counter.set_mode("r2", IrMode.RECEIVE, 0)
    assert counter.set_mode("r2", IrMode.TRANSMIT, 100)  # overlap starts
    assert not counter.set_mode("r3", IrMode.TRANSMIT, 150)  # same episode, three at once
    assert counter.overlapping and counter.transmitters == ["r1", "r2", "r3"]
    assert counter.as_dict(200)["overlap_us"] == 100
    counter.set_mode("r3", IrMode.IDLE, 250)
    counter.remove("r1", 400)  # one left: the episode ends
    assert not counter.overlapping
    assert not counter.set_mode("r1", "receive", 500)
    assert counter.set_mode("r1", IrMode.TRANSMIT, 600)
    counter.set_mode("r2", IrMode.RECEIVE, 650)
    assert counter.as_dict(1000) == {
        "overlap_episodes": 2,
        "overlap_us": 300 + 50,
        "max_transmitters": 3,
        "transmitting": ["r1"],
    }


# == noise ============================================================================================


def test_noise_is_seeded_and_reproducible():
    tx, rx = _geometry(1.0, 1.5)
    rxs = np.repeat(rx, 50, axis=0)
    first = receiver_readings(tx, rxs, CONFIG, np.random.default_rng(42))
    again = receiver_readings(tx, rxs, CONFIG, np.random.default_rng(42))
    other = receiver_readings(tx, rxs, CONFIG, np.random.default_rng(43))
    assert np.array_equal(first, again)
    assert not np.array_equal(first, other)


def test_noise_statistics_match_the_config():
    samples = 20000
    tx, rx = _geometry(0.2, 1.0)
    readings = receiver_readings(tx, np.repeat(rx, samples, axis=0), CONFIG, np.random.default_rng(7))
    light = incident_light(tx, rx, CONFIG)[0]
    sigma = np.hypot(CONFIG.noise_floor_counts, CONFIG.relative_noise * light)
    mean_error = np.abs(readings.mean(axis=0) - (CONFIG.ambient_counts + light))
    assert np.all(mean_error < 4.5 * sigma / math.sqrt(samples))
    np.testing.assert_allclose(readings.std(axis=0), sigma, rtol=0.03)


def test_noise_free_turns_off_only_the_noise():
    assert CLEAN.noiseless and not CONFIG.noiseless
    assert CLEAN.ambient_counts == CONFIG.ambient_counts
    assert CLEAN.saturation_counts == CONFIG.saturation_counts
    assert CLEAN.detection_threshold_counts == 0


# == no signal, saturation, bad input =================================================================


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("config", [CONFIG, CLEAN], ids=["noisy", "clean"])
def test_no_signal_gives_no_estimate(method, config):
    tx, rx = _geometry(2.0, CONFIG.max_range_m + 0.2)
    rxs = np.repeat(rx, 2000, axis=0)
    for transmitters in (tx, np.zeros((0, 3))):
        estimates = estimate_many(
            receiver_readings(transmitters, rxs, config, np.random.default_rng(1)), config, method
        )
        assert estimates.valid.mean() < 0.005  # false detections from noise alone are rare
    assert estimate(np.full(12, config.ambient_counts), config, method) is None


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("distance", [0.05, 0.12, 0.2, 0.22])
@pytest.mark.parametrize("bearing_deg", [0.0, 10.0, 15.0, 100.0, 345.0])
def test_saturation_is_flagged_and_estimates_stay_sane(method, distance, bearing_deg):
    bearing = math.radians(bearing_deg)
    est = estimate(_sweep(bearing, distance, CONFIG, seed=5), CONFIG, method)
    assert est is not None and est.saturated
    assert _angle_error(est.bearing_rad, bearing) <= math.radians(15) + 1e-9
    assert distance - 0.05 <= est.distance_m <= SATURATION_DISTANCE_M + 0.01  # at most this far


def test_bad_input_is_refused_clearly():
    with pytest.raises(ValueError, match="unknown IR estimator"):
        estimate(np.zeros(12), CONFIG, "magic")
    with pytest.raises(ValueError, match="12 readings"):
        estimate(np.zeros(11), CONFIG)
    with pytest.raises(ValueError, match="poses"):
        incident_light([[0.0, 0.0]], [[0.0, 0.0]], CONFIG)


def test_config_loads_validates_and_round_trips():
    assert IrConfig.from_dict(CONFIG.to_dict()) == CONFIG
    assert IrConfig.from_dict({"relative_noise": 0.05}).relative_noise == 0.05
    with pytest.raises(ValueError, match="unknown key "):
        IrConfig.from_dict({"powr": 1})
    with pytest.raises(ValueError, match="max_range_m"):
        IrConfig.from_dict({"max_range_m": 0.05})
    with pytest.raises(ValueError, match="saturation"):
        IrConfig.from_dict({"saturation_counts": 10})


# == beyond the paper: lsq beats equations (1)-(3) ====================================================


def _rmse_over_grid(method: str, seed: int = 2024) -> tuple[float, float]:
    """Distance (m) and bearing (rad) RMSE over 40-200 cm x every 7.5 degrees, 40 sweeps per point."""
    d, b = np.meshgrid(np.arange(0.4, 2.01, 0.2), np.radians(np.arange(0, 360, 7.5)))
    d, b = np.repeat(d.ravel(), 40), np.repeat(b.ravel(), 40)
    rx = np.column_stack([-d * np.cos(b), -d * np.sin(b), np.zeros_like(d)])  # transmitter at the origin
    readings = receiver_readings([[0.0, 0.0, 0.0]], rx, CONFIG, np.random.default_rng(seed))
    est = estimate_many(readings, CONFIG, method)
    assert est.valid.all()
    return math.sqrt(np.mean((est.distance_m - d) ** 2)), math.sqrt(np.mean(_angle_error(est.bearing_rad, b) ** 2))


def test_lsq_beats_the_paper_in_distance_and_bearing_rmse_under_default_noise():
    paper_d, paper_b = _rmse_over_grid("paper")
    lsq_d, lsq_b = _rmse_over_grid("lsq")
    assert lsq_d < 0.95 * paper_d, (lsq_d, paper_d)
    assert lsq_b < 0.7 * paper_b, (lsq_b, paper_b)


# == the bench ========================================================================================


def test_bench_ir_prints_the_table_and_writes_json_and_plot(tmp_path, capsys):
    from cli.main import main

    assert main(["bench", "ir", "--runs", "5", "--seed", "3", "--out", str(tmp_path), "--no-wire"]) == 0
    out = capsys.readouterr().out
    assert "overall" in out and "lsq dir deg" in out
    results = json.loads((tmp_path / "bench_ir.json").read_text())
    assert set(results["methods"]) == set(METHODS)
    assert len(results["methods"]["lsq"]["per_point"]) == 9 * 7
    assert results["methods"]["lsq"]["overall"]["n"] == 9 * 7 * 5
    assert (tmp_path / "bench_ir.png").stat().st_size > 10_000
