"""The surround robot's sensing: beacons through the IR estimator, echoes to points, echoes a beacon explains."""

from __future__ import annotations

import math

import numpy as np
import pytest

from petswarm.controllers.surround_sensing import (
    BeaconTracker,
    SensingConfig,
    SweepJob,
    beacon_fixes,
    beacon_fixes_batch,
    beacon_points,
    echo_points,
    sense,
)
from radio_hub.physics.light import IrConfig, receiver_gains, strength_at
from radio_hub.physics.light import sense as light_sense


def _sweep(x: float, y: float, config: IrConfig, rng: np.random.Generator) -> np.ndarray:
    """One beacon's 12 readings at (x, y) in the receiving robot's frame, from the hub's light model."""
    distance = math.hypot(x, y)
    light = strength_at(np.array([distance]), config)[:, None] * receiver_gains(np.array([math.atan2(y, x)]))
    return light_sense(light, config, rng)[0]


def test_beacons_become_points_in_the_robots_frame_within_the_ir_noise() -> None:
    config = IrConfig()
    rng = np.random.default_rng(3)
    truth = {"robot-2": (0.4, 0.3), "user": (-0.6, -0.2), "robot-9": (0.1, -0.9)}
    points = beacon_points({n: _sweep(*p, config, rng) for n, p in truth.items()}, config)
    assert set(points) == set(truth)
    for name, (x, y) in truth.items():
        assert np.linalg.norm(points[name] - (x, y)) < 0.05, (name, points[name])


def test_a_source_below_the_detection_threshold_gives_no_point() -> None:
    config = IrConfig()
    dark = np.full(12, config.ambient_counts)
    assert beacon_points({"robot-3": dark}, config) == {}


def test_an_echo_is_the_point_it_came_from_measured_from_the_robots_centre() -> None:
    points = echo_points(np.array([0.3, np.nan, 0.1]), np.radians([0.0, 45.0, 90.0]), robot_radius_m=0.1)
    assert np.allclose(points, [[0.4, 0.0], [0.0, 0.2]])
    with pytest.raises(ValueError, match="must match"):
        echo_points(np.zeros(3), np.zeros(2), 0.1)


def test_echoes_off_a_neighbour_or_the_human_are_dropped_and_a_wall_is_kept() -> None:
    beacons = {"robot-2": np.array([0.5, 0.0]), "user": np.array([0.0, 0.6])}
    echoes = np.array([[0.42, 0.0], [0.0, 0.33], [0.0, -0.35]])  # robot-2's skin, the human's body, a wall
    seen = sense(beacons, echoes, "user", SensingConfig())
    assert np.allclose(seen.neighbours, [[0.5, 0.0]])
    assert seen.human is not None and np.allclose(seen.human, [0.0, 0.6])
    assert seen.echoes_dropped == 2
    # the wall's echo, and the human's body surface (his centre brought 0.25 m closer)
    assert np.allclose(seen.obstacles, [[0.0, -0.35], [0.0, 0.35]])


def test_without_the_humans_beacon_there_is_no_human_and_no_body_point() -> None:
    seen = sense({"robot-4": np.array([0.0, -0.7])}, np.zeros((0, 2)), "user", SensingConfig())
    assert seen.human is None and len(seen.obstacles) == 0 and len(seen.neighbours) == 1


def test_a_human_estimated_inside_his_own_radius_still_pushes_straight_away() -> None:
    seen = sense({"user": np.array([0.2, 0.0])}, np.zeros((0, 2)), "user", SensingConfig())
    [point] = seen.obstacles
    assert point[0] > 0 and abs(point[1]) < 1e-12 and np.linalg.norm(point) < 0.05


def test_the_tracker_moves_still_beacons_against_the_robots_own_motion() -> None:
    tracker = BeaconTracker()
    tracker.update({"robot-2": np.array([1.0, 0.0])}, np.zeros(2))
    tracker.predict(np.array([0.5, -0.25]), 0.04)
    assert np.allclose(tracker.points["robot-2"], [0.98, 0.01])
    with pytest.raises(ValueError, match="dt"):
        tracker.predict(np.zeros(2), -1.0)


def test_a_neighbour_driving_alongside_stays_put_between_sweeps_once_tracked() -> None:
    """Both drive at 1 m/s; fixes come at 20 Hz with 1.5 cm of noise, steps at 25 Hz: the tracked neighbour
    stays where it is relative to us, where taking it to stand still would lose 4 cm every step."""
    rng = np.random.default_rng(5)
    tracker = BeaconTracker()
    own = np.array([1.0, 0.0])
    truth = np.array([0.3, 0.2])
    tracker.update({"robot-2": truth}, own)
    errors = []
    for step in range(100):
        tracker.predict(own, 0.04)
        if step * 40 // 50 != (step + 1) * 40 // 50:  # a 20 Hz sweep fell within this 25 Hz step
            tracker.update({"robot-2": truth + rng.normal(0.0, 0.015, 2)}, own)
        errors.append(np.linalg.norm(tracker.points["robot-2"] - truth))
    assert np.mean(errors[20:]) < 0.015


def test_the_tracker_follows_a_beacon_that_moves_and_forgets_one_out_of_sight() -> None:
    tracker = BeaconTracker()
    still = np.zeros(2)
    for step in range(40):  # robot-3 drives away at 0.5 m/s, we stand still; a sweep every 50 ms
        tracker.predict(still, 0.05)
        tracker.update({"robot-3": np.array([0.5 + 0.5 * 0.05 * step, 0.0]), "user": np.array([0.0, 1.0])}, still)
    tracker.predict(still, 0.05)
    assert tracker.points["robot-3"][0] == pytest.approx(0.5 + 0.5 * 0.05 * 40, abs=0.01)  # predicted on
    tracker.update({"user": np.array([0.0, 1.0])}, still)
    assert set(tracker.points) == {"user"}
    with pytest.raises(ValueError, match="alpha"):
        BeaconTracker(alpha=0.0)


def test_bad_settings_are_refused_naming_the_field() -> None:
    with pytest.raises(ValueError, match="person_radius_m"):
        SensingConfig(person_radius_m=-0.1)


def test_a_scenarios_surround_table_is_checked_and_passes_the_law_settings() -> None:
    from petswarm.scenario import parse

    scenario = parse({"surround": {"enabled": True, "drag": 0.6}})
    assert scenario.surround_enabled and scenario.surround_law() == {"drag": 0.6}
    assert not parse({}).surround_enabled
    with pytest.raises(ValueError, match="unknown key "):
        parse({"surround": {"enabled": True, "stifness": 8}})
    with pytest.raises(ValueError, match=r"surround\.enabled"):
        parse({"surround": {"enabled": "yes"}})


def test_the_persons_beacon_reaches_every_robot_of_the_swarm_and_is_located_with_its_own_calibration() -> None:
    from radio_hub.physics.ir_air import IrAir
    from radio_hub.physics.light import PERSON_BEACON_POWER, IrMode

    ir = IrConfig().noise_free()
    air = IrAir(ir, np.random.default_rng(1))
    poses = {"robot-1": (0.0, 0.0, 0.0), "robot-2": (5.0, 0.0, 0.0), "user": (0.0, 5.0, 0.0)}
    for node in poses:
        air.set_mode(node, IrMode.BEACON, 0)
    air.power["user"] = PERSON_BEACON_POWER
    sweeps = air.beacon_sweep(poses)
    sources, readings, gains = sweeps["robot-1"]
    assert gains == [1.0]  # far off: the channel's AGC is at full gain
    assert sources == ["user"]  # 5 m: beyond a robot's module (2.8 m), within the person's beacon (8.4 m)
    points = beacon_points(dict(zip(sources, readings, strict=True)), ir, person="user")
    assert points["user"] == pytest.approx([0.0, 5.0], abs=0.02)
    robot_calibration = beacon_points(dict(zip(sources, readings, strict=True)), ir)
    assert np.hypot(*robot_calibration["user"]) < 2.0  # read as a robot's module it would seem 3x nearer


@pytest.mark.parametrize("distance_m", [0.3, 0.45, 0.6, 0.75, 1.2])
def test_the_agc_keeps_the_persons_beacon_readable_where_the_surround_robots_hold(distance_m: float) -> None:
    """Without the per-channel AGC the person's beacon saturated every facing receiver within 0.74 m, and
    robots 0.3-0.5 m from him read him 0.24-0.44 m too far: the distance of saturation, not his."""
    from radio_hub.physics.ir_air import IrAir
    from radio_hub.physics.light import PERSON_BEACON_POWER, IrMode

    ir = IrConfig()
    air = IrAir(ir, np.random.default_rng(7))
    poses = {"robot-1": (-distance_m, 0.0, 2.0), "user": (0.0, 0.0, 0.0)}
    for node in poses:
        air.set_mode(node, IrMode.BEACON, 0)
    air.power["user"] = PERSON_BEACON_POWER
    truth = distance_m * np.array([math.cos(-2.0), math.sin(-2.0)])  # the user in robot-1's frame
    errors = []
    for _ in range(50):
        sources, readings, gains = air.beacon_sweep(poses)["robot-1"]
        assert readings.max() < ir.saturation_counts
        points = beacon_points(
            dict(zip(sources, readings, strict=True)), ir, person="user", gains=dict(zip(sources, gains, strict=True))
        )
        errors.append(np.linalg.norm(points["user"] - truth))
    assert np.mean(errors) < 0.02, np.mean(errors)
    if distance_m < 0.7:
        assert gains[0] < 1.0
        unscaled = beacon_points(dict(zip(sources, readings, strict=True)), ir, person="user")
        assert np.hypot(*unscaled["user"]) > 1.2 * distance_m  # read at the wrong gain it seems farther


def test_the_agc_steps_down_by_twos_until_the_peak_is_under_the_headroom() -> None:
    from radio_hub.physics.light import AGC_HEADROOM, BEACON_GAINS, beacon_gain

    ir = IrConfig()
    limit = AGC_HEADROOM * ir.saturation_counts - ir.ambient_counts
    assert beacon_gain(limit, ir) == 1.0
    assert beacon_gain(limit * 1.01, ir) == 0.5
    assert beacon_gain(limit * 3.9, ir) == 0.25
    assert beacon_gain(1e9, ir) == BEACON_GAINS[-1]


def _robot_sweeps(rng: np.random.Generator, config: IrConfig, beacons: int) -> np.ndarray:
    """A robot's sweep of ``beacons`` sources at random, from 5 cm (saturated) to beyond the range."""
    distances = rng.uniform(0.05, 3.2, size=beacons)
    light = strength_at(distances, config)[:, None] * receiver_gains(rng.uniform(0, 2 * math.pi, size=beacons))
    return light_sense(light, config, rng).reshape(-1, 12)


@pytest.mark.parametrize("method", ["lsq", "paper"])
def test_a_batch_of_sweeps_gives_each_robot_its_own_estimate_bit_for_bit(method: str) -> None:
    # model time estimates many robots' sweeps at once, lockstep each robot's alone: one digest needs equal bits
    config = IrConfig()
    rng = np.random.default_rng(11)
    saturated = 0
    for _ in range(40):
        jobs = []
        for size in rng.integers(0, 22, size=rng.integers(2, 20)):
            names = [f"robot-{i}" for i in range(size)]
            if size and rng.random() < 0.3:  # the human's beacon anywhere in the sweep, now and then twice
                names[int(rng.integers(size))] = "user"
                if size > 3 and rng.random() < 0.2:
                    names[0] = names[1] = "user"
            gains = rng.choice([1.0, 0.5, 0.125], size=size).tolist()
            jobs.append(SweepJob(names, _robot_sweeps(rng, config, size), gains, "user"))
        jobs.append(SweepJob(["robot-1", "robot-2"], np.full((2, 12), np.nan), [1.0, 1.0], "user"))
        for job, (seen, xy) in zip(jobs, beacon_fixes_batch(jobs, config, method), strict=True):
            alone_seen, alone_xy = beacon_fixes(job.names, job.readings, job.gains, config, method, job.person)
            assert seen == alone_seen
            assert xy.shape == alone_xy.shape and np.array_equal(xy, alone_xy, equal_nan=True)
            saturated += bool(np.any(job.readings >= config.saturation_counts))
    assert saturated > 100  # the fits' saturated fallbacks were exercised, not only the plain path


def test_the_tracker_takes_a_sweep_in_any_order_of_its_beacons_row_by_row() -> None:
    """The same beacons listed in another order than the tracks (a sweep's own order) correct each track by
    its own fix: bit for bit what fixes given in the tracks' order do, sweep after sweep, and a beacon that
    comes or goes still starts or ends its own track."""
    rng = np.random.default_rng(12)
    names = [f"robot-{k}" for k in range(7)]
    shuffled, in_order = BeaconTracker(), BeaconTracker()
    own = np.array([0.3, -0.1])
    for sweep in range(30):
        present = names if sweep % 10 else names[: 4 + sweep % 3]
        xy = rng.normal(0.0, 1.0, (len(present), 2))
        order = [int(i) for i in rng.permutation(len(present))] if sweep % 4 else list(range(len(present)))
        for tracker in (shuffled, in_order):
            tracker.predict(own, 0.04)
        swept = [present[i] for i in order]
        shuffled.update_many(swept, xy[order], own)
        # the tracks' order, new beacons after them in the sweep's order (where a new track goes)
        rows = [present.index(n) for n in in_order.names if n in present]
        rows += [present.index(n) for n in swept if n not in in_order.names]
        in_order.update_many([present[i] for i in rows], xy[rows], own)
        assert shuffled.names == in_order.names
        assert shuffled.positions.tobytes() == in_order.positions.tobytes()
        assert shuffled.velocities.tobytes() == in_order.velocities.tobytes()
    assert shuffled.velocity_of("robot-6") is not None
