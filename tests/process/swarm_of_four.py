"""A swarm of four robot processes for the chaos tests: their poses, and organizing them.
(The relative-location tests themselves run in model time: tests/model/test_token.py.)"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING

from ..waiting import wait_for

if TYPE_CHECKING:
    from .conftest import Air

# master at the origin; three more within IR range, each with its own heading (degrees)
POSES = {1: (0.0, 0.0, 0.0), 2: (1.0, 0.0, 90.0), 3: (0.0, 1.2, 180.0), 4: (1.1, 1.0, -45.0)}


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
