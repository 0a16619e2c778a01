"""Plots of surround runs: the swarm and its human at a few instants (as the paper's Fig. 8), and r(t)
(as its Figs. 7 and 9). Drawn from the hub's ground truth (``world.jsonl`` lines)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from petswarm.lab.surround_metrics import R_STAR_M, WALKING_MPS

SNAPSHOTS = 6
"""Instants per snapshot plot (the paper's Fig. 8 shows 4-6)."""


def is_surround_run(world: list[dict[str, Any]]) -> bool:
    """Whether the robots ran the surround formation: their IR modules were in beacon mode and a user was there."""
    for state in world:
        bodies = state["bodies"]
        if any(b["kind"] == "robot" and b.get("ir") == "beacon" for b in bodies):
            return any(b["kind"] == "user" for b in bodies)
    return False


def snapshot_instants(world: list[dict[str, Any]], count: int = SNAPSHOTS) -> list[int]:
    """Indices of ``count`` states (at least 3): the swarm gathered a second before the human walks, evenly
    through his walk, and the end of the run (without a walk: evenly through the run)."""
    count = max(3, count)
    walking = [i for i, s in enumerate(world) if _user_speed(s) > WALKING_MPS]
    last = len(world) - 1
    if not walking:
        return sorted({round(k * last / (count - 1)) for k in range(count)})
    first, final = walking[0], walking[-1]
    start = _index_at([s["t_us"] for s in world], world[first]["t_us"] - 1_000_000)
    inner = count - 2
    during = [first + round(k * (final - first) / max(1, inner - 1)) for k in range(inner)]
    return sorted({start, *during, last})


def plot_snapshots(world: list[dict[str, Any]], path: Path, title: str = "") -> Path:
    """The robots (discs), the human (a larger disc, with his heading) and the obstacles at a few instants, one
    panel each, all panels on one scale; the swarm's centre is a cross."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle

    instants = snapshot_instants(world)
    fig, axes = plt.subplots(1, len(instants), figsize=(3.2 * len(instants), 3.6), squeeze=False)
    span = plot_span(world, instants)
    for ax, index in zip(axes[0], instants, strict=True):
        state = world[index]
        draw_obstacles(ax, state.get("obstacles", []))
        robots = [b for b in state["bodies"] if b["kind"] == "robot"]
        for b in robots:
            ax.add_patch(Circle((b["x"], b["y"]), b["radius"], facecolor="#4c72b0", edgecolor="k", lw=0.5))
        for b in state["bodies"]:
            if b["kind"] == "user":
                ax.add_patch(Circle((b["x"], b["y"]), b["radius"], facecolor="#c44e52", edgecolor="k", lw=0.8))
                ax.arrow(b["x"], b["y"], 0.4 * math.cos(b["yaw"]), 0.4 * math.sin(b["yaw"]), width=0.02, color="k")
        if robots:
            cx = sum(b["x"] for b in robots) / len(robots)
            cy = sum(b["y"] for b in robots) / len(robots)
            ax.plot(cx, cy, "x", color="k", ms=8)
            cx, cy = swarm_centre(state)
            ax.set_xlim(cx - span, cx + span)
            ax.set_ylim(cy - span, cy + span)
        ax.set_aspect("equal")
        ax.set_title(f"t = {state['t_us'] / 1e6:.1f} s", fontsize=9)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    fig.suptitle(title or "swarm (blue) and human (red); x: swarm centre", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_extent(runs: dict[str, list[dict[str, Any]]], path: Path) -> Path:
    """r(t) of each run, one panel per scenario (``runs``: name -> runs with a ``series`` of [t, r, centre to
    human] and a ``label``), r* dashed, the human's walk shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(runs)
    fig, axes = plt.subplots(len(names), 1, figsize=(8, 2.8 * max(1, len(names))), squeeze=False)
    for ax, name in zip(axes[:, 0], names, strict=True):
        for run in runs[name]:
            t = [row[0] for row in run["series"]]
            r = [row[1] for row in run["series"]]
            ax.plot(t, r, lw=1, label=run["label"], color=run.get("colour"))
        ax.axhline(R_STAR_M, ls="--", color="k", lw=0.8, label="r* 0.65 m")
        ax.axhspan(R_STAR_M * 0.9, R_STAR_M * 1.1, color="k", alpha=0.06)
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("extent r (m)")
        ax.grid(alpha=0.3)
        handles, labels = ax.get_legend_handles_labels()
        unique = dict(zip(labels, handles, strict=True))
        ax.legend(unique.values(), unique.keys(), fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def draw_obstacles(ax: Any, obstacles: list[dict[str, Any]]) -> None:
    from matplotlib.patches import Circle, Rectangle

    for o in obstacles:
        if o["kind"] == "circle":
            ax.add_patch(Circle((o["x"], o["y"]), o["r"], facecolor="#999999", edgecolor="k", lw=0.8))
        elif o["kind"] == "rect":
            size = (o["x1"] - o["x0"], o["y1"] - o["y0"])
            ax.add_patch(Rectangle((o["x0"], o["y0"]), *size, facecolor="#999999", edgecolor="k", lw=0.8))
        else:
            ax.plot([o["x0"], o["x1"]], [o["y0"], o["y1"]], color="k", lw=2)


def plot_span(world: list[dict[str, Any]], instants: list[int]) -> float:
    """Half the side of every panel: enough for the widest instant's swarm and human, at least 2 m."""
    half = 2.0
    for index in instants:
        cx, cy = swarm_centre(world[index])
        for b in world[index]["bodies"]:
            half = max(half, abs(b["x"] - cx) + 0.4, abs(b["y"] - cy) + 0.4)
    return half


def swarm_centre(state: dict[str, Any]) -> tuple[float, float]:
    """Where a panel centres: the human, or the robots' centre without him."""
    user = next((b for b in state["bodies"] if b["kind"] == "user"), None)
    if user is not None:
        return user["x"], user["y"]
    robots = [b for b in state["bodies"] if b["kind"] == "robot"] or state["bodies"]
    return sum(b["x"] for b in robots) / len(robots), sum(b["y"] for b in robots) / len(robots)


def _user_speed(state: dict[str, Any]) -> float:
    user = next((b for b in state["bodies"] if b["kind"] == "user"), None)
    return 0.0 if user is None else math.hypot(user["vx"], user["vy"])


def _index_at(times: list[int], t_us: int) -> int:
    return next((i for i, t in enumerate(times) if t >= t_us), 0)
