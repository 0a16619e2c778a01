"""The safe surround law as 20 robot processes and the human's in lockstep: for seeds 1-3 of each shipped safe
scenario file, the lockstep run is the model-time run, to the digest (each robot steps its own law alone in its own
process; in model time the same code steps every robot, so the filter's numbers are the same bit for bit)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.process, pytest.mark.long]

ROOT = Path(__file__).resolve().parents[2]
TIMEOUT_S = 500
"""A model-time and a lockstep run of 21 processes, on a loaded 2-core machine."""


def _run(scenario: Path, seed: int, clock: str, record: Path) -> dict:
    argv = [sys.executable, "-m", "cli", "run", str(scenario), "--seed", str(seed), "--clock", clock, "--json"]
    done = subprocess.run([*argv, "--record", str(record)], capture_output=True, text=True, timeout=380, cwd=ROOT)
    assert done.stdout, done.stderr[-2000:]
    return json.loads(done.stdout)


@pytest.mark.timeout(TIMEOUT_S)
@pytest.mark.parametrize("obstacle", ["cylinder", "corridor"])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_safe_law_robot_processes_in_lockstep_do_exactly_the_model_time_run(
    obstacle: str, seed: int, tmp_path: Path
) -> None:
    """Seed ``seed`` of scenarios/surround-``obstacle``-safe.toml: lockstep digest == model-time digest."""
    scenario = ROOT / "scenarios" / f"surround-{obstacle}-safe.toml"
    model, lockstep = (_run(scenario, seed, clock, tmp_path / clock) for clock in ("model", "lockstep"))
    assert lockstep["ok"], lockstep["problems"]
    assert model["digest"] and lockstep["digest"] == model["digest"]
