"""``petswarm bench surround``: the surround scenarios in model time, through each robot's own pipeline.

Each run is a ``petswarm run SCENARIO --clock model`` (``petswarm.lab.model_run``): the hub's own environment on its
one schedule (world ticks, body sensors, IR beacons) and every robot and the user as the objects their
processes run, on model time. It is deterministic per seed and independent of the machine's load; a process
run of the same scenario (``--clock wall``) differs only by the processes' scheduling. ``--clock lockstep`` runs
each robot and the user as its own process instead, on the model time the hub owns (``petswarm.lab.lockstep_run``):
the same figures and the same ``digest`` as model time for the same seed, as proof that processes do it too
(about a minute of two cores for 20 robots and 22 s).

``--law`` picks the law the robots run (the paper's, the improved one, or both in turn), whatever the scenario file
says. Figures per run come from ``petswarm.lab.surround_metrics`` over the world's ground truth at 50 Hz (contacts
by kind, connected share, centre to human while he walks, robots ahead of him, r at the end against r*, the time
to pass the obstacle), with the older ``driving_metrics`` figures beside them; the plot draws r(t) (as the
paper's Figs. 7 and 9) and the swarm centre's distance from its human, one colour per law. Each run also says
which of issue 17's four bounds it meets (``surround_metrics.bounds_met``), and the bench counts them per scenario
and law (``bounds_summary``): at 80 % a seed, ten in a row all pass one time in nine, so a rate needs many seeds,
which ``--jobs`` spreads over worker processes.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from petswarm.bench.surround_runs import scenario_run, with_law
from petswarm.lab.metrics import driving_metrics
from petswarm.lab.output import emit, save
from radio_hub.values import lazy_numpy

if TYPE_CHECKING:
    import numpy as np

    from petswarm.scenario import Scenario
else:
    np = lazy_numpy(__name__)

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
DEFAULT_SCENARIOS = [str(SCENARIOS / "surround-cylinder.toml"), str(SCENARIOS / "surround-corridor.toml")]
"""A run's exit code when Ctrl-C or SIGTERM stopped it."""
RECORD_EVERY = 5
"""World ticks (50 Hz) between the states the figures use (10 Hz)."""


@dataclass(frozen=True)
class SurroundOptions:
    """What ``petswarm bench surround`` is asked to do (its command line's options, typed)."""

    scenarios: list[str] = field(default_factory=lambda: list(DEFAULT_SCENARIOS))
    """Surround scenario files (run unless generated courses are asked for)."""
    seeds: int = 3
    """Runs per scenario and law."""
    seed: int = 1
    """Seed of the first run."""
    out: str = "bench-results"
    paper: bool = False
    """Also the pure simulation of the paper's setups (exact sensing, no hub)."""
    law: str = "paper"
    """``paper``, ``improved``, ``safe``, ``both`` (paper and improved) or ``all``."""
    train: int = 0
    """Generated training courses to run instead of scenario files."""
    test: int = 0
    """Generated test courses to run instead of scenario files."""
    first_course: int = 0
    clock: str = "model"
    jobs: int = 1
    """Model-time runs at once, each in its own worker process."""
    snapshots: bool = False
    """Also the safe law's snapshot plot of the first scenario's first seed."""
    json: bool = False


def bench_surround(args: SurroundOptions) -> int:
    """Run every scenario for ``--seeds`` seeds on ``--clock``; print, save JSON and the plot. Exit code 1 when a
    run was not ok (its row says why), 2 for a bad scenario file."""
    # imported here, not at load: building the CLI's parser imports this module in every process,
    # robots too, and these bring the hub's side and numpy (issue 13)
    from petswarm.bench.surround_sim import surround_figures
    from petswarm.scenario import load

    if args.train or args.test:
        return bench_courses(args)
    results: dict[str, Any] = {"first_seed": args.seed, "laws": _laws(args.law), "clock": args.clock, "runs": {}}
    try:  # every file is read before the long runs start
        scenarios = [load(path) for path in args.scenarios]
    except ValueError as err:
        print(f"petswarm bench surround: {err}", file=sys.stderr)
        return 2
    for path, scenario in zip(args.scenarios, scenarios, strict=True):
        if not scenario.surround_enabled:
            print(f"petswarm bench surround: {path} is not a surround scenario ([surround] enabled)", file=sys.stderr)
            return 2
    if args.jobs > 1 and args.clock != "model":
        print(
            "petswarm bench surround: --jobs applies to --clock model (a lockstep run is 21 processes already)",
            file=sys.stderr,
        )
        return 2
    jobs = [
        (scenario, law, seed)
        for scenario in scenarios
        for law in results["laws"]
        for seed in range(args.seed, args.seed + args.seeds)
    ]
    for (scenario, law, _), run in zip(jobs, _run_all(jobs, args.clock, args.jobs), strict=True):
        results["runs"].setdefault(scenario.name, {}).setdefault(law, []).append(run)
    results["summary"] = bounds_summary(results)
    if args.paper:
        print("[bench surround] the paper's setups, pure simulation", file=sys.stderr)
        results["pure_simulation"] = surround_figures(args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.snapshots:
        from petswarm.bench.surround_snapshots import plot_active, record_active

        print(f"[bench surround] {scenarios[0].name} seed {args.seed}: safe law snapshots", file=sys.stderr)
        world, active, digest = record_active(scenarios[0], args.seed)
        title = f"{scenarios[0].name}, safe law, seed {args.seed}: active safety constraints"
        snapshots = plot_active(world, active, out / "bench_surround_safe_snapshots.png", title)
        results["snapshots"] = {"png": str(snapshots), "seed": args.seed, "digest": digest}
    save(results, out, "bench_surround", plot)
    emit(table(results) + summary_lines(results["summary"]), results, args.json)
    failed = [run for laws in results["runs"].values() for runs in laws.values() for run in runs if not run["ok"]]
    if failed:
        print(f"petswarm bench surround: {len(failed)} run(s) not ok (the table says why)", file=sys.stderr)
    return 1 if failed else 0


def _laws(choice: str) -> list[str]:
    return {"both": ["paper", "improved"], "all": ["paper", "improved", "safe"]}.get(choice, [choice])


def bench_courses(args: SurroundOptions) -> int:
    """Each law on ``--train`` training and ``--test`` test courses (``surround_bench_courses``): JSON, table and
    plot (``bench_surround_courses``). Exit code 0: every run finished (the bounds are figures, not a verdict)."""
    from petswarm.bench import surround_bench_courses as courses

    if args.clock != "model":
        print("petswarm bench surround: generated courses run in model time only (--clock model)", file=sys.stderr)
        return 2
    laws = _laws(args.law)
    jobs = courses.course_jobs(args.train, args.test, laws, args.first_course)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    runs = courses.run_all(jobs, args.jobs, out / "bench_surround_courses_runs.jsonl")
    results: dict[str, Any] = {"laws": laws, "first_course": args.first_course, "runs": runs}
    results["summary"] = courses.summarise(runs)
    save(results, out, "bench_surround_courses", courses.plot)
    emit(courses.lines(results["summary"]), results, args.json)
    return 0


def _run_all(jobs: list[tuple[Scenario, str, int]], clock: str, workers: int) -> list[dict[str, Any]]:
    """Every job's run (``bench_run``) in the jobs' order: one after another, or on ``workers`` worker processes
    (forked: each a copy of this one, which has read the scenario files). Progress goes to stderr."""
    if workers <= 1:
        return [bench_run(*job, clock) for job in jobs]
    import concurrent.futures
    import multiprocessing

    context = multiprocessing.get_context("fork")
    with concurrent.futures.ProcessPoolExecutor(workers, mp_context=context) as pool:
        futures = [pool.submit(bench_run, *job, clock) for job in jobs]
        try:
            return [future.result() for future in futures]
        except BaseException:  # Ctrl-C, or a worker that died: stop the others' queued runs too
            pool.shutdown(wait=False, cancel_futures=True)
            raise


def bench_run(scenario: Scenario, law: str, seed: int, clock: str) -> dict[str, Any]:
    """One bench run of ``scenario`` under ``law``: its seed, digest, ok and problems, figures and issue 17's
    bounds (``surround_metrics.bounds_met``)."""
    from petswarm.lab.surround_metrics import bounds_met

    print(f"[bench surround] {scenario.name} law {law} seed {seed} ({clock})", file=sys.stderr)
    world, run = scenario_run(with_law(scenario, law), seed, clock)
    figures = summarise(world) if world else {}
    return {"seed": seed, **run, **figures, "bounds": bounds_met(figures)}


def bounds_summary(results: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Per scenario and law (``"<scenario> <law>"``): how many runs meet each of issue 17's bounds and all four,
    the contacts by kind summed, the walking median's and r's ranges, and the seeds that miss."""
    from petswarm.lab.surround_metrics import BOUNDS

    out = {}
    for name, laws in results["runs"].items():
        for law, runs in laws.items():
            measured = [run for run in runs if "contacts" in run]
            medians = [
                run["centre_to_human_walking_m"]["median"] for run in measured if run["centre_to_human_walking_m"]
            ]
            ends = [run["r_end_m"] for run in measured]
            out[f"{name} {law}"] = {
                "runs": len(runs),
                "met": {bound: sum(run["bounds"][bound] for run in runs) for bound in (*BOUNDS, "all")},
                "contacts": {
                    kind: sum(run["contacts"][kind] for run in measured)
                    for kind in ("robot_robot", "robot_obstacle", "robot_human", "unattributed")
                },
                "median_m": [min(medians), max(medians)] if medians else None,
                "r_end_m": [min(ends), max(ends)] if ends else None,
                "missed": [run["seed"] for run in runs if not run["bounds"]["all"]],
            }
    return out


def summary_lines(summary: dict[str, dict[str, Any]]) -> list[str]:
    """The bounds summary as lines: issue 17's four bounds, each met on how many of the runs."""
    lines = ["the surround bounds (no contact, connected >= 0.99, walking median <= 0.5 m, r within 10 % of r*):"]
    for key, row in summary.items():
        met, n, c = row["met"], row["runs"], row["contacts"]
        median = "-" if row["median_m"] is None else "{:.2f}-{:.2f} m".format(*row["median_m"])
        r_end = "-" if row["r_end_m"] is None else "{:.3f}-{:.3f} m".format(*row["r_end_m"])
        missed = ", ".join(map(str, row["missed"])) or "none"
        lines.append(
            f"  {key}: all four {met['all']}/{n}; no contact {met['no_contact']}/{n} "
            f"(rr/ro/rh {c['robot_robot']}/{c['robot_obstacle']}/{c['robot_human']}), "
            f"connected {met['connected']}/{n}, median {met['inside']}/{n} ({median}), r {met['r_end']}/{n} ({r_end}); "
            f"missed: seeds {missed}"
        )
    return lines


def summarise(world: list[dict[str, Any]]) -> dict[str, Any]:
    """A run's surround figures (``surround_metrics``), the older driving ones on the 10 Hz states they were
    defined on, and the centre-to-human distance over time (for the plot)."""
    from petswarm.lab.surround_metrics import surround_metrics

    figures = surround_metrics(world)
    sampled = world[RECORD_EVERY - 1 :: RECORD_EVERY]
    driving = driving_metrics(sampled)
    keys = ("collisions", "connected_fraction", "centre_to_user_m", "centre_to_user_end_m", "extent_end_m")
    series = figures.pop("series")
    return {
        **{k: driving[k] for k in keys},
        **figures,
        "centre_to_user_series": [[t, centre] for t, _, centre in series],
        "extent_series": [[t, r] for t, r, _ in series],
    }


def table(results: dict[str, Any]) -> list[str]:
    """One line per run: contacts by kind (robot-robot/robot-obstacle/robot-human), connected share, the
    centre-to-human median and p90 while he walks, the share of robots ahead of him, r at the end, the time
    to pass the obstacle (human reaching it to last robot leaving it)."""
    head = f"{'scenario':26s} {'law':8s} {'seed':>4s} {'contacts rr/ro/rh':>17s} {'connected':>9s}"
    lines = [f"{head} {'centre-human med/p90':>20s} {'ahead':>5s} {'r end':>6s} {'pass (s)':>8s} {'digest':8s}"]
    for name, laws in results["runs"].items():
        for law, runs in laws.items():
            for run in runs:
                lines.append(_row(name, law, run))
    pure = results.get("pure_simulation")
    if pure:
        lines.append(f"pure simulation, the paper's law (seed {pure['seed']}): r* {pure['r_star']}")
        for name, fig in pure.items():
            if isinstance(fig, dict) and "trailing_m" in fig:
                contacts = fig["robot_robot_contacts"] + fig["robot_obstacle_contacts"] + fig["robot_human_contacts"]
                lines.append(
                    f"  {name:24s} contacts {contacts:4d}  connected {fig['connected_fraction']:.3f}  "
                    f"centre-human end {fig['trailing_m']:.2f} m  r after {fig['r_after_m']:.3f}"
                )
    return lines


def _row(name: str, law: str, run: dict[str, Any]) -> str:
    if "contacts" not in run:  # the run recorded no world: nothing to measure
        return f"{name:26s} {law:8s} {run['seed']:4d}  no world recorded  not ok: {'; '.join(run['problems'] or [])}"
    c = run["contacts"]
    kinds = f"{c['robot_robot']}/{c['robot_obstacle']}/{c['robot_human']}" + (
        f"+{c['unattributed']}" if c["unattributed"] else ""
    )
    centre = run["centre_to_human_walking_m"] or {"median": math.nan, "p90": math.nan}
    ahead = run["ahead_while_walking"] if run["ahead_while_walking"] is not None else math.nan
    passing = (run["obstacle_pass"] or {}).get("time_to_pass_s")
    return (
        f"{name:26s} {law:8s} {run['seed']:4d} {kinds:>17s} {run['connected_fraction']:9.3f} "
        f"{centre['median']:9.2f}/{centre['p90']:<10.2f} {ahead:5.2f} {run['r_end_m']:6.3f} "
        f"{'-' if passing is None else f'{passing:.1f}':>8s} {(run.get('digest') or '-')[:8]:8s}"
        + ("" if run.get("ok", True) else f"  not ok: {'; '.join(run.get('problems') or [])}")
    )


LAW_COLOURS = {"paper": "#c44e52", "improved": "#4c72b0"}


def plot(results: dict[str, Any], path: Path) -> None:
    """Per scenario, r(t) of every run (as the paper's Figs. 7 and 9, r* dashed) and the swarm centre's
    distance from the human; one colour per law."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from petswarm.lab.surround_metrics import R_STAR_M

    names = list(results["runs"])
    fig, axes = plt.subplots(len(names), 2, figsize=(13, 3.2 * len(names)), squeeze=False)
    for (ax_r, ax_c), name in zip(axes, names, strict=True):
        for law, runs in results["runs"][name].items():
            for k, run in enumerate(r for r in runs if "extent_series" in r):
                label = f"{law} ({len(runs)} seeds)" if k == 0 else None
                colour = LAW_COLOURS.get(law)
                t, r = np.array(run["extent_series"], dtype=float).T
                ax_r.plot(t, r, color=colour, lw=0.8, alpha=0.7, label=label)
                t, d = np.array(run["centre_to_user_series"], dtype=float).T
                ax_c.plot(t, d, color=colour, lw=0.8, alpha=0.7, label=label)
        ax_r.axhline(R_STAR_M, ls="--", color="k", lw=0.8, label="r* 0.65 m")
        ax_r.axhspan(0.9 * R_STAR_M, 1.1 * R_STAR_M, color="k", alpha=0.07)
        ax_r.set_title(f"{name}: extent r(t) (model time)", fontsize=10)
        ax_r.set_ylabel("r (m)")
        ax_c.set_title(f"{name}: swarm centre to human", fontsize=10)
        ax_c.set_ylabel("distance (m)")
        for ax in (ax_r, ax_c):
            ax.set_xlabel("time (s)")
            ax.grid(alpha=0.3)
            if ax.get_legend_handles_labels()[0]:  # no runs drawn (none recorded a world): no empty legend
                ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
