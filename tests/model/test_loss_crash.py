"""A following swarm under heavy frame loss: a member that missed every roster still drives without raising.

Under 30 % loss a member can hear its JoinNotice and the master's DriveState before any roster: it knows its
member number but not the others' addresses, and its controller indexed the formation's layout past the chain
it knew (``IndexError`` in ``DriverCore._slave``, the robot's control loop dead and the run failed). These are
the three seeds of following-turn with ``[[faults]] at = 4, kind = "loss", p = 0.3`` that crashed, in model
time, whole (the checker holds every robot to end waiting or with its user, after the dispersal at 42 s).
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from petswarm.scenario import parse

from .harness import SCENARIOS, record_events, run_scenario

pytestmark = pytest.mark.long


def _lossy_following_turn() -> object:
    data = tomllib.loads((SCENARIOS / "following-turn.toml").read_text())
    data["faults"] = [{"at": 4, "kind": "loss", "p": 0.3}]
    return parse(data)


@pytest.mark.timeout(300)
@pytest.mark.parametrize("seed", [5, 6, 7])
def test_a_member_that_missed_the_roster_holds_still_instead_of_crashing(tmp_path: Path, seed: int) -> None:
    record = tmp_path / "run"
    summary = run_scenario(_lossy_following_turn(), seed, record)
    assert summary["ok"], summary["problems"]
    assert summary["invariants"] == "all hold"
    for rid in (2, 3, 4):  # every member's controller ran to the end: its record closes with the stop event
        assert record_events(record, f"robot-{rid}")[-1]["kind"] == "stop"
