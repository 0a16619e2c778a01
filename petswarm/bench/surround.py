"""``petswarm bench surround``: the surround scenarios in model time, through each robot's own pipeline.

Each run is a ``petswarm run SCENARIO --clock model`` (``petswarm.lab.model_run``): the hub's own environment on its
one schedule (world ticks, body sensors, IR beacons) and every robot and the user as the objects their
processes run, on model time. It is deterministic per seed and independent of the machine's load; a process
run of the same scenario (``--clock wall``) differs only by the processes' scheduling.

Figures per run come from the same ``petswarm.lab.metrics.driving_metrics`` as a process run's, over the world's
ground truth at 10 Hz; the plot draws how far each run's swarm centre is from its human over time.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

from petswarm.bench.output import emit, save
from petswarm.lab.metrics import driving_metrics, read_world
from radio_hub.interface import lazy_numpy

if TYPE_CHECKING:
    import numpy as np

    from petswarm.scenario import Scenario
else:
    np = lazy_numpy(__name__)

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
DEFAULT_SCENARIOS = [str(SCENARIOS / "surround-cylinder.toml"), str(SCENARIOS / "surround-corridor.toml")]
RECORD_EVERY = 5
"""World ticks (50 Hz) between the states the figures use (10 Hz)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The bench's options."""
    from petswarm.lab.arguments import bounded, seed

    parser.add_argument(
        "scenarios", nargs="*", default=DEFAULT_SCENARIOS, help="surround scenario files (default: cylinder, corridor)"
    )
    parser.add_argument("--seeds", type=bounded(int, 1, 1000), default=3, help="runs per scenario (default 3)")
    parser.add_argument("--seed", type=seed, default=1, help="seed of the first run (default %(default)s)")
    parser.add_argument("--out", default="bench-results", help="directory for JSON and plots (default %(default)s)")
    parser.add_argument(
        "--paper",
        action="store_true",
        help="also the pure simulation of the paper's setups (exact sensing, no hub): r* from both lattices, "
        "thin- and solid-walled corridor and cylinder, each also with noisy sensing",
    )
    parser.add_argument("--json", action="store_true", help="print the results as JSON on stdout")


def bench_surround(args: argparse.Namespace) -> int:
    """Run every scenario for ``--seeds`` seeds in model time; print, save JSON and the plot."""
    # imported here, not at load: building the CLI's parser imports this module in every process,
    # robots too, and these bring the hub's side and numpy (issue 13)
    from petswarm.bench.surround_sim import surround_figures
    from petswarm.scenario import load

    results: dict[str, Any] = {"first_seed": args.seed, "runs": {}}
    try:  # every file is read before the long runs start
        scenarios = [load(path) for path in args.scenarios]
    except ValueError as err:
        print(f"petswarm bench surround: {err}", file=sys.stderr)
        return 2
    for path, scenario in zip(args.scenarios, scenarios, strict=True):
        if not scenario.surround_enabled:
            print(f"petswarm bench surround: {path} is not a surround scenario ([surround] enabled)", file=sys.stderr)
            return 2
    for scenario in scenarios:
        runs = []
        for seed in range(args.seed, args.seed + args.seeds):
            print(f"[bench surround] {scenario.name} seed {seed}", file=sys.stderr)
            world = model_time_run(scenario, seed)
            runs.append({"seed": seed, **summarise(world)})
        results["runs"][scenario.name] = runs
    if args.paper:
        print("[bench surround] the paper's setups, pure simulation", file=sys.stderr)
        results["pure_simulation"] = surround_figures(args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    save(results, out, "bench_surround", plot)
    emit(table(results), results, args.json)
    return 0


def model_time_run(scenario: Scenario, seed: int, record_dir: str | Path | None = None) -> list[dict[str, Any]]:
    """One ``--clock model`` run of ``scenario``: the world's states at 10 Hz, from the run's world.jsonl."""
    from petswarm.lab.model_run import execute  # the hub's side: see bench_surround
    from petswarm.lab.run import RunOptions

    if scenario.user is None:
        raise ValueError(f"scenario {scenario.name!r} has no user to surround")
    with tempfile.TemporaryDirectory(prefix="bench-surround-") as scratch:
        record = Path(record_dir or scratch) / f"{scenario.name}-{seed}"
        opts = RunOptions(
            robots=scenario.robot_count,
            seed=seed,
            duration=scenario.duration_s,
            ping_interval=0.5,
            record_dir=str(record),
            scenario=str(scenario.path),
            clock="model",
        )
        execute(opts, scenario)
        return read_world(record / "world.jsonl")[RECORD_EVERY - 1 :: RECORD_EVERY]


def summarise(world: list[dict[str, Any]]) -> dict[str, Any]:
    """A run's surround figures, and its centre-to-human distance over time (for the plot)."""
    figures = driving_metrics(world)
    series = []
    for state in world[::5]:  # 2 Hz is plenty for the plot, and keeps the JSON readable
        user = next(b for b in state["bodies"] if b["kind"] == "user")
        robots = np.array([(b["x"], b["y"]) for b in state["bodies"] if b["kind"] == "robot"])
        series.append(
            [round(state["t_us"] / 1e6, 2), round(float(np.hypot(*(robots.mean(axis=0) - (user["x"], user["y"])))), 3)]
        )
    keys = ("collisions", "connected_fraction", "centre_to_user_m", "centre_to_user_end_m", "extent_end_m")
    ahead = _ahead_while_walking(world)
    return {**{k: figures[k] for k in keys}, "ahead_while_walking": ahead, "centre_to_user_series": series}


def _ahead_while_walking(world: list[dict[str, Any]]) -> float | None:
    """The mean fraction of robots ahead of the human (past him along his heading) while he walks faster than
    0.5 m/s: a swarm that surrounds him keeps some ahead; one that trails him as a tail keeps none."""
    fractions = []
    for state in world:
        user = next(b for b in state["bodies"] if b["kind"] == "user")
        if math.hypot(user["vx"], user["vy"]) < 0.5:
            continue
        heading = np.array([math.cos(user["yaw"]), math.sin(user["yaw"])])
        robots = np.array([(b["x"], b["y"]) for b in state["bodies"] if b["kind"] == "robot"])
        fractions.append(float(np.mean((robots - (user["x"], user["y"])) @ heading > 0)))
    return round(float(np.mean(fractions)), 3) if fractions else None


def table(results: dict[str, Any]) -> list[str]:
    """One line per run."""
    head = f"{'scenario':20s} {'seed':>4s} {'contacts':>8s} {'connected':>9s} {'centre-human median':>19s}"
    lines = [f"{head} {'end':>6s} {'r end':>6s} {'ahead walking':>13s}"]
    for name, runs in results["runs"].items():
        for run in runs:
            median = (run["centre_to_user_m"] or {}).get("median", float("nan"))
            lines.append(
                f"{name:20s} {run['seed']:4d} {run['collisions']:8d} {run['connected_fraction']:9.3f} "
                f"{median:19.2f} {run['centre_to_user_end_m']:6.2f} {run['extent_end_m']:6.3f} "
                f"{run['ahead_while_walking'] if run['ahead_while_walking'] is not None else float('nan'):13.2f}"
            )
    pure = results.get("pure_simulation")
    if pure:
        lines.append(f"pure simulation (seed {pure['seed']}): r* {pure['r_star']}")
        for name, fig in pure.items():
            if isinstance(fig, dict) and "trailing_m" in fig:
                contacts = fig["robot_robot_contacts"] + fig["robot_obstacle_contacts"] + fig["robot_human_contacts"]
                lines.append(
                    f"  {name:24s} contacts {contacts:4d}  connected {fig['connected_fraction']:.3f}  "
                    f"centre-human end {fig['trailing_m']:.2f} m  r after {fig['r_after_m']:.3f}"
                )
    return lines


def plot(results: dict[str, Any], path: Path) -> None:
    """The swarm centre's distance from its human over time, one panel per scenario, one line per seed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(results["runs"])
    fig, axes = plt.subplots(len(names), 1, figsize=(8, 3 * len(names)), squeeze=False)
    for ax, name in zip(axes[:, 0], names, strict=True):
        for run in results["runs"][name]:
            t, d = np.array(run["centre_to_user_series"]).T
            ax.plot(t, d, label=f"seed {run['seed']}: {run['collisions']} contacts")
        ax.set_title(f"{name} (model time)")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("swarm centre to human (m)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
