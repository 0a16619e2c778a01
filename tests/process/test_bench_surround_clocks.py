"""``petswarm bench surround --clock lockstep``: the bench's robots as processes give the model-time bench's row.

Five robots of the improved cylinder scenario for 5 s (the human sets off at 3 s), so the proof costs seconds, not
the half minute of each 20-robot run that tests/process/surround_improved_runs.py spends through ``petswarm run``."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from cli.main import main

pytestmark = pytest.mark.process
ROOT = Path(__file__).resolve().parents[2]


def _short_scenario(tmp: Path) -> Path:
    """The improved cylinder scenario cut to its lattice's second row of five robots and 5 s."""
    text = (ROOT / "scenarios" / "surround-cylinder-improved.toml").read_text()
    head, positions = text.split("positions = [", 1)
    rows = re.findall(r"\[[^\[\]]+\]", positions)[5:10]
    head = head.replace("duration_s = 22", "duration_s = 5").replace("count = 20", "count = 5")
    head = head.replace('name = "surround-cylinder-improved"', 'name = "surround-five"')
    path = tmp / "surround-five.toml"
    path.write_text(head + "positions = [" + ", ".join(rows) + "]\n")
    return path


@pytest.mark.timeout(300)
def test_the_lockstep_bench_gives_the_model_time_bench_row_run_by_processes(tmp_path: Path, capsys) -> None:
    scenario = str(_short_scenario(tmp_path))
    rows = {}
    for clock in ("model", "lockstep"):
        argv = ["bench", "surround", scenario, "--law", "improved", "--seeds", "1", "--clock", clock, "--json"]
        assert main([*argv, "--out", str(tmp_path / clock)]) == 0
        results = json.loads(capsys.readouterr().out)
        assert results["clock"] == clock
        [rows[clock]] = results["runs"]["surround-five"]["improved"]
    assert rows["lockstep"]["ok"], rows["lockstep"]["problems"]
    assert rows["lockstep"]["digest"] and rows["lockstep"] == rows["model"]
    assert rows["model"]["centre_to_human_walking_m"] is not None  # the human walked: the figures are not empty


def test_a_clock_the_bench_cannot_repeat_is_refused(capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["bench", "surround", "--clock", "wall"])
    assert exit_.value.code == 2 and "invalid choice: 'wall'" in capsys.readouterr().err


@pytest.mark.timeout(300)
def test_runs_on_worker_processes_give_the_rows_of_runs_one_after_another(tmp_path: Path, capsys) -> None:
    scenario = str(_short_scenario(tmp_path))
    results = {}
    for jobs in (1, 2):
        argv = ["bench", "surround", scenario, "--law", "both", "--seeds", "2", "--jobs", str(jobs), "--json"]
        assert main([*argv, "--out", str(tmp_path / f"jobs{jobs}")]) == 0
        results[jobs] = json.loads(capsys.readouterr().out)
    runs = results[2]["runs"]["surround-five"]
    assert [run["seed"] for run in runs["paper"]] == [1, 2] and [run["seed"] for run in runs["improved"]] == [1, 2]
    assert len({run["digest"] for law in runs.values() for run in law}) == 4  # four different runs, each whole
    assert results[2]["runs"] == results[1]["runs"] and results[2]["summary"] == results[1]["summary"]


def test_jobs_are_for_model_time(tmp_path: Path, capsys) -> None:
    argv = ["bench", "surround", "--clock", "lockstep", "--jobs", "2", "--seeds", "1", "--out", str(tmp_path)]
    assert main(argv) == 2
    assert "--jobs applies to --clock model" in capsys.readouterr().err
