"""Lockstep time over real processes: hub and robot processes on loopback, model time owned by the hub."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.process
ROOT = Path(__file__).resolve().parents[2]


def _run(tmp: Path, clock: str, *extra: str) -> dict:
    argv = [sys.executable, "-m", "cli", "run", "--robots", "4", "--organize", "2", "--duration", "2", "--seed", "5"]
    done = subprocess.run(
        [*argv, *extra, "--clock", clock, "--json", "--record", str(tmp / clock)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
    )
    assert done.stdout, done.stderr[-2000:]
    return json.loads(done.stdout)


@pytest.mark.timeout(400)
def test_robot_processes_in_lockstep_do_exactly_what_the_model_time_run_does(tmp_path: Path) -> None:
    """Four robot processes and a hub over zenoh, the hub granting model time: the record is the model-time
    run's, event for event and frame for frame, whatever the machine's load does to the processes."""
    model = _run(tmp_path, "model")
    lockstep = _run(tmp_path, "lockstep")
    assert model["ok"] and lockstep["ok"], (model["problems"], lockstep["problems"])
    assert lockstep["clock"] == "lockstep" and lockstep["model_time_s"] == model["model_time_s"]
    assert lockstep["digest"] == model["digest"]
    assert lockstep["organization"]["members"] == model["organization"]["members"]
    # the processes really were separate: each robot reports its own process's memory
    assert all(node["peak_rss_mb"] for node in lockstep["nodes"].values())
    assert (tmp_path / "lockstep" / "air.pcap").read_bytes() == (tmp_path / "model" / "air.pcap").read_bytes()
