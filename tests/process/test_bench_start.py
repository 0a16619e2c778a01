"""``petswarm bench start``: robots started both ways through real processes, figures for each way on record."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.timeout(120)
def test_the_start_bench_starts_robots_both_ways_and_records_each_ways_figures(tmp_path: Path) -> None:
    argv = [sys.executable, "-m", "cli", "bench", "start", "--robots", "2", "--rounds", "1", "--out", str(tmp_path)]
    done = subprocess.run([*argv, "--json"], capture_output=True, text=True, timeout=110, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-2000:]
    results = json.loads(done.stdout)
    assert set(results["ways"]) == {"forked", "exec"}
    for way, figures in results["ways"].items():
        assert figures["cpu_per_robot_s"] > 0 and figures["ready_s"] > 0, (way, figures)
        assert 5 < figures["peak_rss_mb"] < 200 and 0 < figures["pss_mb"] <= figures["peak_rss_mb"], (way, figures)
    assert "forked" in done.stderr and "CPU s/robot" in done.stderr  # the table, beside the JSON
    recorded = json.loads((tmp_path / "bench_start.json").read_text())
    assert [s["ready"] for s in recorded["samples"]["forked"] + recorded["samples"]["exec"]] == [True, True]
    assert (tmp_path / "bench_start.png").stat().st_size > 10_000
