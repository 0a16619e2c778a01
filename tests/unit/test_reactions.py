"""Reaction times to the user's rotations, from the ground truth (petswarm/lab/metrics.py), and how they are printed."""

from __future__ import annotations

from typing import Any

import pytest

from petswarm.lab.metrics import describe_driving, reactions

USER_TURNS_AT = 1.0


def _world(omegas: dict[str, list[tuple[float, float]]]) -> list[dict[str, Any]]:
    """Ticks every 20 ms for 4 s; the user turns from 1.0 s; each robot's yaw rate steps at the given times."""
    ticks = []
    for k in range(200):
        t = round(k * 0.02, 3)
        bodies = [{"id": "user", "kind": "user", "x": 0, "y": 0, "omega": 0.8 if t >= USER_TURNS_AT else 0.0}]
        for rid, steps in omegas.items():
            omega = next((w for since, w in reversed(steps) if t >= since), 0.0)
            role = "master" if rid == "robot-1" else "slave"
            bodies.append({"id": rid, "kind": "robot", "x": 0, "y": 0, "omega": omega, "role": role})
        ticks.append({"t_us": int(t * 1e6), "bodies": bodies})
    return ticks


def test_a_slave_already_turning_when_the_user_starts_reacts_when_it_next_starts_turning() -> None:
    world = _world(
        {
            "robot-1": [(1.3, 0.8)],  # the master starts turning 0.3 s after the user
            "robot-2": [(0.5, 0.5), (1.2, 0.0), (1.6, 0.8)],  # correcting before the turn, stops, then reacts
            "robot-3": [(1.5, 0.8)],
            "robot-4": [(0.5, 0.5)],  # turning all along: no turn starts after the user's, so no reaction
        }
    )
    [reaction] = reactions(world)
    assert reaction["user_turn_at_s"] == pytest.approx(USER_TURNS_AT)
    assert reaction["master"] == "robot-1" and reaction["master_s"] == pytest.approx(0.3)
    assert reaction["slaves_s"] == pytest.approx({"robot-2": 0.6, "robot-3": 0.5, "robot-4": None})
    assert reaction["slave_minus_master_s"] == pytest.approx({"robot-2": 0.3, "robot-3": 0.2})


def test_reactions_print_as_a_table() -> None:
    world = _world({"robot-1": [(1.3, 0.8)], "robot-2": [(1.6, 0.8)], "robot-3": [(0.5, 0.5)]})
    text = describe_driving({"collisions": 0, "reactions": reactions(world)})
    assert "{" not in text and "[" not in text, text  # no Python dicts or lists
    lines = text.splitlines()
    header = next(line for line in lines if "robot-2" in line and "robot-3" in line)
    assert "master" in header and "turn at" in header
    row = lines[lines.index(header) + 1]
    assert row.split() == ["1.0", "robot-1", "0.30", "0.60", "(+0.30)", "-"], row
