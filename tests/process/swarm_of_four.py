"""A swarm of four robot processes for the chaos tests' IR faults: poses, the ground truth, and a wait for token
rounds. (The relative-location tests themselves run in model time: tests/model/test_token.py.)"""

from __future__ import annotations

import math
import time

# master at the origin; three more within IR range, each with its own heading (degrees)
POSES = {1: (0.0, 0.0, 0.0), 2: (1.0, 0.0, 90.0), 3: (0.0, 1.2, 180.0), 4: (1.1, 1.0, -45.0)}
NOISE_FREE_IR = {"relative_noise": 0.0, "noise_floor_counts": 0.0}


def _swarm_of_four(air, *extra: str) -> dict:
    for rid, (x, y, heading) in POSES.items():
        user = ["--user", "1"] if rid == 1 else []
        air.robot(rid, (x, y), 0x1000, 11, f"--heading={heading}", *user, *extra)
    organized = air.cmd(1, "organize", timeout=30, count=3)
    assert organized["members"] == [2, 3, 4], organized
    return organized


def _truth(me: int, other: int) -> tuple[float, float]:
    (x0, y0, h0), (x1, y1, _) = POSES[me], POSES[other]
    bearing = math.degrees(math.atan2(y1 - y0, x1 - x0)) - h0
    return bearing % 360.0, math.hypot(x1 - x0, y1 - y0)


def _angle_gap(a: float, b: float) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


def _wait_for_rounds(air, rounds: int, timeout: float = 20.0) -> dict[int, dict]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        statuses = {rid: air.cmd(rid, "status") for rid in POSES}
        if all(s["ir"]["rounds_held"] >= rounds for s in statuses.values()):
            return statuses
        time.sleep(0.2)
    raise AssertionError({rid: s["ir"] for rid, s in statuses.items()})
