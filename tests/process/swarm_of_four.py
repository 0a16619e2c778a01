"""A swarm of four robot processes for the chaos tests' IR faults: poses, the ground truth, and a wait for token
rounds. (The relative-location tests themselves run in model time: tests/model/test_token.py.)"""

from __future__ import annotations

import math
import time
import warnings
from typing import TYPE_CHECKING

from ..waiting import wait_for

if TYPE_CHECKING:
    from .conftest import Air

# master at the origin; three more within IR range, each with its own heading (degrees)
POSES = {1: (0.0, 0.0, 0.0), 2: (1.0, 0.0, 90.0), 3: (0.0, 1.2, 180.0), 4: (1.1, 1.0, -45.0)}
NOISE_FREE_IR = {"relative_noise": 0.0, "noise_floor_counts": 0.0}


def _swarm_of_four(air, *extra: str) -> dict:
    for rid, (x, y, heading) in POSES.items():
        user = ["--user", "1"] if rid == 1 else []
        air.robot(rid, (x, y), 0x1000, 11, f"--heading={heading}", *user, *extra)
    return organize_all(air)


def organize_all(air: Air) -> dict:
    """Robot 1 organizes robots 2-4: the starting point of the chaos tests, not what they test.

    Organization is asserted in model time and lockstep (tests/model/test_formation*.py, test_lockstep.py),
    where the machine's load cannot touch it. On the wall clock a robot starved of CPU misses a step's
    deadline as a real one would, and is left out; the user then disperses and asks again, up to three times."""
    organized: dict = {}
    for _ in range(3):
        organized = air.cmd(1, "organize", timeout=30, count=3)
        if organized["members"] == [2, 3, 4]:
            return organized
        # said in the run's warnings summary, so that robots left out more and more often show in CI
        warnings.warn(
            f"wall clock: robot 1 organized {organized['members']}; dispersing and asking again", stacklevel=2
        )
        air.cmd(1, "disperse", timeout=30)
        wait_for("robots 2-4 home after the disperse", lambda: _home(air), 10, every=0.2)
    raise AssertionError(f"robot 1 organized {organized['members']} three times, not [2, 3, 4]")


def _home(air: Air) -> bool:
    statuses = [air.cmd(rid, "status") for rid in (2, 3, 4)]
    return all(s["state"] == "waiting" and s["radio"]["pan_id"] == 0x1000 for s in statuses)


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
