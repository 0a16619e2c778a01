"""``petswarm bench surround``: the surround scenarios in model time, through each robot's own pipeline.

Each run steps the hub's world (``radio_hub.world``: kinematics, contacts, ultrasonic, odometry) and its IR
beacons (``radio_hub.ir_air``: 20 Hz sweeps, noise, AGC) exactly as the hub schedules them (a 20 ms world
tick, body sensors every second tick, beacons every fifth), and one ``SurroundPilot`` per robot, the very
code a robot process runs, fed from them. A command takes effect at the next world tick. What is left out is
only the processes' scheduling: on a loaded machine (20 robot processes on 2 cores) sensor samples come late
and commands later, and ``petswarm run SCENARIO`` shows that; this bench shows the pipeline itself,
deterministically per seed, in seconds.

Figures per run come from the same ``cli.metrics.driving_metrics`` as a process run's, over the world's
ground truth at 10 Hz; the plot draws how far each run's swarm centre is from its human over time.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from cli.bench_output import emit, save
from cli.metrics import driving_metrics
from petswarm.scenario import Scenario, load
from petswarm.surround import SurroundConfig
from petswarm.surround_pilot import SurroundDriverConfig, SurroundPilot
from petswarm.surround_sim import surround_figures
from radio_hub.interface import BeaconSweep, IrConfig, OwnSensors
from radio_hub.ir_air import IrAir
from radio_hub.light import PERSON_BEACON_POWER
from radio_hub.world import World, WorldConfig, parse_obstacle

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
DEFAULT_SCENARIOS = [str(SCENARIOS / "surround-cylinder.toml"), str(SCENARIOS / "surround-corridor.toml")]
TICK_S = 0.02
"""The hub's world tick."""
SENSORS_EVERY = 2
"""Ticks between body-sensor samples (25 Hz), as the hub sends them."""
BEACONS_EVERY = 5
"""Ticks between beacon sweeps (20 Hz), as the hub sends them."""
RECORD_EVERY = 5
"""Ticks between recorded world states (10 Hz) for the figures."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The bench's options."""
    from cli.args import bounded, seed

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


def model_time_run(scenario: Scenario, seed: int) -> list[dict[str, Any]]:
    """One run of ``scenario`` in model time; the world's states at 10 Hz, as a run's world.jsonl holds them."""
    if scenario.user is None:
        raise ValueError(f"scenario {scenario.name!r} has no user to surround")
    tables = scenario.hub_tables()
    config = WorldConfig.from_dict(tables.get("world", {}))
    world = World(config, [parse_obstacle(o) for o in tables["obstacles"]])
    body_rng, ir_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
    ir = IrAir(IrConfig.from_dict(tables.get("ir", {})) if "ir" in tables else IrConfig(), ir_rng)
    human = scenario.user.node_id
    world.add(human, "user", *scenario.user.start)
    ir.set_mode(human, "beacon", 0)
    ir.power[human] = PERSON_BEACON_POWER
    law = SurroundConfig.from_dict(scenario.surround_law())
    pilots: dict[str, SurroundPilot] = {}
    for n, (x, y, heading_deg) in enumerate(scenario.robot_poses, start=1):
        robot = f"robot-{n}"
        world.add(robot, "robot", x, y, math.radians(heading_deg))
        ir.set_mode(robot, "beacon", 0)
        pilots[robot] = SurroundPilot(SurroundDriverConfig(law=law, human_id=human))
    return _step_world(scenario, world, ir, pilots, body_rng)


def _step_world(
    scenario: Scenario, world: World, ir: IrAir, pilots: dict[str, SurroundPilot], rng: np.random.Generator
) -> list[dict[str, Any]]:
    assert scenario.user is not None
    human = scenario.user.node_id
    angles = np.radians(np.array(world.config.ultrasonic_angles_deg))
    sweeps = {robot: BeaconSweep(0, {}, {}) for robot in pilots}
    commands: dict[str, tuple[float, float]] = {}
    states: list[dict[str, Any]] = []
    for tick in range(1, round(scenario.duration_s / TICK_S) + 1):
        t = tick * TICK_S
        t_us = round(t * 1e6)
        for robot, (vx, vy) in commands.items():
            world.command(robot, vx, vy, 0.0, t)
        commands = {}
        world.place(human, *scenario.user.pose_at(t))
        world.step(t)
        if tick % BEACONS_EVERY == 0:
            sweeps.update(_beacon_sweeps(world, ir, t_us))
        if tick % SENSORS_EVERY == 0:
            for robot, pilot in pilots.items():
                own = world.sense(robot, rng)
                sensors = OwnSensors(t_us, own.ranges_m, angles, own.yaw_rad, tuple(float(v) for v in own.odometry))
                command = pilot.step(sensors, sweeps[robot], t)
                if command is not None:
                    commands[robot] = command
        if tick % RECORD_EVERY == 0:
            states.append({"t_us": t_us, "bodies": world.snapshot(), "collisions": world.collisions})
    return states


def _beacon_sweeps(world: World, ir: IrAir, t_us: int) -> dict[str, BeaconSweep]:
    poses = world.poses()
    return {
        node: BeaconSweep(t_us, dict(zip(sources, block, strict=True)), dict(zip(sources, gains, strict=True)))
        for node, (sources, block, gains) in ir.beacon_sweep(poses).items()
    }


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
