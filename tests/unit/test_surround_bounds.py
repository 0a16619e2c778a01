"""Issue 17's four bounds on a surround run's figures, and the bench's count of them (pure: figures in)."""

from __future__ import annotations

from typing import Any

import pytest

from petswarm.bench.surround import bounds_summary, summary_lines
from petswarm.lab.surround_metrics import bounds_met


def _figures(total: int = 0, connected: float = 1.0, median: float = 0.3, r_end_off: float = 0.05) -> dict[str, Any]:
    kinds = {"robot_robot": 0, "robot_obstacle": total, "robot_human": 0, "unattributed": 0, "total": total}
    return {
        "contacts": kinds,
        "connected_fraction": connected,
        "centre_to_human_walking_m": {"median": median, "p90": median + 0.2, "n": 10},
        "r_end_m": 0.65 * (1 + r_end_off),
        "r_end_off": r_end_off,
    }


def test_a_run_within_every_bound_meets_all_four_even_at_the_edges() -> None:
    assert bounds_met(_figures(connected=0.99, median=0.5, r_end_off=0.1)) == {
        "no_contact": True,
        "connected": True,
        "inside": True,
        "r_end": True,
        "all": True,
    }


@pytest.mark.parametrize(
    ("figures", "missed"),
    [
        (_figures(total=1), "no_contact"),
        (_figures(connected=0.9899), "connected"),
        (_figures(median=0.5001), "inside"),
        (_figures(r_end_off=0.1001), "r_end"),
    ],
)
def test_each_bound_alone_fails_the_run(figures: dict[str, Any], missed: str) -> None:
    met = bounds_met(figures)
    assert not met[missed] and not met["all"]
    assert all(ok for bound, ok in met.items() if bound not in (missed, "all"))


def test_a_run_with_no_figures_meets_none() -> None:
    assert not any(bounds_met({}).values())
    assert not bounds_met({**_figures(), "centre_to_human_walking_m": None})["inside"]  # he never walked


def test_the_bench_counts_each_bound_and_names_the_seeds_that_missed() -> None:
    runs = [
        {"seed": seed, **figures, "bounds": bounds_met(figures)}
        for seed, figures in [(1, _figures()), (2, _figures(total=2)), (3, _figures(connected=0.9, median=0.45))]
    ]
    runs.append({"seed": 4, "ok": False, "problems": ["no world"], "bounds": bounds_met({})})
    summary = bounds_summary({"runs": {"corridor": {"improved": runs}}})
    row = summary["corridor improved"]
    assert row["runs"] == 4 and row["missed"] == [2, 3, 4]
    assert row["met"] == {"no_contact": 2, "connected": 2, "inside": 3, "r_end": 3, "all": 1}
    assert row["contacts"]["robot_obstacle"] == 2 and row["median_m"] == [0.3, 0.45]
    [_head, line] = summary_lines(summary)
    assert "all four 1/4" in line and "missed: seeds 2, 3, 4" in line and "rr/ro/rh 0/2/0" in line
