"""The reaction bench's arithmetic and outputs on made-up trials (the runs themselves are process-level)."""

from __future__ import annotations

from pathlib import Path

import pytest

from petswarm.bench.reaction import plot_cdfs, summarise, table


def _trial(master: float | None, slaves: dict[str, float | None]) -> dict:
    gaps = {n: round(s - master, 3) for n, s in slaves.items() if s is not None and master is not None}
    return {"master": "robot-1", "master_s": master, "slaves_s": slaves, "slave_minus_master_s": gaps}


def test_percentiles_count_every_slave_and_the_reactions_that_never_came(tmp_path: Path) -> None:
    trials = [
        _trial(0.2, {"robot-2": 0.3, "robot-3": 0.25}),
        _trial(0.4, {"robot-2": 0.5, "robot-3": None}),
        _trial(None, {"robot-2": 0.6, "robot-3": 0.7}),
    ]
    results = summarise(trials)
    assert results["trials"] == 3
    assert results["master_s"]["n"] == 2 and results["master_s"]["mean"] == pytest.approx(0.3)
    assert results["slave_s"]["n"] == 5 and results["slave_s"]["max"] == pytest.approx(0.7)
    assert sorted(results["samples"]["slave_minus_master_s"]) == pytest.approx([0.05, 0.1, 0.1])
    assert results["missed_reactions"] == 2
    text = "\n".join(table(results))
    assert "master" in text and "missed reactions (no turn within 5 s): 2" in text
    path = tmp_path / "reaction.png"
    plot_cdfs(results, path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 5000


def test_no_trials_give_no_statistics_rather_than_an_error() -> None:
    results = summarise([])
    assert results["master_s"] is None and results["slave_s"] is None
    assert any("no samples" in line for line in table(results))
