"""The over-the-wire half of ``petswarm bench ir``: real hub and robot processes running the token schedule.

1. *Over the wire*: a master at the centre and receivers around it at the paper's distances and angles
   (heading 0), one sweep per holding (``--ir-slot`` = one sample period) so that each fix is a single
   measurement like the in-process experiment's; every receiver's fixes of the master give the distance
   and direction RMSE through the real hub, radio and estimator.
2. *Token cycle*: for swarms of 2..10 members, how long a full round of the token takes (every member
   shines once) and how often each robot gets a fresh fix of each of the others.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from petswarm import control
from petswarm.bench.hub import HubRun, check_alive, start_hub
from petswarm.lab.processes import Supervisor
from radio_hub.values import HubUnavailable

WIRE_POINTS = [(d, a) for d in (0.4, 1.0, 1.6, 2.0) for a in (0.0, 60.0, 120.0, 180.0)]
"""(distance m, angle deg) of the receivers in the over-the-wire run: a subset of the paper's grid."""
ONE_SWEEP_S = 0.012
"""A holding just over one 10 ms sample period: one sweep per fix."""
STARTUP_TIMEOUT_S = 30.0


def progress(text: str) -> None:
    """Progress on stderr."""
    print(f"[bench ir] {text}", file=sys.stderr, flush=True)


def _start_swarm(
    sup: Supervisor, tag: str, poses: dict[int, tuple[float, float]], seed: int, extra: list[str]
) -> HubRun:
    """A hub and one robot per pose (robot 1 connected to user 1), organized into one swarm."""
    hub = start_hub(sup, f"hub-{tag}", f"bench-ir-{tag}-{seed}", seed, None)
    names = [hub.name]
    for rid, (x, y) in poses.items():
        argv = [
            "robot",
            "--id",
            str(rid),
            "--hub",
            hub.endpoint,
            "--world",
            hub.keys.world,
            f"--pos={x},{y}",
            "--seed",
            str(seed),
            *extra,
            *(["--user", "1"] if rid == 1 else []),
        ]
        names.append(f"robot-{tag}-{rid}")
        sup.spawn(names[-1], argv)
    _wait_serving(sup, hub, list(poses), names)
    wanted = len(poses) - 1
    for _ in range(3):  # with many robots one scan can miss some (their replies collide): ask again
        organized = control.command(hub.session, hub.keys, 1, "organize", 60.0, count=wanted, protocol="slotted")
        if len(organized.get("members", [])) == wanted:
            return hub
        if organized.get("members"):
            control.command(hub.session, hub.keys, 1, "disperse", 60.0)
            time.sleep(0.3)
    raise RuntimeError(f"a swarm of {len(poses)} did not form: {organized}")


def _wait_serving(sup: Supervisor, hub: HubRun, rids: list[int], names: list[str]) -> None:
    deadline = time.monotonic() + STARTUP_TIMEOUT_S
    pending = set(rids)
    while pending and time.monotonic() < deadline:
        check_alive(sup, names)
        for rid in sorted(pending):
            try:
                control.command(hub.session, hub.keys, rid, "status", 1.0)
                pending.discard(rid)
            except HubUnavailable:
                pass
        time.sleep(0.1)
    if pending:
        raise RuntimeError(f"robots {sorted(pending)} did not start")


def _fixes_of(hub: HubRun, rid: int, holder: int) -> list[dict[str, Any]]:
    events = control.command(hub.session, hub.keys, rid, "events", 10.0)["events"]
    return [e for e in events if e["kind"] == "ir_fix" and e["holder"] == holder]


def over_the_wire(sup: Supervisor, seed: int, seconds: float, estimator: str) -> dict[str, Any]:
    """RMSE of the receivers' fixes of the master, through real processes."""
    poses = {1: (0.0, 0.0)}
    for i, (d, a) in enumerate(WIRE_POINTS, start=2):
        poses[i] = (d * math.cos(math.radians(a)), d * math.sin(math.radians(a)))
    progress(f"over the wire: master + {len(WIRE_POINTS)} receivers, {estimator} estimator, {seconds:g} s")
    extra = ["--ir-slot", str(ONE_SWEEP_S), "--ir-estimator", estimator]
    hub = _start_swarm(sup, f"wire-{estimator}", poses, seed, extra)
    time.sleep(seconds)
    dist_err, dir_err = [], []
    for i, (d, a) in enumerate(WIRE_POINTS, start=2):
        for fix in _fixes_of(hub, i, 1):
            dist_err.append((fix["distance_m"] - d) * 100)
            # the receiver at angle a from the master sees the master at a + 180 degrees (heading 0)
            dir_err.append((fix["bearing_deg"] - (a + 180.0) + 180.0) % 360.0 - 180.0)

    overlaps = hub.stats()["ir"]["overlap_episodes"]
    hub.session.close()
    return {
        "estimator": estimator,
        "points": [list(p) for p in WIRE_POINTS],
        "fixes": len(dist_err),
        "distance_rmse_cm": _rmse(dist_err),
        "direction_rmse_deg": _rmse(dir_err),
        "overlap_episodes": overlaps,
    }


def token_cycle(sup: Supervisor, seed: int, members: range, seconds: float) -> list[dict[str, Any]]:
    """Full-round time and per-robot refresh rate for each swarm size."""
    rows = []
    for n in members:
        poses = {
            rid: (0.5 * math.cos(2 * math.pi * rid / n), 0.5 * math.sin(2 * math.pi * rid / n))
            for rid in range(1, n + 1)
        }
        hub = _start_swarm(sup, f"cycle{n}", poses, seed, [])
        time.sleep(1.0)  # the first rounds
        before = _rounds(hub, n)
        t0 = time.monotonic()
        time.sleep(seconds)
        after = _rounds(hub, n)
        elapsed = time.monotonic() - t0
        held = sum(after.values()) - sum(before.values())
        cycle_s = n * elapsed / held if held else float("inf")
        rows.append(
            {
                "members": n,
                "holdings": held,
                "window_s": round(elapsed, 3),
                "cycle_s": round(cycle_s, 4),
                "refresh_hz": round(1.0 / cycle_s, 3) if held else 0.0,
                "overlap_episodes": hub.stats()["ir"]["overlap_episodes"],
            }
        )
        progress(f"token cycle: {n} members, full round {cycle_s * 1000:.0f} ms")
        hub.session.close()
        sup.stop([name for name in sup.children if name.endswith(f"cycle{n}") or f"cycle{n}-" in name])
    return rows


def _rounds(hub: HubRun, n: int) -> dict[int, int]:
    return {rid: control.command(hub.session, hub.keys, rid, "status")["ir"]["rounds_held"] for rid in range(1, n + 1)}


def _rmse(errors: list[float]) -> float | None:
    return round(float(np.sqrt(np.mean(np.square(errors)))), 3) if errors else None


def wire_lines(wire: list[dict[str, Any]], cycle: list[dict[str, Any]]) -> list[str]:
    """The over-the-wire and token-cycle tables."""
    lines = [
        "",
        "over the wire (real hub and robot processes, one sweep per fix)",
        f"{'estimator':<10}{'fixes':>7}{'dist RMSE cm':>14}{'dir RMSE deg':>14}{'overlaps':>10}",
    ]
    for w in wire:
        lines.append(
            f"{w['estimator']:<10}{w['fixes']:>7}{w['distance_rmse_cm']!s:>14}"
            f"{w['direction_rmse_deg']!s:>14}{w['overlap_episodes']:>10}"
        )
    lines += [
        "",
        "token cycle (default slot 0.1 s)",
        f"{'members':>8}{'full round ms':>15}{'refresh Hz':>12}{'holdings':>10}{'overlaps':>10}",
    ]
    for c in cycle:
        lines.append(
            f"{c['members']:>8}{c['cycle_s'] * 1000:>15.0f}{c['refresh_hz']:>12.2f}"
            f"{c['holdings']:>10}{c['overlap_episodes']:>10}"
        )
    return lines


def run_wire_benches(seed: int, out: Path, seconds: float, members: range) -> dict[str, Any]:
    """Both over-the-wire experiments, every process stopped at the end."""
    sup = Supervisor(out / "logs")
    try:
        wire = [over_the_wire(sup, seed, seconds, est) for est in ("paper", "lsq")]
        sup.stop_all()
        cycle = token_cycle(sup, seed, members, seconds)
    finally:
        sup.stop_all()
    return {"wire": wire, "token_cycle": cycle}
