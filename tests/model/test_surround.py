"""The surround formation past the cylinder in model time (moved from tests/process/test_surround.py, with its
original bounds): 20 robots and a user wearing an IR beacon, each robot sensing its neighbours and the human
only through IR beacons and obstacles through ultrasonic, all on the hub's environment in one process.

The process test's bounds had been widened after CI flakes (connected 0.95 -> 0.9, keep-up 1.5 -> 2.0 m): 22
processes on 2 cores deliver sensor samples late now and then, which the figures measured, not the law. Model
time has no such lateness, so the original bounds hold here; the spec's claim itself (no contact, always
connected) is asserted by tests/unit/test_bench_surround.py on the same run.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from .harness import SCENARIOS, run_scenario

R_STAR_M = 0.65
"""The extent the paper's 20 robots settle to under local forces alone (the law's gains reproduce it)."""
EXTENT_BOUND_M = 0.15
"""Documented bound on |r_end - r*|: with the human standing in the middle the swarm's extent is about
0.70 m in the pure simulation (his body takes room), so 0.15 m leaves 0.1 m for the sensing noise."""
CONNECTED_FRACTION = 0.95
"""The original bound: the swarm is connected at least this share of the time (seed 1 in model time: 1.0)."""
KEEP_UP_M = 1.5
"""The original bound: at the end the swarm's centre is within this of its human (seed 1 in model time: 0.69 m)."""


@pytest.mark.timeout(300)  # 22 s of 20 robots and their IR beacons: about 50 s of CPU
def test_past_the_cylinder_the_surround_swarm_stays_connected_at_r_star_and_keeps_its_human(tmp_path: Path) -> None:
    summary = run_scenario(SCENARIOS / "surround-cylinder.toml", 1, tmp_path / "run")
    assert summary["ok"], summary["problems"]
    driving = summary["driving"]
    assert driving["connected_at_end"], driving["connected_fraction"]
    assert driving["connected_fraction"] >= CONNECTED_FRACTION, driving["connected_fraction"]
    assert abs(driving["extent_end_m"] - R_STAR_M) < EXTENT_BOUND_M, driving["extent_end_m"]
    assert driving["centre_to_user_end_m"] < KEEP_UP_M, driving["centre_to_user_end_m"]
