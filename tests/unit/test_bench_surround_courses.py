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
