"""Surround figures of a run, from the hub's ground truth (``world.jsonl``, one line per 50 Hz world tick).

Pure: lines in, figures out. What the surround paper claims (no collisions, the swarm connected, r back at r*
after each obstacle) and what issue 17 asks beyond it (the human inside the swarm while he walks):

- contacts by kind. The world counts a contact when two bodies (or a body and an obstacle) start to overlap
  and then pushes them apart until they touch; the lines carry only the running count, so each new contact is
  put down to the pairs touching (gap under ``TOUCH_M``) at the tick the count rose, nearest first; one left
  unexplained is counted as ``unattributed`` (still a contact).
- the connected share of the ticks (robots closer than the sight S linked);
- the swarm centre's distance from the human while he walks (faster than ``WALKING_MPS``): median and p90;
- the share of robots ahead of him (past him along his heading) while he walks;
- r over the last second (its mean) against r*;
- the obstacle pass: when the human reached the obstacles' near edge and left their far edge, and when the
  last robot left it (along his walk, from his first position to his last).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from radio_hub.values import lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

R_STAR_M = 0.65
"""The extent the paper's 20 robots settle to under local forces alone (spec; the law's gains reproduce it)."""
WALKING_MPS = 0.5
"""The human 'walks' faster than this (he speeds up to 1 m/s over 3 s)."""
TOUCH_M = 0.002
"""Two bodies this close after the world's settling are touching (poses are logged to 0.1 mm)."""
SIGHT_M = 1.0
END_S = 1.0
"""r 'at the end' is its mean over the last second (one tick's r jitters with every push)."""
CONNECTED_AT_LEAST = 0.99
"""Issue 17's bounds on a surround run: connected at least this share of the time, ..."""
INSIDE_MEDIAN_M = 0.5
"""... the swarm centre at most this far from the walking human at the median, ..."""
EXTENT_OFF_AT_MOST = 0.10
"""... r at the end within this share of r*, and no contact of any kind."""
BOUNDS = ("no_contact", "connected", "inside", "r_end")


def surround_metrics(world: list[dict[str, Any]], sight_m: float = SIGHT_M) -> dict[str, Any]:
    """Every figure of a surround run (see the module's docstring), and r(t) and centre-to-human at 2 Hz."""
    ticks = [_tick(state) for state in world if any(b["kind"] == "robot" for b in state["bodies"])]
    if not ticks:
        return {"ticks": 0}
    walking = [t for t in ticks if t["user"] is not None and t["user_speed"] > WALKING_MPS]
    centre = [float(np.hypot(*(t["robots"].mean(axis=0) - t["user"]))) for t in walking]
    end = ticks[-1]["t"]
    last = [t for t in ticks if t["t"] > end - END_S]
    r_end = float(np.mean([_extent(t["robots"]) for t in last]))
    return {
        "ticks": len(ticks),
        "contacts": contacts(world),
        "connected_fraction": round(float(np.mean([_connected(t["robots"], sight_m) for t in ticks])), 4),
        "centre_to_human_walking_m": _percentiles(centre),
        "ahead_while_walking": round(float(np.mean([_ahead(t) for t in walking])), 3) if walking else None,
        "r_end_m": round(r_end, 4),
        "r_star_m": R_STAR_M,
        "r_end_off": round(abs(r_end - R_STAR_M) / R_STAR_M, 4),
        "centre_to_human_end_m": _centre_to_human(ticks[-1]),
        "obstacle_pass": obstacle_pass(world, ticks),
        "series": [[round(t["t"], 2), round(_extent(t["robots"]), 4), _centre_to_human(t)] for t in ticks[::25]],
    }


def bounds_met(figures: dict[str, Any]) -> dict[str, bool]:
    """Which of issue 17's four bounds a run's ``surround_metrics`` figures meet (``BOUNDS``), and ``all``."""
    centre = figures.get("centre_to_human_walking_m") or {}
    met = {
        "no_contact": figures.get("contacts", {}).get("total", 1) == 0,
        "connected": figures.get("connected_fraction", 0.0) >= CONNECTED_AT_LEAST,
        "inside": centre.get("median", math.inf) <= INSIDE_MEDIAN_M,
        "r_end": figures.get("r_end_off", math.inf) <= EXTENT_OFF_AT_MOST,
    }
    return {**met, "all": all(met.values())}


def contacts(world: list[dict[str, Any]]) -> dict[str, int]:
    """New contacts over the run by kind: robot-robot, robot-obstacle, robot-human, and unattributed."""
    counts = {"robot_robot": 0, "robot_obstacle": 0, "robot_human": 0, "unattributed": 0}
    before = 0
    for state in world:
        now = int(state.get("collisions", 0))
        if now > before:
            kinds = _touching(state)
            new = now - before
            for kind in kinds[:new]:
                counts[kind] += 1
            counts["unattributed"] += max(0, new - len(kinds))
        before = now
    counts["total"] = sum(counts.values())
    return counts


def obstacle_pass(world: list[dict[str, Any]], ticks: list[dict[str, Any]] | None = None) -> dict[str, Any] | None:
    """When the human reached the obstacles and left them, and when the last robot left them (model s); the
    time to pass is from the human reaching them to the last robot leaving them (None: not within the run)."""
    ticks = ticks if ticks is not None else [_tick(s) for s in world if s["bodies"]]
    path = [t["user"] for t in ticks if t["user"] is not None]
    obstacles = world[-1].get("obstacles", []) if world else []
    if len(path) < 2 or not obstacles:
        return None
    axis = path[-1] - path[0]
    if not np.hypot(*axis) > 0:
        return None
    axis = axis / np.hypot(*axis)
    near, far = _span(obstacles, axis)
    reached = next((t["t"] for t in ticks if t["user"] is not None and t["user"] @ axis >= near), None)
    human_past = next((t["t"] for t in ticks if t["user"] is not None and t["user"] @ axis > far), None)
    swarm_past = next((t["t"] for t in ticks if (t["robots"] @ axis).min() > far), None)
    return {
        "human_reached_s": _round(reached),
        "human_past_s": _round(human_past),
        "swarm_past_s": _round(swarm_past),
        "time_to_pass_s": _round(None if reached is None or swarm_past is None else swarm_past - reached),
        "lag_s": _round(None if human_past is None or swarm_past is None else swarm_past - human_past),
    }


def _span(obstacles: list[dict[str, Any]], axis: np.ndarray) -> tuple[float, float]:
    """The obstacles' extent along ``axis``: nearest and farthest (a robot past ``far`` has left them)."""
    along: list[float] = []
    for o in obstacles:
        if o["kind"] == "circle":
            centre = float(np.array([o["x"], o["y"]]) @ axis)
            along += [centre - o["r"], centre + o["r"]]
        else:
            along += [float(np.array([o["x0"], o["y0"]]) @ axis), float(np.array([o["x1"], o["y1"]]) @ axis)]
    return min(along), max(along)


def _touching(state: dict[str, Any]) -> list[str]:
    """The kinds of the pairs touching in this state, nearest first."""
    bodies = state["bodies"]
    found: list[tuple[float, str]] = []
    for i, a in enumerate(bodies):
        if a["kind"] != "robot":
            continue
        for b in bodies:
            if b is a or (b["kind"] == "robot" and bodies.index(b) < i):
                continue
            gap = math.hypot(a["x"] - b["x"], a["y"] - b["y"]) - a["radius"] - b["radius"]
            if gap < TOUCH_M:
                found.append((gap, "robot_robot" if b["kind"] == "robot" else "robot_human"))
        for o in state.get("obstacles", []):
            gap = _obstacle_gap(a, o)
            if gap < TOUCH_M:
                found.append((gap, "robot_obstacle"))
    return [kind for _, kind in sorted(found)]


def _obstacle_gap(body: dict[str, Any], o: dict[str, Any]) -> float:
    """The gap between a body's surface and an obstacle (circle, wall or rectangle)."""
    x, y, r = body["x"], body["y"], body["radius"]
    if o["kind"] == "circle":
        return math.hypot(x - o["x"], y - o["y"]) - o["r"] - r
    if o["kind"] == "rect":
        dx = max(o["x0"] - x, 0.0, x - o["x1"])
        dy = max(o["y0"] - y, 0.0, y - o["y1"])
        return math.hypot(dx, dy) - r
    ax, ay, bx, by = o["x0"], o["y0"], o["x1"], o["y1"]
    ex, ey = bx - ax, by - ay
    length2 = ex * ex + ey * ey
    u = 0.0 if length2 <= 0 else min(1.0, max(0.0, ((x - ax) * ex + (y - ay) * ey) / length2))
    return math.hypot(x - ax - u * ex, y - ay - u * ey) - r


def _tick(state: dict[str, Any]) -> dict[str, Any]:
    user = next((b for b in state["bodies"] if b["kind"] == "user"), None)
    robots = np.array([(b["x"], b["y"]) for b in state["bodies"] if b["kind"] == "robot"], dtype=float)
    return {
        "t": state["t_us"] / 1e6,
        "robots": robots.reshape(-1, 2),
        "user": None if user is None else np.array([user["x"], user["y"]]),
        "user_speed": 0.0 if user is None else math.hypot(user["vx"], user["vy"]),
        "user_yaw": 0.0 if user is None else user["yaw"],
    }


def _ahead(tick: dict[str, Any]) -> float:
    heading = np.array([math.cos(tick["user_yaw"]), math.sin(tick["user_yaw"])])
    return float(np.mean((tick["robots"] - tick["user"]) @ heading > 0))


def _centre_to_human(tick: dict[str, Any]) -> float | None:
    if tick["user"] is None:
        return None
    return round(float(np.hypot(*(tick["robots"].mean(axis=0) - tick["user"]))), 4)


def _extent(positions: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((positions - positions.mean(axis=0)) ** 2, axis=1))))


def _connected(positions: np.ndarray, sight_m: float) -> bool:
    near = np.linalg.norm(positions[:, None] - positions[None], axis=2) < sight_m
    reached = np.zeros(len(positions), dtype=bool)
    reached[0] = True
    while True:
        grown = reached | near[reached].any(axis=0)
        if grown.sum() == reached.sum():
            return bool(reached.all())
        reached = grown


def _percentiles(values: list[float]) -> dict[str, float] | None:
    if not values:
        return None
    a = np.asarray(values)
    return {"median": round(float(np.median(a)), 4), "p90": round(float(np.percentile(a, 90)), 4), "n": len(values)}


def _round(value: float | None) -> float | None:
    return None if value is None else round(value, 2)
