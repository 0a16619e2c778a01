"""A change between following and leading turns the robot round in whatever state the user asks for it.

Following, a robot faces its user; leading, it faces away from him (LF cannot tell front from back, so the mode is
what says where the user is). A robot turned round only when the change came while it drove: the user who
cancelled (command-waiting), turned about and chose leading had a robot still facing him that took him for the
user behind it. It saw him as an obstacle ahead and handed over to remote control, and never led. (Found
reading ``petswarm explore --seed 1 --family drive,mixed`` case 74, where a mode change came in remote control
and the turn it started waited for the next choice.) Now the first choice after pairing turns nothing (the robot
stands as the user placed it) and every later change of side is a turn-about.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from petswarm.scenario import parse

from .harness import record_events, run_scenario

pytestmark = pytest.mark.long

CANCEL_THEN_LEAD = {
    "name": "cancel-then-lead",
    "description": "one robot following; the user cancels, turns about and chooses leading",
    "duration_s": 24.0,
    "user": {
        "owner": 1,
        "start": [0.0, 0.0, 90.0],
        "walk_at": 3.0,
        "path": [
            {"walk": 2.0, "speed": 0.6},
            {"stop": 1.17},
            {"turn": 180, "rate": 60},
            {"stop": 3.1},
            {"walk": 3.0, "speed": 0.5},
            {"stop": 3.0},
        ],
        "watch": [
            {"at": 1.0, "request": "follow"},
            {"at": 7.0, "request": "cancel"},
            {"at": 10.55, "request": "lead"},
        ],
    },
    "robots": {"count": 1, "positions": [[0.0, -0.9, 90.0]]},
}


@pytest.mark.timeout(120)
@pytest.mark.parametrize("seed", [3, 4])
def test_choosing_leading_after_a_cancel_and_a_turn_about_turns_the_robot_round(tmp_path: Path, seed: int) -> None:
    record = tmp_path / "run"
    summary = run_scenario(parse(CANCEL_THEN_LEAD), seed, record)
    assert summary["invariants"] == "all hold"
    events = record_events(record, "robot-1")
    assert [e["to"] for e in events if e["kind"] == "state"][-2:] == ["command-waiting", "leading"]
    assert any(e["kind"] == "turn_about_done" for e in events)
    last = json.loads((record / "world.jsonl").read_text().splitlines()[-1])
    bodies = {b["id"]: b for b in last["bodies"]}
    robot, user = bodies["robot-1"], bodies["user"]
    # the user walked south: the robot leads him, ahead (further south), about a metre off
    assert robot["y"] < user["y"] - 0.5
    assert 0.5 < ((robot["x"] - user["x"]) ** 2 + (robot["y"] - user["y"]) ** 2) ** 0.5 < 2.0
