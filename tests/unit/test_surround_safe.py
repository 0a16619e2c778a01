"""The safe surround law (``petswarm.controllers.surround_safe``): a nominal command under an exact barrier filter."""

from __future__ import annotations

import math

import numpy as np
import pytest

from petswarm.controllers.surround import SurroundConfig
from petswarm.controllers.surround_safe import SafeSurroundController, _excess, _nearest

CONFIG = SurroundConfig(law="safe")


def _stoppable(h: float) -> float:
    a, late = CONFIG.brake_mps2, CONFIG.track_lag_s
    return math.sqrt(a * a * late * late + 2 * a * h) - a * late


@pytest.mark.parametrize("seed", range(20))
def test_the_filter_is_the_exact_nearest_velocity_under_the_half_planes(seed: int) -> None:
    """``_nearest`` against a fine grid search: never farther from the nominal than any allowed grid velocity, and
    itself allowed (random sets of 1-8 half-planes that keep the origin, as the barrier constraints do)."""
    rng = np.random.default_rng(seed)
    angles = rng.uniform(-math.pi, math.pi, int(rng.integers(1, 9)))
    rows = [(math.cos(a), math.sin(a), float(rng.uniform(0.0, 1.0))) for a in angles]
    v = (float(rng.uniform(-1.5, 1.5)), float(rng.uniform(-1.5, 1.5)))
    u = _nearest(v, rows)
    assert _excess(u, rows) <= 1e-9
    grid = np.stack(np.meshgrid(np.linspace(-2, 2, 401), np.linspace(-2, 2, 401)), -1).reshape(-1, 2)
    normals = np.array([r[:2] for r in rows])
    allowed = grid[np.all(grid @ normals.T <= np.array([r[2] for r in rows]) + 1e-12, axis=1)]
    best = float(np.min(np.hypot(*(allowed - np.array(v)).T)))
    assert math.hypot(u[0] - v[0], u[1] - v[1]) <= best + 1e-9


def test_nothing_near_leaves_the_nominal_command_as_it_is() -> None:
    """A robot with no body or wall within reach drives its nominal command, and no constraint is active."""
    law = SafeSurroundController(CONFIG)
    u = law.step_plain([[0.9, 0.0]], [], [3.0, 0.0], (0.5, 0.0), 0.04, (0.5, 0.0), [(0.5, 0.0)], [])
    assert u == law.nominal and law.active == []


def test_a_still_neighbour_ahead_is_closed_on_no_faster_than_the_robot_can_stop() -> None:
    """Driving at 1 m/s toward a still neighbour 0.3 m ahead (centres), the command's speed toward it is the
    barrier's s(h), h the gap beyond touching and the margin: the robot stops short, and the neighbour's constraint
    is the active one. Sideways motion is left alone. Moving away at 0.5 m/s, it may be closed on faster, by its
    speed less what braking over the track's lag takes off it."""
    law = SafeSurroundController(CONFIG)
    # the human far ahead pulls the robot on; a neighbour 0.3 m ahead stands in its way
    u = law.step_plain([[0.3, 0.0]], [], [2.0, 0.5], (1.0, 0.3), 0.04, (1.0, 0.3), [(0.0, 0.0)], [])
    h = 0.3 - 2 * CONFIG.robot_radius_m - CONFIG.stop_margin_m
    assert u[0] == pytest.approx(_stoppable(h), abs=1e-9)
    assert u[1] > 0.2 and law.active == [("neighbour", 0.3, 0.0)]
    law = SafeSurroundController(CONFIG)
    u = law.step_plain([[0.3, 0.0]], [], [2.0, 0.5], (1.0, 0.3), 0.04, (1.0, 0.3), [(0.5, 0.0)], [])
    lost = CONFIG.brake_mps2 * CONFIG.track_lag_s
    assert u[0] == pytest.approx(0.5 - lost + _stoppable(h), abs=1e-9)


def test_a_remembered_wall_point_in_a_blind_gap_stops_the_robot_short() -> None:
    """A wall point the echo memory holds (none heard now) limits the speed toward it as an echo would."""
    law = SafeSurroundController(CONFIG)
    point = (0.25 * math.cos(0.4), 0.25 * math.sin(0.4))
    u = law.step_plain([], [], None, (1.0, 0.0), 0.04, None, [], [point])
    n = (math.cos(0.4), math.sin(0.4))
    h = 0.25 - CONFIG.robot_radius_m - CONFIG.stop_margin_m
    assert n[0] * u[0] + n[1] * u[1] <= _stoppable(h) + 1e-9
    assert law.active and law.active[0][0] == "obstacle"
    free = SafeSurroundController(CONFIG).step_plain([], [], None, (1.0, 0.0), 0.04, None, [], [])
    assert n[0] * free[0] + n[1] * free[1] > _stoppable(h) + 0.1  # without the point it would have driven on


def test_the_human_coming_at_a_robot_makes_it_give_way_and_his_walking_away_gives_no_credit() -> None:
    """The human 0.5 m ahead walking at the robot at 1 m/s: the robot backs away. Walking away from it at 1 m/s:
    it may close only at s(h) (he may stop at any step), not at his speed plus s(h)."""
    law = SafeSurroundController(CONFIG)
    coming = law.step_plain([], [], [0.5, 0.0], (0.0, 0.0), 0.04, (-1.0, 0.0), [], [])
    assert coming[0] < 0 and law.active == [("human", 0.5, 0.0)]
    law = SafeSurroundController(CONFIG)
    going = law.step_plain([], [], [0.5, 0.0], (1.0, 0.0), 0.04, (1.0, 0.0), [], [])
    h = 0.5 - CONFIG.robot_radius_m - 0.25 - CONFIG.stop_margin_m
    assert going[0] == pytest.approx(_stoppable(h), abs=1e-9)


def test_obstacles_and_the_human_come_before_neighbours_when_no_velocity_keeps_them_all() -> None:
    """Squeezed between the human walking at it from behind and a still neighbour just ahead: the robot keeps the
    human's constraint (it moves on, into the neighbour's margin), as the neighbour gives way in turn."""
    law = SafeSurroundController(CONFIG)
    u = law.step_plain([[0.26, 0.0]], [], [-0.42, 0.0], (0.0, 0.0), 0.04, (1.0, 0.0), [(0.0, 0.0)], [])
    human_row = [r for r in [law._body(-0.42, 0.0, 1.0, 0.0, 0.35, True)] if r is not None]
    assert _excess(u, human_row) <= 1e-9
    assert ("human", -0.42, 0.0) in law.active
