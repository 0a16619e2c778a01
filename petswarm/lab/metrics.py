"""Driving metrics of a run, from the hub's ground truth (``world.jsonl``: one line per world tick).

Pure: lines in, figures out. Formation error is a slave's distance from its reference (its slot, placed
by the master's true pose; the slot is what the slave itself reported); reaction time is from the start
of the user's rotation (the user's true yaw rate leaving zero) to the first turn a robot starts after it:
the first tick after the rotation's start at which the robot's own yaw rate reaches ``REACTION_OMEGA_RPS``
from below. A robot already turning when the user starts (a correction of its own) has not reacted: its
reaction is its next turn, or none within the window. Surround figures are the swarm's extent r and
connectivity.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from radio_hub.values import lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)


REACTION_OMEGA_RPS = 0.3
"""A robot 'moves' in answer to a rotation once it turns at this rate: well above the controllers'
idle corrections (a few hundredths of a rad/s), well below a 60 deg/s user turn."""
USER_TURN_RPS = 0.1
REACTION_WINDOW_S = 5.0
END_TICKS = 50
"""The extent 'at the end' is its mean over the last 50 world ticks (1 s): one tick's r jitters with every push."""


def read_world(path: str | Path) -> list[dict[str, Any]]:
    """The lines of a world log; a torn last line (a killed hub) is skipped."""
    lines = []
    with open(path, encoding="utf-8") as f:
        for line in f:
            try:
                lines.append(json.loads(line))
            except json.JSONDecodeError:
                continue
    return lines


def driving_metrics(world: list[dict[str, Any]], sight_m: float = 1.0) -> dict[str, Any]:
    """Every figure issue 5 asks of a run: formation error, user-master distance, reactions, collisions."""
    if not world:
        return {"ticks": 0}
    errors: dict[str, list[tuple[float, float]]] = {}
    user_master: list[tuple[float, float]] = []
    extents: list[tuple[float, float, bool]] = []
    centre_to_user: list[float] = []
    """How far the swarm's centre is from the user: a surrounding swarm keeps it small."""
    for tick in world:
        t = tick["t_us"] / 1e6
        bodies = {b["id"]: b for b in tick["bodies"]}
        user = next((b for b in tick["bodies"] if b["kind"] == "user"), None)
        for b in tick["bodies"]:
            ref = b.get("reference")
            if b.get("role") == "slave" and ref is not None:
                errors.setdefault(b["id"], []).append((t, math.hypot(b["x"] - ref[0], b["y"] - ref[1])))
            if b.get("role") in ("master", "single") and user is not None:
                user_master.append((t, math.hypot(b["x"] - user["x"], b["y"] - user["y"])))
        robots = np.array([(b["x"], b["y"]) for b in bodies.values() if b["kind"] == "robot"]).reshape(-1, 2)
        if len(robots) > 1:
            extents.append((t, swarm_extent(robots), is_connected(robots, sight_m)))
            if user is not None:
                centre_to_user.append(float(np.hypot(*(robots.mean(axis=0) - (user["x"], user["y"])))))
    return {
        "ticks": len(world),
        "duration_s": round((world[-1]["t_us"] - world[0]["t_us"]) / 1e6, 2),
        "collisions": world[-1].get("collisions", 0),
        "formation_error_m": {node: _percentiles([e for _, e in series]) for node, series in sorted(errors.items())},
        "formation_error_all_m": _percentiles([e for s in errors.values() for _, e in s]),
        "formation_error_series": {node: _thin(series) for node, series in sorted(errors.items())},
        "user_master_distance_m": _percentiles([d for _, d in user_master]),
        "reactions": reactions(world),
        "extent_m": _percentiles([r for _, r, _ in extents]),
        "connected_fraction": round(float(np.mean([c for _, _, c in extents])), 4) if extents else None,
        "connected_at_end": bool(extents[-1][2]) if extents else None,
        "centre_to_user_m": _percentiles(centre_to_user),
        "centre_to_user_end_m": round(centre_to_user[-1], 3) if centre_to_user else None,
        "extent_end_m": round(float(np.mean([r for _, r, _ in extents[-END_TICKS:]])), 4) if extents else None,
    }


def reactions(world: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """For each start of a user rotation: how long until the master and each slave started a turn."""
    out = []
    for t0 in rotation_starts(world):
        roles: dict[str, str] = {}
        first: dict[str, float] = {}
        was_turning: dict[str, bool] = {}
        for tick in world:
            t = tick["t_us"] / 1e6
            if t > t0 + REACTION_WINDOW_S:
                break
            for b in tick["bodies"]:
                if b["kind"] != "robot":
                    continue
                turning = abs(b.get("omega", 0.0)) >= REACTION_OMEGA_RPS
                # a turn counts once it starts after the user's: one under way at t0 is not a reaction to it
                started = turning and was_turning.get(b["id"]) is False
                was_turning[b["id"]] = turning
                if t < t0:
                    continue
                roles.setdefault(b["id"], b.get("role") or "")
                if started and t > t0 and b["id"] not in first:
                    first[b["id"]] = round(t - t0, 3)
        master = next((n for n, r in roles.items() if r in ("master", "single")), None)
        slaves = {n: first.get(n) for n, r in sorted(roles.items()) if r == "slave"}
        master_s = first.get(master) if master else None
        out.append(
            {
                "user_turn_at_s": round(t0, 3),
                "master": master,
                "master_s": master_s,
                "slaves_s": slaves,
                "slave_minus_master_s": {
                    n: round(s - master_s, 3) for n, s in slaves.items() if s is not None and master_s is not None
                },
            }
        )
    return out


def rotation_starts(world: Iterable[dict[str, Any]]) -> list[float]:
    """Model times (s) at which the user's true yaw rate rose above ``USER_TURN_RPS``."""
    starts, turning = [], False
    for tick in world:
        user = next((b for b in tick["bodies"] if b["kind"] == "user"), None)
        if user is None:
            continue
        now_turning = abs(user.get("omega", 0.0)) > USER_TURN_RPS
        if now_turning and not turning:
            starts.append(tick["t_us"] / 1e6)
        turning = now_turning
    return starts


def swarm_extent(positions: np.ndarray) -> float:
    """r = sqrt(mean |p_i - g|^2) (surround paper)."""
    return float(np.sqrt(np.mean(np.sum((positions - positions.mean(axis=0)) ** 2, axis=1))))


def is_connected(positions: np.ndarray, sight_m: float) -> bool:
    """True when the graph of robots closer than ``sight_m`` is connected."""
    near = np.linalg.norm(positions[:, None] - positions[None], axis=2) < sight_m
    reached = np.zeros(len(positions), dtype=bool)
    reached[:1] = True
    # grow the set reached from robot 0 by every neighbour of it at once (a tick's metric, 50 per model second)
    while True:
        grown = reached | near[reached].any(axis=0)
        if (grown == reached).all():
            return bool(reached.all())
        reached = grown


def _percentiles(values: list[float]) -> dict[str, float] | None:
    if not values:
        return None
    a = np.asarray(values)
    return {
        "median": round(float(np.median(a)), 4),
        "p90": round(float(np.percentile(a, 90)), 4),
        "max": round(float(a.max()), 4),
        "n": len(values),
    }


def _thin(series: list[tuple[float, float]], every: int = 5) -> list[list[float]]:
    # 50 Hz is more than a plot needs; keep every 5th sample (10 Hz) for the summary's series
    return [[round(t, 2), round(e, 4)] for t, e in series[::every]]


def describe_driving(driving: dict[str, Any]) -> str:
    """A few lines a person reads after a scenario run."""
    lines = [f"collisions {driving.get('collisions', 0)}"]
    error = driving.get("formation_error_all_m")
    if error:
        lines.append(f"formation error (all slaves): median {error['median']:.3f} m, p90 {error['p90']:.3f} m")
    distance = driving.get("user_master_distance_m")
    if distance:
        lines.append(f"user-master distance: median {distance['median']:.2f} m, p90 {distance['p90']:.2f} m")
    lines += _swarm_shape(driving)
    lines += reaction_table(driving.get("reactions", []))
    return "\n".join(lines)


def _swarm_shape(driving: dict[str, Any]) -> list[str]:
    """The swarm as a whole (a surround run's figures): connected, its centre's distance from the user, r."""
    centre, extent = driving.get("centre_to_user_m"), driving.get("extent_m")
    if not centre or not extent or driving.get("connected_fraction") is None:
        return []
    return [
        f"swarm connected {driving['connected_fraction']:.3f} of the time"
        + (", and at the end" if driving.get("connected_at_end") else ", not at the end"),
        f"swarm centre to user: median {centre['median']:.2f} m, p90 {centre['p90']:.2f} m, "
        f"{driving['centre_to_user_end_m']:.2f} m at the end",
        f"swarm extent r: median {extent['median']:.2f} m, {driving['extent_end_m']:.2f} m at the end",
    ]


def reaction_table(reactions: list[dict[str, Any]]) -> list[str]:
    """One row per user rotation: the master and its reaction, each slave's and (in brackets) its lag
    behind the master; '-' where no turn started within the window."""
    if not reactions:
        return []
    slaves = sorted({n for r in reactions for n in r["slaves_s"]}, key=lambda n: (len(n), n))

    def seconds(value: float | None) -> str:
        return "-" if value is None else f"{value:.2f}"

    def cell(r: dict[str, Any], n: str) -> str:
        gap = r["slave_minus_master_s"].get(n)
        return seconds(r["slaves_s"].get(n)) + ("" if gap is None else f" ({gap:+.2f})")

    rows = [[cell(r, n) for n in slaves] for r in reactions]
    widths = [max(len(n), *(len(row[i]) for row in rows)) + 2 for i, n in enumerate(slaves)]
    lines = [
        f"reaction to the user's turns (s after each rotation starts; slave minus master in brackets; "
        f"-: no turn within {REACTION_WINDOW_S:g} s)",
        f"{'turn at':>8}  {'master':<10}{'master s':>8}  "
        + "".join(f"{n:<{w}}" for n, w in zip(slaves, widths, strict=True)),
    ]
    for r, row in zip(reactions, rows, strict=True):
        lines.append(
            f"{r['user_turn_at_s']:>8.1f}  {r['master'] or '-':<10}{seconds(r['master_s']):>8}  "
            + "".join(f"{c:<{w}}" for c, w in zip(row, widths, strict=True))
        )
    return [line.rstrip() for line in lines]
