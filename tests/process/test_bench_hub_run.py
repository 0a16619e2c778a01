"""``petswarm bench hub --floor``, small: both phases through real hub, echo and load processes, then again on
the floor's hub (``--floor``), figures on record.

The figures themselves are the machine's (never asserted); what is asserted is that every phase ran: each
round trip answered, the load's frames delivered, the JSON and the plot written. A bench whose nodes cannot
reach the hub fails here, not when someone next measures."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.timeout(120)
def test_a_small_hub_bench_runs_every_phase_and_records_its_figures(tmp_path: Path) -> None:
    argv = [sys.executable, "-m", "cli", "bench", "hub", "--rounds", "20", "--nodes", "4", "--load-seconds", "1"]
    argv.append("--floor")
    done = subprocess.run(
        [*argv, "--out", str(tmp_path), "--json"], capture_output=True, text=True, timeout=110, cwd=ROOT
    )
    assert done.returncode == 0, done.stderr[-2000:]
    results = json.loads(done.stdout)
    rtt = results["rtt"]
    assert rtt["lost"] == {"plain": 0, "radio": 0} and rtt["ratio_p50"] > 0, rtt["lost"]
    for load in results["load"]:  # the defaults, and any air configuration the bench also loads
        assert load["nodes"] == 4 and load["delivered"] > 0 and load["frames_per_s"] > 0, load
    floor = results["floor"]  # the same phases on the hub that models nothing
    assert floor["rtt"]["lost"] == {"plain": 0, "radio": 0} and floor["rtt"]["radio_model_us"]["p50"] == 0, floor["rtt"]
    assert floor["load"]["delivered"] > 0 and floor["load"]["collided"] == 0, floor["load"]
    assert "the floor:" in done.stderr
    recorded = json.loads((tmp_path / "bench_hub.json").read_text())
    assert [r["delivered"] for r in recorded["load"]] == [r["delivered"] for r in results["load"]]
    assert (tmp_path / "bench_hub.png").stat().st_size > 10_000
