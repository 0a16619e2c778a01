"""``petswarm bench surround --train N --test M``: each law on generated courses, training and test sets side by side.

Every course (``surround_courses.course``) runs once in model time with its own run seed, and is judged on the
four bounds of a surround run (``surround_metrics``: no contact of any kind, connected >= 0.99 of the time, the
swarm's centre within 0.5 m of the walking human at the median, r over the last second within 10 % of r*), r*
being the course's robot count's (``surround_courses.R_STAR_M``), not the 20 robots' 0.65 m. The summary gives,
per law and set, the share of courses meeting each bound and all four; the plot draws them as bars, training and
test side by side, with the issue's targets as ticks.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

TARGETS = {"no_contact": 0.99, "connected": 0.97, "inside": 0.95, "r_end": 0.95}
"""The share of test courses each bound must hold on (the generalisation target)."""
BOUND_NAMES = ("no_contact", "connected", "inside", "r_end")
SETS = ("train", "test")


def course_jobs(train: int, test: int, laws: list[str], first: int = 0) -> list[tuple[str, int, str]]:
    """(set name, course index, law) for every run, laws innermost: a course's laws run one after another."""
    jobs = []
    for name, count in (("train", train), ("test", test)):
        for i in range(first, first + count):
            jobs += [(name, i, law) for law in laws]
    return jobs


def run_course(set_name: str, i: int, law: str) -> dict[str, Any]:
    """One course under ``law`` in model time: what it drew, its figures and bounds, model and CPU seconds."""
    from petswarm.bench.surround_courses import TEST_SET, TRAINING_SET, course, scenario_tables
    from petswarm.lab.metrics import read_world
    from petswarm.lab.model_run import execute, scenario_options
    from petswarm.lab.surround_metrics import surround_metrics
    from petswarm.scenario import parse

    data = course(TRAINING_SET if set_name == "train" else TEST_SET, i)
    tables = scenario_tables(data)
    tables["surround"] = {**tables["surround"], "law": law}
    scenario = parse(tables)
    started = time.process_time()
    workdir = Path(tempfile.mkdtemp(prefix="petswarm-course-"))
    try:
        opts = scenario_options(scenario, data["run_seed"], workdir / "record")
        with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
            summary = execute(opts, scenario)
        world_path = Path(summary.get("record", workdir / "record")) / "world.jsonl"
        world = read_world(world_path) if world_path.exists() else []
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    figures = surround_metrics(world) if world else {}
    events = contact_events(world)
    figures.pop("series", None)
    r_star = data["course"]["r_star_m"]
    off = abs(figures["r_end_m"] - r_star) / r_star if "r_end_m" in figures else math.inf
    figures["r_star_m"], figures["r_end_off"] = r_star, round(off, 4)
    run = {
        "set": set_name,
        "course": i,
        "law": law,
        "run_seed": data["run_seed"],
        "drawn": data["course"],
        "digest": summary.get("digest"),
        "ok": summary.get("ok", False),
        "model_time_s": summary.get("model_time_s"),
        "cpu_s": round(time.process_time() - started, 2),
        "contacts": figures.get("contacts"),
        "connected_fraction": figures.get("connected_fraction"),
        "centre_to_human_walking_m": figures.get("centre_to_human_walking_m"),
        "r_end_m": figures.get("r_end_m"),
        "r_star_m": r_star,
        "r_end_off": figures["r_end_off"],
    }
    run["contact_events"] = events
    run["bounds"] = bounds(figures)
    return run


CONE_SPACING_DEG = 45.0
"""The ultrasonic ring's cones are this far apart round the robot, the first on its heading (the Pet-Bot's ring)."""
HALF_BEAM_DEG = 15.0
"""Each cone's half beam (``surround_memory.HALF_BEAM_RAD``): a bearing farther than this from every cone's axis lies
in a blind gap."""
TOUCHING_M = 0.002
"""Bodies this close at the tick a contact was counted are the ones touching (``surround_metrics.TOUCH_M``)."""


def contact_events(world: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each contact of a run as the world saw it, to tell why it happened. At each tick the world's contact count
    rose by k, the k touches nearest (deepest) then, as ``surround_metrics.contacts`` puts them down: the time (s),
    the robot, what it touched (``robot``, ``user`` or ``obstacle``, and for a wall whether at its end), the robot's
    speed (m/s), the bearing of the touching point in the robot's frame (degrees) and whether that bearing lies in a
    blind gap of its ultrasonic ring."""
    out: list[dict[str, Any]] = []
    before = 0
    for state in world:
        count = int(state.get("collisions", 0))
        if count > before:
            touches = sorted(_touching_now(state), key=lambda event: event["gap_m"])
            out += touches[: count - before]
        before = count
    return out


def _touching_now(state: dict[str, Any]) -> list[dict[str, Any]]:
    """The robots touching a body or an obstacle in ``state`` (each robot-robot pair once), with the gap (m)."""
    bodies = state["bodies"]
    events = []
    for k, robot in enumerate(bodies):
        if robot["kind"] != "robot":
            continue
        x, y, radius = robot["x"], robot["y"], robot["radius"]
        touched: list[tuple[str, float, float, float, bool]] = []
        for j, other in enumerate(bodies):
            if j == k or (other["kind"] == "robot" and j < k):
                continue
            gap = math.hypot(other["x"] - x, other["y"] - y) - radius - other["radius"]
            if gap < TOUCHING_M:
                touched.append(("robot" if other["kind"] == "robot" else "user", gap, other["x"], other["y"], False))
        for o in state.get("obstacles", []):
            px, py, end = _nearest_point(o, x, y)
            gap = math.hypot(px - x, py - y) - radius
            if gap < TOUCHING_M:
                touched.append(("obstacle", gap, px, py, end))
        for kind, gap, px, py, end in touched:
            bearing = math.degrees(math.atan2(py - y, px - x) - robot["yaw"])
            off_axis = abs((bearing + CONE_SPACING_DEG / 2) % CONE_SPACING_DEG - CONE_SPACING_DEG / 2)
            events.append(
                {
                    "t": round(state["t_us"] / 1e6, 2),
                    "robot": robot["id"],
                    "with": kind,
                    "wall_end": end,
                    "speed_mps": round(math.hypot(robot["vx"], robot["vy"]), 3),
                    "bearing_deg": round((bearing + 180.0) % 360.0 - 180.0, 1),
                    "blind_gap": off_axis > HALF_BEAM_DEG,
                    "gap_m": round(gap, 4),
                }
            )
    return events


def _nearest_point(o: dict[str, Any], x: float, y: float) -> tuple[float, float, bool]:
    """The obstacle's point nearest (x, y), and whether it is a wall's end."""
    if o["kind"] == "circle":
        d = max(math.hypot(x - o["x"], y - o["y"]), 1e-12)
        return o["x"] + (x - o["x"]) * o["r"] / d, o["y"] + (y - o["y"]) * o["r"] / d, False
    if o["kind"] == "rect":
        return min(max(x, o["x0"]), o["x1"]), min(max(y, o["y0"]), o["y1"]), False
    ax, ay, ex, ey = o["x0"], o["y0"], o["x1"] - o["x0"], o["y1"] - o["y0"]
    length2 = ex * ex + ey * ey
    u = 0.0 if length2 <= 0 else min(1.0, max(0.0, ((x - ax) * ex + (y - ay) * ey) / length2))
    return ax + u * ex, ay + u * ey, u in (0.0, 1.0)


def bounds(figures: dict[str, Any]) -> dict[str, bool]:
    """The four bounds (``surround_metrics.bounds_met``) on a course's figures, r judged against its own r*."""
    from petswarm.lab.surround_metrics import bounds_met

    return bounds_met(figures)


def run_all(jobs: list[tuple[str, int, str]], workers: int, log: Path | None = None) -> list[dict[str, Any]]:
    """Every job's run, in order, with a progress line per run on stderr; ``workers`` > 1: forked worker processes.
    ``log``: each run is also appended to this JSON-lines file as it ends (a long bench stopped early keeps them)."""
    total = len(jobs)

    def told(k: int, run: dict[str, Any]) -> dict[str, Any]:
        if log is not None:
            with log.open("a") as out:
                out.write(json.dumps(run) + "\n")
        met = run["bounds"]
        missed = ",".join(b for b in BOUND_NAMES if not met[b]) or "-"
        print(
            f"[bench surround] {k + 1}/{total} {run['set']} course {run['course']} ({run['drawn']['kind']}, "
            f"{run['drawn']['robots']} robots) law {run['law']}: {'all four' if met['all'] else 'missed ' + missed} "
            f"({run['cpu_s']:.1f} CPU s)",
            file=sys.stderr,
            flush=True,
        )
        return run

    if workers <= 1:
        return [told(k, run_course(*job)) for k, job in enumerate(jobs)]
    import concurrent.futures
    import multiprocessing

    context = multiprocessing.get_context("fork")
    with concurrent.futures.ProcessPoolExecutor(workers, mp_context=context) as pool:
        futures = [pool.submit(run_course, *job) for job in jobs]
        try:
            return [told(k, future.result()) for k, future in enumerate(futures)]
        except BaseException:  # Ctrl-C, or a worker that died: stop the queued runs too
            pool.shutdown(wait=False, cancel_futures=True)
            raise


def summarise(runs: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per law and set: courses, how many meet each bound and all four (and the share), the courses missed, the
    contacts by kind, and the CPU seconds per model second."""
    out: dict[str, dict[str, Any]] = {}
    for run in runs:
        row = out.setdefault(run["law"], {}).setdefault(
            run["set"],
            {"courses": 0, "met": dict.fromkeys((*BOUND_NAMES, "all"), 0), "missed": [], "cpu_s": 0.0, "model_s": 0.0},
        )
        row["courses"] += 1
        for bound, met in run["bounds"].items():
            row["met"][bound] += met
        if not run["bounds"]["all"]:
            row["missed"].append(run["course"])
        row["cpu_s"] += run["cpu_s"]
        row["model_s"] += run["model_time_s"] or 0.0
        kinds = row.setdefault("contacts", {"robot_robot": 0, "robot_obstacle": 0, "robot_human": 0})
        for kind in kinds:
            kinds[kind] += (run["contacts"] or {}).get(kind, 0)
    for sets in out.values():
        for row in sets.values():
            row["share"] = {bound: round(n / row["courses"], 3) for bound, n in row["met"].items()}
            row["cpu_per_model_s"] = round(row["cpu_s"] / row["model_s"], 3) if row["model_s"] else None
    return out


def lines(summary: dict[str, dict[str, Any]]) -> list[str]:
    """The summary as a table: per law, each bound's share on the training and the test set side by side."""
    head = f"{'law':9s} {'set':5s} {'courses':>7s}"
    for bound in (*BOUND_NAMES, "all"):
        head += f" {bound:>10s}"
    out = [head + f" {'rr/ro/rh':>11s} {'CPU/model s':>11s}"]
    for law, sets in summary.items():
        for name in SETS:
            row = sets.get(name)
            if row is None:
                continue
            text = f"{law:9s} {name:5s} {row['courses']:7d}"
            for bound in (*BOUND_NAMES, "all"):
                text += f" {100 * row['share'][bound]:9.1f}%"
            c = row["contacts"]
            text += f" {c['robot_robot']:>3d}/{c['robot_obstacle']}/{c['robot_human']:<3d}".rjust(12)
            text += f" {row['cpu_per_model_s'] or math.nan:11.3f}"
            out.append(text)
    targets = ", ".join(f"{b} {100 * t:.0f} %" for b, t in TARGETS.items())
    out.append(f"targets on the test set: {targets}")
    return out


LAW_COLOURS = {"paper": "#c44e52", "improved": "#4c72b0", "safe": "#55a868"}


def plot(results: dict[str, Any], path: Path) -> None:
    """Bars: per bound (and all four), each law's share of courses meeting it, training (hatched) and test side by
    side; the targets as black ticks."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    summary = results["summary"]
    laws = list(summary)
    names = [*BOUND_NAMES, "all"]
    fig, ax = plt.subplots(figsize=(11, 4))
    width = 0.8 / max(1, 2 * len(laws))
    for k, law in enumerate(laws):
        for s, name in enumerate(SETS):
            row = summary[law].get(name)
            if row is None:
                continue
            x = np.arange(len(names)) + (2 * k + s - len(laws)) * width + width / 2
            shares = [100 * row["share"][b] for b in names]
            ax.bar(
                x,
                shares,
                width,
                color=LAW_COLOURS.get(law, "grey"),
                hatch="//" if name == "train" else None,
                alpha=0.6 if name == "train" else 1.0,
                label=f"{law} {name} ({row['courses']} courses)",
            )
    for j, bound in enumerate(names):
        if bound in TARGETS:
            ax.plot([j - 0.4, j + 0.4], [100 * TARGETS[bound]] * 2, color="k", lw=1.2)
    ax.set_xticks(np.arange(len(names)), names)
    ax.set_ylabel("courses meeting it (%)")
    ax.set_ylim(0, 105)
    ax.set_title("surround laws on generated courses: training vs test (model time)", fontsize=10)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=7, ncol=2, loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
