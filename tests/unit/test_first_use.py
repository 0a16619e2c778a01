"""What a new user meets first: last lines that agree with the exit status, refusals in one line, help that
reads on a terminal, progress and verdicts that say what they measure."""

from __future__ import annotations

import argparse
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from cli.main import build_parser
from petswarm import scenario
from tests.unit.test_human_output import _summary

ROOT = Path(__file__).resolve().parents[2]


def test_a_run_whose_robot_died_does_not_end_with_ok(capsys: Any) -> None:
    """Its exit status is 3 (checks held, a process died): its last line must not say plain OK."""
    from petswarm.lab.run import _print
    from petswarm.lab.supervision import DEATHS_ONLY

    death = {"process": "robot-3", "robot": 3, "cause": "SIGKILL", "elapsed_s": 2.5}
    _print(_summary(problems=[], deaths=[death]), as_json=False)
    last = capsys.readouterr().out.splitlines()[-1]
    assert last != "OK" and "robot-3" in last and f"exit status {DEATHS_ONLY}" in last, last
    _print(_summary(problems=[]), as_json=False)
    assert capsys.readouterr().out.splitlines()[-1] == "OK"


def test_a_report_of_such_a_run_says_the_same() -> None:
    from petswarm.lab.supervision import verdict

    died = verdict({"ok": True, "problems": [], "deaths": [{"process": "robot-2"}]})
    assert died.startswith("CHECKS HELD, BUT 1 DIED: robot-2"), died
    assert verdict({"ok": False, "problems": ["x"], "deaths": [{"process": "robot-2"}]}) == "PROBLEMS: x"


def test_more_positions_than_robots_is_refused_by_name() -> None:
    data = {"robots": {"count": 2, "positions": [[0, -1, 90], [0, -1.6, 90], [0, -2.2, 90]]}}
    with pytest.raises(ValueError, match=r"\[robots\] gives 3 positions for count = 2"):
        scenario.parse(data)
    fewer = scenario.parse({"robots": {"count": 3, "positions": [[0, -1, 90]]}})  # the rest on a default grid
    assert len(fewer.robot_poses) == 3 and fewer.robot_poses[0] == (0.0, -1.0, 90.0)


def test_such_a_scenario_is_a_one_line_error_with_exit_2(tmp_path: Path) -> None:
    path = tmp_path / "three.toml"
    path.write_text("duration_s = 1\n[robots]\ncount = 2\npositions = [[0, -1, 90], [0, -1.6, 90], [0, -2.2, 90]]\n")
    done = _petswarm("run", str(path), "--clock", "model")
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "gives 3 positions for count = 2" in done.stderr


def test_a_missing_experiment_file_is_one_plain_line_with_exit_2(tmp_path: Path) -> None:
    missing = tmp_path / "missing.toml"
    done = _petswarm("experiment", str(missing))
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip() == f"petswarm experiment: {missing}: no such file or directory", done.stderr


def _parsers(parser: argparse.ArgumentParser, path: str) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, f"{path} {name}")


def test_no_help_shows_rst_markup() -> None:
    helps = dict(_parsers(build_parser(), "petswarm"))
    assert len(helps) > 20  # every command and subcommand, not just the top
    marked = sorted(path for path, parser in helps.items() if "``" in parser.format_help())
    assert marked == [], marked


def _petswarm(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "cli", *argv], capture_output=True, text=True, timeout=120, cwd=ROOT, check=False
    )


def _axes() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    return fig, ax


def test_the_paths_legend_names_every_marker_a_path_carries() -> None:
    import matplotlib.pyplot as plt

    from petswarm.lab.report import draw_trajectories
    from tests.unit.test_report_world import _tick

    fig, ax = _axes()
    draw_trajectories(ax, [_tick(k) for k in range(300)])
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    plt.close(fig)
    assert {"start", "end", "end, as the master", "heading", "slave's reference"} <= set(labels), labels
    assert "user" in labels


def test_the_state_chart_legend_has_every_state_a_robot_can_be_in() -> None:
    import matplotlib.pyplot as plt

    from petswarm.lab.report import _plot_states
    from petswarm.managers.sequence import RobotState

    fig, ax = _axes()
    _plot_states(ax, {})
    labels = {t.get_text() for t in ax.get_legend().get_texts()}
    plt.close(fig)
    assert {s.label for s in RobotState} <= labels, sorted({s.label for s in RobotState} - labels)


def _bar_colours(ax: Any) -> dict[str, tuple[float, ...]]:
    return {c.get_label(): tuple(c.patches[0].get_facecolor()) for c in ax.containers}


def test_delivered_collided_and_lost_have_one_colour_in_the_report_and_the_results() -> None:
    import matplotlib.pyplot as plt

    from petswarm.lab.experiment import draw_radio_per_run
    from petswarm.lab.report import _plot_radio

    node = {"sent": 5, "delivered": 7, "collided": 1, "lost": 2, "mac_retries": 2}
    fig, (report, results) = plt.subplots(1, 2)
    _plot_radio(report, {"nodes": {"robot-1": node, "robot-2": node}})
    draw_radio_per_run(results, [{"seed": 1, "delivered": 9, "collided": 1, "lost": 3}])
    in_report, in_results = _bar_colours(report), _bar_colours(results)
    plt.close(fig)
    outcomes = ("delivered", "collided", "lost")
    assert {k: in_report[k] for k in outcomes} == {k: in_results[k] for k in outcomes}
    assert len({in_report[k] for k in outcomes}) == 3  # and three distinct colours


@pytest.mark.parametrize(
    ("robots", "user", "line"),
    [(5, False, "6 nodes (5 robots, this run)"), (1, True, "3 nodes (1 robot, the user, this run)")],
)
def test_the_lockstep_progress_line_counts_what_it_runs(robots: int, user: bool, line: str) -> None:
    from petswarm.lab.lockstep_run import nodes_line

    assert nodes_line(robots, user) == line


def test_paper_comparisons_are_judged_only_under_the_testbeds_profile() -> None:
    from petswarm.bench import paper

    rows = [paper.row("organizing time, 3 slaves (s)", 0.7, 0.2), paper.row("organizing time, 1 slave (s)", 0.6, 0.61)]
    ideal = paper.lines(rows, "ideal")
    assert not any(line.endswith((" off", " ok")) for line in ideal), ideal
    assert "not judged" in ideal[0] and f"--profile {paper.TESTBED_PROFILE}" in ideal[0]
    testbed = paper.lines(rows, paper.TESTBED_PROFILE)
    assert testbed[2].endswith(" off") and testbed[3].endswith(" ok"), testbed
    assert [r["within_20pct"] for r in rows] == [False, True]  # the JSON keeps its key and verdict
