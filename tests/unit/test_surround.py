"""The surround formation: the per-robot law, its metrics, and the paper's setups in the pure simulation."""

from __future__ import annotations

import math
import random
import struct

import numpy as np
import pytest

from petswarm.bench import surround_sim as sim
from petswarm.controllers.surround import (
    MIN_RANGE_M,
    Obstacles,
    SurroundConfig,
    SurroundController,
    SurroundLaw,
    collisions,
    connected,
    extent,
    min_separation,
)

CONFIG = SurroundConfig()
PAPER_R_STAR = 0.65


def test_config_rejects_bad_fields_by_name_and_round_trips() -> None:
    with pytest.raises(ValueError, match="repulsion"):
        SurroundConfig(repulsion=-1.0)
    with pytest.raises(ValueError, match="dt_s"):
        SurroundConfig(dt_s=0.0)
    with pytest.raises(ValueError, match="avoidance_m"):
        SurroundConfig(avoidance_m=2.0)
    with pytest.raises(ValueError, match="inertia"):
        SurroundConfig(inertia=1.0)
    with pytest.raises(ValueError, match="unknown key "):
        SurroundConfig.from_dict({"sigth_m": 1.0})
    config = SurroundConfig(surround_force=1.0)
    assert SurroundConfig.from_dict(config.to_dict()) == config


@pytest.mark.parametrize("config", [CONFIG, SurroundConfig(centroid_filter_s=0.05)])
def test_controller_is_the_batched_law_for_one_robot_bit_for_bit(config: SurroundConfig) -> None:
    # the controller is the law in plain floats: equal to the last bit, with up to 19 neighbours (numpy sums
    # longer runs pairwise, so an order the controller does not share would show), robots entering and
    # leaving the sight, points at the centre, the human unseen, and the robot still
    rng = np.random.default_rng(3)
    controller, law = SurroundController(config), SurroundLaw(config, 2)
    velocity = np.zeros(2)
    for step in range(60):
        k, m = int(rng.integers(0, 20)), int(rng.integers(0, 9))
        neighbours, obstacles = rng.uniform(-1.2, 1.2, (k, 2)), rng.uniform(-0.6, 0.6, (m, 2))
        if k and step % 7 == 0:
            neighbours[0] = 0.0
        human = None if step % 5 == 0 else rng.uniform(-1, 1, 2)
        single = controller.step(neighbours, obstacles, human, velocity, config.dt_s)
        batch = law.step(
            np.stack([neighbours, -neighbours]),
            np.ones((2, k), dtype=bool),
            np.stack([obstacles, obstacles]),
            np.ones((2, m), dtype=bool),
            np.stack([np.zeros(2) if human is None else human] * 2),
            np.full(2, human is not None),
            np.stack([velocity, velocity]),
            config.dt_s,
        )
        np.testing.assert_array_equal(single, batch[0])
        for mine, theirs in zip(
            controller.last_forces, (law.last.centroid, law.last.repulsion, law.last.surround), strict=True
        ):
            np.testing.assert_array_equal(mine, theirs[0])
        velocity = single if step % 11 else np.zeros(2)


def test_an_obstacle_ahead_pushes_back_and_far_things_are_ignored() -> None:
    controller = SurroundController(CONFIG)
    controller.step(np.array([[1.5, 0.0]]), np.array([[0.3, 0.0], [0.0, 0.9]]), None, np.zeros(2), 0.02)
    f_r, f_o, f_g = controller.last_forces
    np.testing.assert_allclose(f_r, 0.0)  # the only robot is beyond the sight
    assert f_o[0] == pytest.approx(-CONFIG.repulsion / 0.3**2) and f_o[1] == 0.0
    np.testing.assert_allclose(f_g, 0.0)  # no human sensed


def test_rear_robots_push_toward_the_human_and_front_robots_do_not() -> None:
    rear, front = SurroundController(CONFIG), SurroundController(CONFIG)
    # Human ahead (+x); the rear robot's local swarm lies toward him and it moves that way.
    rear.step(np.array([[0.6, 0.3], [0.6, -0.3]]), np.zeros((0, 2)), np.array([2.0, 0.0]), np.array([0.5, 0]), 0.02)
    # The front robot is ahead of the human and of its swarm, moving on (+x), away from its swarm's centroid.
    front.step(np.array([[-0.6, 0.3], [-0.6, -0.3]]), np.zeros((0, 2)), np.array([-2.0, 0.0]), np.array([0.5, 0]), 0.02)
    assert rear.last_forces[2] == pytest.approx([CONFIG.surround_force, 0.0])
    assert np.linalg.norm(front.last_forces[2]) == pytest.approx(0.0, abs=1e-12)


def test_a_robot_entering_the_sight_is_not_read_as_motion() -> None:
    controller = SurroundController(CONFIG)
    still = np.zeros(2)
    neighbours = np.array([[0.4, 0.0], [0.0, 0.4]])
    for _ in range(3):
        controller.step(neighbours, np.zeros((0, 2)), None, still, 0.02)
    entered = np.vstack([neighbours, [[-0.95, 0.0]]])
    controller.step(entered, np.zeros((0, 2)), None, still, 0.02)
    g = entered.sum(axis=0) / 4
    np.testing.assert_allclose(controller.last_forces[0], CONFIG.stiffness * g)


def test_controller_rejects_malformed_sensing() -> None:
    controller = SurroundController(CONFIG)
    with pytest.raises(ValueError, match="neighbours_xy"):
        controller.step(np.zeros((3, 3)), np.zeros((0, 2)), None, np.zeros(2), 0.02)
    with pytest.raises(ValueError, match="own_velocity"):
        controller.step(np.zeros((0, 2)), np.zeros((0, 2)), None, np.array([np.nan, 0.0]), 0.02)


def test_metrics() -> None:
    square = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    assert extent(square) == pytest.approx(np.sqrt(0.5))
    assert connected(square, 1.01) and not connected(square, 0.99)
    assert connected(np.array([[0.0, 0.0], [0.9, 0.0], [1.8, 0.0]]), 1.0)  # linked through the middle robot
    assert min_separation(square) == pytest.approx(1.0)
    walls = Obstacles(circles=np.array([[0.0, 0.5, 0.45]]), segments=np.array([[-1.0, 1.05, 2.0, 1.05]]))
    count = collisions(np.vstack([square, [[0.15, 0.0]]]), 0.1, walls)
    assert (count.robot_robot, count.robot_obstacle) == (1, 5)  # (0,0)-(0.15,0); the circle 3, the wall 2


def test_lattice_and_human_walk() -> None:
    grid = sim.lattice(20, 0.8, (1.0, 2.0))
    assert grid.shape == (20, 2) and min_separation(grid) == pytest.approx(0.8)
    np.testing.assert_allclose(grid.mean(axis=0), (1.0, 2.0))
    walk = sim.HumanWalk()
    speeds = np.diff([walk.travelled(t) for t in np.arange(0, 8, 0.01)]) / 0.01
    assert speeds.max() == pytest.approx(1.0, abs=0.01) and np.all(np.diff(speeds) > -1e-9)  # speeds up only
    assert walk.time_at(walk.travelled(6.3)) == pytest.approx(6.3)


@pytest.fixture(scope="module")
def r_star() -> dict[float, float]:
    """The extent under local forces alone, from each lattice (8 s: both settle within ~5 s)."""
    runs = {s: sim.simulate(CONFIG, sim.free(s), seed=1, duration=8.0) for s in (0.8, 0.2)}
    for run in runs.values():
        assert not run.collisions and run.connected.all()
    return {s: run.mean_r(6.0, 9.0) for s, run in runs.items()}


def test_both_lattices_converge_to_the_papers_extent(r_star: dict[float, float]) -> None:
    assert r_star[0.8] == pytest.approx(r_star[0.2], rel=0.10)
    assert r_star[0.8] == pytest.approx(PAPER_R_STAR, rel=0.10)


@pytest.mark.parametrize("scenario", [sim.corridor(), sim.cylinder()], ids=lambda s: s.name)
def test_the_swarm_passes_the_obstacle_with_the_human(scenario: sim.Scenario, r_star: dict[float, float]) -> None:
    run = sim.simulate(CONFIG, scenario, seed=1, duration=sim.WALK_S)
    assert run.robot_robot.sum() == run.robot_obstacle.sum() == run.robot_human.sum() == 0
    assert run.connected.all()
    assert np.linalg.norm(run.positions.mean(axis=0) - run.human[-1]) < 1.0  # the swarm came along
    assert run.mean_r(sim.WALK_S - 2.0, sim.WALK_S + 1.0) == pytest.approx(r_star[0.8], rel=0.10)


def test_noisy_runs_follow_the_seed() -> None:
    noisy = sim.Scenario("noisy", robots=6, spacing_m=0.4, noisy=True)
    first, again, other = (sim.simulate(CONFIG, noisy, seed, 0.5) for seed in (7, 7, 8))
    np.testing.assert_array_equal(first.positions, again.positions)
    assert not np.allclose(first.positions, other.positions)


def _repulsion_as_summed_before(
    config: SurroundConfig, neighbours: list[list[float]], near: list[bool], obstacles: list[tuple[float, float]]
) -> tuple[float, float]:
    """The repulsion as the controller first wrote it (one list of points, ``max`` for the floors): the
    reference its faster loops must equal, zero signs and nans included."""
    sx = sy = 0.0
    points = [(p, math.sqrt(p[0] * p[0] + p[1] * p[1]), seen) for p, seen in zip(neighbours, near, strict=True)]
    points += [(p, math.sqrt(p[0] * p[0] + p[1] * p[1]), True) for p in obstacles]
    for i, ((x, y), d, seen) in enumerate(points):
        inside = seen and d <= config.avoidance_m and d > 0
        reach = max(d, MIN_RANGE_M)
        magnitude = config.repulsion / (reach * reach) if inside else 0.0
        scale = max(d, 1e-12)
        px, py = magnitude * (x / scale), magnitude * (y / scale)
        sx, sy = (px, py) if i == 0 else (sx + px, sy + py)
    return -sx, -sy


def test_the_repulsion_loops_sum_as_the_list_of_points_did_to_the_sign_of_zero() -> None:
    rng = random.Random(5)
    controller = SurroundController(CONFIG)
    special = [0.0, -0.0, 1e-13, -1e-13, 0.01, -0.01, 0.3, -0.3, 2.0, math.nan]

    def value() -> float:
        return rng.choice(special) if rng.random() < 0.5 else rng.uniform(-1.5, 1.5)

    for _ in range(20000):
        neighbours = [[value(), value()] for _ in range(rng.randint(0, 5))]
        obstacles = [(value(), value()) for _ in range(rng.randint(0, 4))]
        distances = [math.sqrt(x * x + y * y) for x, y in neighbours]
        near = [d <= CONFIG.sight_m for d in distances]
        want = _repulsion_as_summed_before(CONFIG, neighbours, near, obstacles)
        got = controller._repulsion(neighbours, distances, near, obstacles)
        assert struct.pack("2d", *got) == struct.pack("2d", *want)
