"""The surround formation, process-level: a hub, a user process wearing an IR beacon and 20 robot processes,
each robot sensing its neighbours and the human only through IR beacons and obstacles through ultrasonic.

The spec's claim (spec/surround-swarm.md): through the corridor (1.2 m) and past the cylinder (1.0 m) no
collisions, the swarm stays connected, and r returns to r*. In processes the swarm stays connected and
settles at r* with a few contacts (CONTACTS_BOUND); it does not keep up with its human through the
corridor at 1 m/s (README, "Surround formation"), which these tests do not claim.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.process
ROOT = Path(__file__).resolve().parents[2]

R_STAR_M = 0.65
"""The extent the paper's 20 robots settle to under local forces alone (the law's gains reproduce it)."""
EXTENT_BOUND_M = 0.15
"""Documented bound on |r_end - r*|: with the human standing in the middle the swarm's extent is about
0.70 m in the pure simulation (his body takes room), so 0.15 m leaves 0.1 m for the sensing noise."""
CONTACTS_BOUND = 3
"""Documented bound on body contacts per run (README): measured 1 (corridor) and 0 (cylinder) with seed 1;
21-36 before the ultrasonic safety stage. The spec's claim is none."""


def _run(scenario: str, tmp_path: Path) -> dict:
    argv = [sys.executable, "-m", "cli", "run", str(ROOT / "scenarios" / scenario), "--seed", "1", "--json"]
    done = subprocess.run([*argv, "--record", str(tmp_path / "run")], capture_output=True, text=True, timeout=200)
    summary = json.loads(done.stdout)
    assert done.returncode == 0, summary["problems"]
    return summary["driving"]


@pytest.mark.timeout(240)  # 20 robot processes start on 2 cores, then a 22 s scenario: about 30 s measured
@pytest.mark.parametrize("scenario", ["surround-corridor.toml", "surround-cylinder.toml"])
def test_the_surround_swarm_passes_the_obstacle_connected_and_settles_near_r_star(
    scenario: str, tmp_path: Path
) -> None:
    driving = _run(scenario, tmp_path)
    assert driving["connected_at_end"], driving["connected_fraction"]
    assert driving["connected_fraction"] >= 0.95, driving["connected_fraction"]
    assert abs(driving["extent_end_m"] - R_STAR_M) < EXTENT_BOUND_M, driving["extent_end_m"]
    assert driving["collisions"] <= CONTACTS_BOUND, driving["collisions"]
