"""The generated surround courses (``petswarm.bench.surround_courses``): pure, inside the issue's ranges, runnable."""

from __future__ import annotations

import math

import pytest

from petswarm.bench.surround_courses import (
    R_STAR_M,
    TEST_SET,
    TRAINING_SET,
    course,
    r_star,
    scenario_tables,
)
from petswarm.scenario import parse


def test_a_course_draws_only_from_its_set_seed_and_index() -> None:
    """Course 7 is the same drawn alone or after others; another index or set gives another course."""
    alone = course(TEST_SET, 7)
    for i in range(7):
        course(TEST_SET, i)
    assert course(TEST_SET, 7) == alone
    assert course(TEST_SET, 8) != alone
    assert course(TRAINING_SET, 7) != alone


def test_training_and_test_sets_share_no_world() -> None:
    """The split: no training course is also a test course (worlds and run seeds)."""
    train = {repr(scenario_tables(course(TRAINING_SET, i))["obstacles"]) for i in range(40)}
    test = {repr(scenario_tables(course(TEST_SET, i))["obstacles"]) for i in range(200)}
    assert not train & test
    seeds = {course(TRAINING_SET, i)["run_seed"] for i in range(40)}
    assert not seeds & {course(TEST_SET, i)["run_seed"] for i in range(200)}


def _gap_between_circles(a: dict, b: dict) -> float:
    return math.hypot(a["x"] - b["x"], a["y"] - b["y"]) - a["r"] - b["r"]


@pytest.mark.parametrize("i", range(60))
def test_every_course_parses_and_keeps_within_the_ranges(i: int) -> None:
    """Each of 60 test courses parses as a scenario, and what it drew is within the issue's ranges: corridors
    1.0-2.0 m x 2-6 m, cylinders 0.4-1.5 m, gaps between obstacles of at least 1.2 m, top speed 0.5-1.2 m/s,
    10-30 robots none within 0.5 m of the human, every start clear of the obstacles."""
    data = course(TEST_SET, i)
    scenario = parse(scenario_tables(data))
    drawn = data["course"]
    assert 10 <= scenario.robot_count <= 30 and scenario.surround_enabled
    assert 0.5 <= drawn["top_speed_mps"] <= 1.2
    assert drawn["r_star_m"] == R_STAR_M[scenario.robot_count]
    speeds = [leg["speed"] for leg in data["user"]["path"] if "walk" in leg]
    assert max(speeds) == drawn["top_speed_mps"]
    for x, y, _ in data["robots"]["positions"]:
        assert math.hypot(x, y) >= 0.5 - 0.15
    circles = [o for o in data["obstacles"] if o["kind"] == "circle"]
    if drawn["kind"] == "corridor":
        assert 1.0 <= drawn["width_m"] <= 2.0 and 2.0 <= drawn["length_m"] <= 6.0
    elif drawn["kind"] == "cylinder":
        assert 0.4 <= circles[0]["r"] <= 1.5
    else:
        gaps = [_gap_between_circles(a, b) for k, a in enumerate(circles) for b in circles[k + 1 :]]
        assert min(gaps) >= 1.2 - 0.01


def test_a_straight_corridor_is_as_wide_as_drawn_and_the_human_walks_through_it() -> None:
    """A straight corridor's two walls are its width apart, and his path crosses its whole length."""
    data = next(
        d
        for d in (course(TRAINING_SET, i) for i in range(100))
        if d["course"]["kind"] == "corridor" and not d["course"]["bend_deg"] and not d["course"]["turn_before_deg"]
    )
    a, b = data["obstacles"]
    assert abs(a["y0"] - b["y0"]) == pytest.approx(data["course"]["width_m"], abs=0.002)
    walked = sum(leg["walk"] for leg in data["user"]["path"] if "walk" in leg)
    assert walked >= a["x1"]


def test_r_star_table_is_the_pure_simulation() -> None:
    """The written-down r* per robot count is what the paper's pure simulation gives (two counts checked)."""
    for n in (10, 20):
        assert r_star(n) == R_STAR_M[n]
