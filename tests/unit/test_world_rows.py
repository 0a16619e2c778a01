"""The world keeps its bodies' state as arrays (``_Rows``), each body's arrays views of them: whatever changes
a body, in place or by giving it another array, is what the world's computations see."""

from __future__ import annotations

import math

import numpy as np
import pytest

from radio_hub.physics.world import World, _clip_norms, _ray_hits


def test_a_bodys_arrays_are_the_worlds_rows_however_they_are_changed() -> None:
    world = World()
    world.add("a", "robot", 0.0, 0.0, 0.0)
    world.add("u", "user", 2.0, 0.0, 0.0)
    world.command("a", 1.0, 0.0, 0.0, 0.0)
    world.step(0.1)
    assert world.truth_rows()[0][:2] == [round(float(world.bodies["a"].pose[0]), 4), 0.0]
    world.bodies["a"].pose[1] = 0.5  # in place
    assert world.poses()["a"][1] == 0.5
    world.bodies["u"].pose = np.array([3.0, 1.0, 0.0])  # another array
    assert world.poses()["u"] == (3.0, 1.0, 0.0)
    world.place("u", 4.0, 1.0, 0.0, vx=0.5)
    assert world.truth_rows()[1] == [4.0, 1.0, 0.0, 0.5, 0.0, 0.0]
    world.remove("a")
    world.add("b", "robot", -1.0, 0.0, 0.0)
    assert list(world.poses()) == ["u", "b"] and world.poses()["b"] == (-1.0, 0.0, 0.0)
    assert world.ultrasonic_many(["b"]).shape == (1, len(world.config.ultrasonic_angles_deg))


def test_clipping_norms_without_errstate_gives_the_very_values_of_the_division() -> None:
    rng = np.random.default_rng(5)
    v = np.concatenate([rng.normal(0.0, 2.0, (5000, 2)), np.zeros((3, 2)), [[np.nan, 1.0], [np.inf, 0.0]]])
    for limit in (1.5, 0.04, 1e-300):
        n = np.hypot(v[:, 0], v[:, 1])
        with np.errstate(divide="ignore", invalid="ignore"):
            want = np.where((n > limit)[:, None], v * (limit / n)[:, None], v)
        with np.errstate(invalid="ignore"):  # the infinite row: nan either way, here with numpy's warning
            assert _clip_norms(v, limit).tobytes() == want.tobytes()


def test_ray_hits_in_place_are_the_masked_formula_bit_for_bit() -> None:
    rng = np.random.default_rng(6)
    shape = (7, 8, 3, 9)
    along = rng.normal(0.0, 2.0, shape)
    r2 = rng.uniform(0.0, 1.0, shape[-1]) ** 2
    perp2 = rng.uniform(0.0, 1.5, shape)
    perp2[..., 0] = r2[0]  # grazing: r2 - perp2 exactly 0
    along[..., 1] = 0.0
    not_self = rng.random((shape[0], shape[-1])) > 0.2
    hit = (perp2 <= r2) & (along > 0) & not_self[:, None, None, :]
    with np.errstate(invalid="ignore"):
        want = np.where(hit, np.maximum(along - np.sqrt(r2 - perp2), 0.0), np.inf).min(axis=-1)
    assert _ray_hits(along, perp2.copy(), r2, not_self).tobytes() == want.tobytes()


def test_a_motor_command_or_a_placed_velocity_beyond_the_rate_bound_is_refused_and_changes_nothing() -> None:
    from radio_hub.physics.world import MAX_RATE

    world = World()
    world.add("robot-1", "robot", 0.0, 0.0, math.pi / 4)
    world.add("user", "user", 1.0, 0.0, 0.0)
    world.command("robot-1", MAX_RATE, -MAX_RATE, 0.0, 0.0)  # at the bound: taken
    for vx, vy, omega in ((1.5e308, -1.5e308, 0.0), (0.0, 0.0, 2 * MAX_RATE), (math.nan, 0.0, 0.0)):
        with pytest.raises(ValueError, match="motor command"):
            world.command("robot-1", vx, vy, omega, 0.1)
    with pytest.raises(ValueError, match="velocity"):
        world.place("user", 1.0, 0.0, 0.0, vx=1e300)
    assert world.bodies["robot-1"].command.tolist() == [MAX_RATE, -MAX_RATE, 0.0]
    world.step(0.04)
    assert all(math.isfinite(v) for b in world.bodies.values() for v in (*b.pose, *b.velocity))
