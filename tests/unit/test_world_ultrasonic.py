"""The world's ultrasonic ring (radio_hub/physics/world.py): an obstacle echoes from its nearest point inside a
sensor's whole cone, as an HC-SR04-like transducer hears it, not only where the cone's three rays meet it."""

from __future__ import annotations

import math

import pytest

from radio_hub.physics.world import Obstacle, World, WorldConfig

RADIUS_M = 0.1


def _world(*obstacles: Obstacle) -> World:
    world = World(WorldConfig(robot_radius_m=RADIUS_M), list(obstacles))
    world.add("robot-1", "robot", 0.0, 0.0, 0.0)
    return world


def _at(distance_m: float, bearing_deg: float) -> tuple[float, float]:
    return distance_m * math.cos(math.radians(bearing_deg)), distance_m * math.sin(math.radians(bearing_deg))


def test_a_walls_end_between_the_rays_echoes_from_the_end() -> None:
    # a wall running away to the left from an end 0.6 m off, 8 degrees left of the forward sensor's axis:
    # the axis ray passes right of it and the 15 degree edge ray meets the wall far beyond the end
    x, y = _at(0.6, 8.0)
    ranges = _world(Obstacle("wall", x0=x, y0=y, x1=x, y1=3.0)).ultrasonic("robot-1")
    assert ranges[0] == pytest.approx(0.6 - RADIUS_M)


def test_a_small_cylinder_between_the_rays_echoes_from_its_near_side() -> None:
    x, y = _at(1.0, 7.0)  # 5 cm across: between the axis and the edge ray, 1 m off
    ranges = _world(Obstacle("circle", x=x, y=y, r=0.05)).ultrasonic("robot-1")
    assert ranges[0] == pytest.approx(1.0 - 0.05 - RADIUS_M)


def test_an_obstacle_outside_every_cone_is_not_heard() -> None:
    x, y = _at(0.6, 22.5)  # between the 0 and 45 degree sensors' cones (each 15 degrees either side)
    ranges = _world(Obstacle("circle", x=x, y=y, r=0.05)).ultrasonic("robot-1")
    assert all(math.isnan(r) for r in ranges)


def test_a_wall_across_the_beam_echoes_from_its_nearest_point() -> None:
    # a long wall square to the forward axis: nearest on the axis, as the rays had it
    ranges = _world(Obstacle("wall", x0=0.8, y0=-2.0, x1=0.8, y1=2.0)).ultrasonic("robot-1")
    assert ranges[0] == pytest.approx(0.8 - RADIUS_M)
    # the 45 degree sensor hears the same wall along its cone's nearer edge (30 degrees off the wall's normal)
    assert ranges[1] == pytest.approx(0.8 / math.cos(math.radians(30.0)) - RADIUS_M)
