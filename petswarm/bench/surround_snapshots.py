"""The safe law's snapshot plot: the swarm, its human and the obstacles at a few instants, each robot's active
safety constraints drawn as a line from the robot to what it keeps off (a neighbour, the human, an obstacle point).

One model-time run of a scenario under the safe law; while it runs, ``SurroundTask.observer`` reads every robot's
``SafeSurroundController.active`` (its own frame) after each step, and the plot puts them in the world with the
robot's pose from the hub's ground truth at that instant (the law never turns the robot, so its frame is its body
frame). Reading the pilots changes nothing in the run (its digest is the run's without the observer).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from petswarm.controllers.surround_driver import SurroundDriver
    from petswarm.scenario import Scenario

KIND_COLOURS = {"neighbour": "#4c72b0", "human": "#c44e52", "obstacle": "#222222"}
"""The colour of an active constraint's line by what it keeps the robot off."""


def record_active(scenario: Scenario, seed: int) -> tuple[list[dict[str, Any]], dict[int, dict[str, list]], str]:
    """Run ``scenario`` under the safe law in model time: its world states, each step's active constraints per
    robot (model microseconds -> node id -> [(kind, x, y)] in the robot's frame), and its digest."""
    from petswarm.bench.surround_runs import scenario_run, with_law
    from petswarm.controllers.surround_driver import SurroundTask
    from petswarm.controllers.surround_safe import SafeSurroundController

    active: dict[int, dict[str, list]] = {}

    def observe(now: float, drivers: list[SurroundDriver]) -> None:
        step: dict[str, list] = {}
        for driver in drivers:
            controller = driver.pilot.controller
            if isinstance(controller, SafeSurroundController) and controller.active:
                step[driver.radio.identity.node_id] = list(controller.active)
        active[round(now * 1e6)] = step

    SurroundTask.observer = observe
    try:
        world, run = scenario_run(with_law(scenario, "safe"), seed, "model")
    finally:
        SurroundTask.observer = None
    return world, active, run.get("digest") or ""


def plot_active(world: list[dict[str, Any]], active: dict[int, dict[str, list]], path: Path, title: str = "") -> Path:
    """Snapshots (``surround_plots.snapshot_instants``) with each robot's active constraints at the last step at or
    before each instant, coloured by kind (``KIND_COLOURS``)."""
    import bisect

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle

    from petswarm.lab.surround_plots import draw_obstacles, plot_span, snapshot_instants, swarm_centre

    instants = snapshot_instants(world)
    times = sorted(active)
    fig, axes = plt.subplots(1, len(instants), figsize=(3.4 * len(instants), 3.9), squeeze=False)
    span = plot_span(world, instants)
    for ax, index in zip(axes[0], instants, strict=True):
        state = world[index]
        draw_obstacles(ax, state.get("obstacles", []))
        at = bisect.bisect_right(times, state["t_us"]) - 1
        step = active[times[at]] if at >= 0 else {}
        count = 0
        for b in state["bodies"]:
            if b["kind"] == "robot":
                ax.add_patch(Circle((b["x"], b["y"]), b["radius"], facecolor="#9fb7d9", edgecolor="k", lw=0.5))
                c, s = math.cos(b["yaw"]), math.sin(b["yaw"])
                for kind, x, y in step.get(b["id"], []):
                    wx, wy = b["x"] + c * x - s * y, b["y"] + s * x + c * y
                    ax.plot([b["x"], wx], [b["y"], wy], color=KIND_COLOURS[kind], lw=1.2)
                    count += 1
            elif b["kind"] == "user":
                ax.add_patch(Circle((b["x"], b["y"]), b["radius"], facecolor="#c44e52", edgecolor="k", lw=0.8))
        cx, cy = swarm_centre(state)
        ax.set_xlim(cx - span, cx + span)
        ax.set_ylim(cy - span, cy + span)
        ax.set_aspect("equal")
        ax.set_title(f"t = {state['t_us'] / 1e6:.1f} s, {count} active", fontsize=9)
        ax.grid(alpha=0.3)
    handles = [Line2D([], [], color=colour, lw=1.5, label=kind) for kind, colour in KIND_COLOURS.items()]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=8)
    fig.suptitle(title or "safe law: active safety constraints (robot -> what it keeps off)", fontsize=10)
    fig.tight_layout(rect=(0, 0.06, 1, 0.95))
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
