"""``petswarm bench surround --train/--test``: generated courses, judged on their own r*, summarised per law and set."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from cli.main import main
from petswarm.bench.surround_bench_courses import course_jobs, summarise
from petswarm.bench.surround_courses import TRAINING_SET, course


def _run(set_name: str, i: int, law: str, met: dict[str, bool]) -> dict:
    return {
        "set": set_name,
        "course": i,
        "law": law,
        "bounds": {**met, "all": all(met.values())},
        "cpu_s": 2.0,
        "model_time_s": 10.0,
        "contacts": {"robot_robot": 1, "robot_obstacle": 0, "robot_human": 0, "total": 1},
    }


def test_jobs_run_each_course_under_each_law_and_the_summary_counts_each_bound_per_set() -> None:
    jobs = course_jobs(2, 1, ["paper", "safe"], first=5)
    assert jobs == [
        ("train", 5, "paper"),
        ("train", 5, "safe"),
        ("train", 6, "paper"),
        ("train", 6, "safe"),
        ("test", 5, "paper"),
        ("test", 5, "safe"),
    ]
    good = dict.fromkeys(("no_contact", "connected", "inside", "r_end"), True)
    runs = [
        _run("train", 0, "safe", good),
        _run("train", 1, "safe", {**good, "r_end": False}),
        _run("test", 0, "safe", {**good, "inside": False}),
    ]
    summary = summarise(runs)
    train, test = summary["safe"]["train"], summary["safe"]["test"]
    assert train["courses"] == 2 and train["met"]["r_end"] == 1 and train["met"]["all"] == 1
    assert train["missed"] == [1] and train["share"]["no_contact"] == 1.0
    assert test["met"]["inside"] == 0 and test["missed"] == [0] and test["cpu_per_model_s"] == 0.2


@pytest.mark.timeout(600)  # a model-time run of 28 robots: seconds on a quiet machine, minutes on a loaded one
def test_a_training_course_runs_in_model_time_judged_on_its_own_r_star(tmp_path: Path, capsys) -> None:
    """One training course under the paper's law: its r at the end is judged against its robot count's r*, and the
    JSON, the runs' JSON lines and the plot are written."""
    argv = ["bench", "surround", "--train", "1", "--first-course", "9", "--law", "paper", "--out", str(tmp_path)]
    assert main([*argv, "--json"]) == 0
    results = json.loads(capsys.readouterr().out)
    (run,) = results["runs"]
    drawn = course(TRAINING_SET, 9)["course"]
    assert run["r_star_m"] == drawn["r_star_m"] != 0.65
    assert run["r_end_off"] == round(abs(run["r_end_m"] - drawn["r_star_m"]) / drawn["r_star_m"], 4)
    assert run["bounds"]["r_end"] == (run["r_end_off"] <= 0.10)
    assert results["summary"]["paper"]["train"]["courses"] == 1
    assert (tmp_path / "bench_surround_courses.png").stat().st_size > 5_000
    assert len((tmp_path / "bench_surround_courses_runs.jsonl").read_text().splitlines()) == 1


def _robot(name: str, x: float, y: float, yaw: float = 0.0, vx: float = 0.0) -> dict:
    return {"id": name, "kind": "robot", "x": x, "y": y, "yaw": yaw, "vx": vx, "vy": 0.0, "radius": 0.1}


def test_contact_events_name_each_touch_its_bearing_and_whether_the_ring_could_hear_it() -> None:
    """A robot meeting a wall's end dead ahead is heard (on a cone's axis); one meeting it 22.5 degrees off its heading
    met it in a blind gap; a pair of robots touching is one event; a tick where the count rose by one gives the
    deepest touch only (as the contact counts put it down); ticks where the count did not rise give none."""
    import math

    from petswarm.bench.surround_bench_courses import contact_events

    wall = {"kind": "wall", "x0": 1.0, "y0": 0.0, "x1": 3.0, "y1": 0.0}
    quiet = {"t_us": 0, "collisions": 0, "bodies": [_robot("robot-1", 0.5, 0.0)], "obstacles": [wall]}
    ahead = {"t_us": 1_000_000, "collisions": 1, "bodies": [_robot("robot-1", 0.9, 0.0, vx=0.5)], "obstacles": [wall]}
    yaw = -math.radians(22.5)  # the wall's end 22.5 degrees to its left: midway between two cones
    away = {**quiet, "t_us": 1_500_000, "collisions": 1}
    gap = {"t_us": 2_000_000, "collisions": 2, "bodies": [_robot("robot-1", 0.9, 0.0, yaw)], "obstacles": [wall]}
    still = {**gap, "t_us": 3_000_000}
    pair = {
        "t_us": 4_000_000,
        "collisions": 3,
        "bodies": [_robot("robot-1", 0.0, 5.0), _robot("robot-2", 0.2, 5.0, math.pi / 2)],
        "obstacles": [wall],
    }
    both = {**pair, "t_us": 5_000_000, "collisions": 4}
    both["bodies"] = [*pair["bodies"], _robot("robot-3", 0.1, 5.17)]  # robot-3 overlaps both; the pair just touches
    events = contact_events([quiet, ahead, away, gap, still, pair, both])
    assert [(e["t"], e["with"], e["blind_gap"]) for e in events] == [
        (1.0, "obstacle", False),
        (2.0, "obstacle", True),
        (4.0, "robot", False),
        (5.0, "robot", False),
    ]
    assert events[0]["wall_end"] and events[0]["speed_mps"] == 0.5 and events[0]["bearing_deg"] == 0.0
    assert events[1]["bearing_deg"] == 22.5
    assert events[2]["robot"] == "robot-1"
    assert events[3]["robot"] == "robot-1" and events[3]["gap_m"] < 0  # the count rose by one: the deeper touch
