"""IR relative location over the token schedule, with real hub and robot processes."""

from __future__ import annotations

import math
import time

import pytest

from .conftest import LOSSLESS

pytestmark = pytest.mark.process
NOISE_FREE_IR = {"relative_noise": 0.0, "noise_floor_counts": 0.0}
# master at the origin; three more within IR range, each with its own heading (degrees)
POSES = {1: (0.0, 0.0, 0.0), 2: (1.0, 0.0, 90.0), 3: (0.0, 1.2, 180.0), 4: (1.1, 1.0, -45.0)}


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


def _check_fixes(statuses: dict[int, dict], max_cm: float, max_deg: float, heading_deg: float = 0.01) -> None:
    """``heading_deg``: the heading exchange carries each robot's AHRS yaw, exact only with the AHRS noise off."""
    for rid, status in statuses.items():
        table = status["relative_location"]
        for neighbour in status["swarm"]["neighbours"]:
            fix = table[str(neighbour)]
            bearing, distance = _truth(rid, neighbour)
            assert abs(fix["distance_m"] - distance) * 100 <= max_cm, (rid, neighbour, fix, distance)
            assert _angle_gap(fix["bearing_deg"], bearing) <= max_deg, (rid, neighbour, fix, bearing)
            assert _angle_gap(fix["heading_deg"], POSES[neighbour][2]) <= heading_deg  # heading exchange


def test_noise_free_fixes_are_within_1_cm_and_1_degree_after_two_rounds(make_air):
    air = make_air({**LOSSLESS, "ir": NOISE_FREE_IR, "world": {"yaw_noise_deg": 0.0}})
    _swarm_of_four(air)
    statuses = _wait_for_rounds(air, 2)
    _check_fixes(statuses, max_cm=1.0, max_deg=1.0)
    ir = air.stats()["ir"]
    assert ir["overlap_episodes"] == 0 and ir["sweeps"] > 0


def test_default_noise_fixes_are_within_documented_bounds(make_air):
    air = make_air()
    _swarm_of_four(air)
    # bounds: ten sweeps averaged at 1.0-1.5 m; the bench's per-sweep RMSE there is 1-2.3 cm and 1-1.7 deg
    # headings: the world's AHRS has 1 degree of noise (WorldConfig.yaw_noise_deg): 4 sigma
    _check_fixes(_wait_for_rounds(air, 2), max_cm=5.0, max_deg=4.0, heading_deg=4.0)
    assert air.stats()["ir"]["overlap_episodes"] == 0


def test_with_20_percent_loss_the_schedule_keeps_cycling_without_overlap(make_air):
    air = make_air({**LOSSLESS, "loss": {"base": 0.2}}, seed=7)
    _swarm_of_four(air)
    first = {rid: s["ir"]["round"] for rid, s in _wait_for_rounds(air, 1, timeout=30).items()}
    time.sleep(3.0)
    later = {rid: air.cmd(rid, "status")["ir"]["round"] for rid in POSES}
    assert max(later.values()) >= max(first.values()) + 4  # still cycling
    assert air.stats()["ir"]["overlap_episodes"] == 0


def test_killing_the_token_holder_the_schedule_resumes_among_the_survivors(make_air):
    air = make_air()
    _swarm_of_four(air)
    _wait_for_rounds(air, 1)
    victim = None
    deadline = time.monotonic() + 10
    while victim is None and time.monotonic() < deadline:
        transmitting = air.stats()["ir"]["transmitting"]
        victim = next((int(n.split("-")[1]) for n in transmitting if n != "robot-1"), None)
    assert victim is not None, "no slave was ever seen holding the token"
    air.sup.children[f"robot-{victim}"].kill()
    killed_at = time.monotonic()
    survivors = [rid for rid in POSES if rid != victim]
    held = {rid: air.cmd(rid, "status")["ir"]["rounds_held"] for rid in survivors}
    regen = 1.5  # TokenConfig.regen_timeout_s
    while time.monotonic() - killed_at < regen + 5:
        now = {rid: air.cmd(rid, "status")["ir"]["rounds_held"] for rid in survivors}
        if all(now[rid] > held[rid] for rid in survivors):
            break
        time.sleep(0.2)
    assert all(now[rid] > held[rid] for rid in survivors), (held, now)  # every survivor shone again
    assert time.monotonic() - killed_at < regen + 5
    assert air.stats()["ir"]["overlap_episodes"] == 0
