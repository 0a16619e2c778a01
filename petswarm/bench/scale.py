"""``petswarm bench scale``: how runs scale with the number of robots, in model and lockstep time.

For each robot count the default run (``petswarm run --robots N --duration D --seed S``) goes once with
``--clock model`` and once with ``--clock lockstep`` (robot counts up to ``--lockstep-max``; model time goes
further, e.g. to 1000). Each run is a child ``petswarm run`` process; the figures come from its JSON summary:
wall seconds per model second, the peak resident memory of the robot processes (lockstep: each robot is its
own process), the hub process's CPU seconds, and whether the lockstep run's digest equals the model run's
(the same run, as the clocks promise). The table goes to stdout, JSON and a plot to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from petswarm.lab.output import emit, save


def robot_counts(text: str) -> list[int]:
    """``10,20,50,100``: the robot counts, each 2..5000 (``none``: no count, for ``--model-robots``)."""
    if text.strip().lower() == "none":
        return []
    try:
        counts = sorted({int(part) for part in text.split(",") if part.strip()})
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma-separated list of robot counts") from None
    if not counts or counts[0] < 2 or counts[-1] > 5000:
        raise argparse.ArgumentTypeError("robot counts must be 2..5000")
    return counts


@dataclass
class ScaleOptions:
    """What ``petswarm bench scale`` is asked to do."""

    robots: list[int] = field(default_factory=lambda: [10, 20, 50, 100])
    model_robots: list[int] = field(default_factory=lambda: [1000])
    """More counts run in model time only."""
    lockstep_max: int = 100
    """Largest lockstep run."""
    duration: float = 5.0
    """Model seconds a run."""
    seed: int = 3
    out: str = "bench-results"
    json: bool = False


def bench_scale(args: ScaleOptions) -> int:
    """Run every count in model time and (up to ``--lockstep-max``) in lockstep; print, save JSON and plot."""
    rows = []
    counts = sorted(set(args.robots) | set(args.model_robots))
    with tempfile.TemporaryDirectory(prefix="petswarm-scale-") as tmp:
        for count in counts:
            row: dict[str, Any] = {"robots": count}
            clocks = ["model"] + (["lockstep"] if count in args.robots and count <= args.lockstep_max else [])
            for clock in clocks:
                print(f"[bench scale] {count} robots, {clock} time", file=sys.stderr, flush=True)
                row[clock] = _figures(_run(count, clock, args, Path(tmp) / f"{clock}-{count}"))
            if "lockstep" in row:
                row["digests_equal"] = row["lockstep"]["digest"] == row["model"]["digest"]
            rows.append(row)
    results = {"duration_s": args.duration, "seed": args.seed, "rows": rows}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    save(results, out, "bench_scale", plot)
    emit(table(results), results, args.json)
    # what the bench vouches for is that lockstep and model time run the same run; a run's own pass criterion
    # (say, every robot heard some other one within a short duration) is shown, not judged here
    return 0 if all(r.get("digests_equal", True) for r in rows) else 1


def _run(count: int, clock: str, args: ScaleOptions, record: Path) -> dict[str, Any]:
    argv = [sys.executable, "-m", "cli", "run", "--robots", str(count), "--duration", str(args.duration)]
    argv += ["--seed", str(args.seed), "--clock", clock, "--json", "--record", str(record)]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=7200)
    try:
        return json.loads(done.stdout)
    except json.JSONDecodeError:
        tail = "\n".join(done.stderr.splitlines()[-5:])
        return {"ok": False, "problems": [f"no summary (exit {done.returncode}): {tail}"]}


def _figures(summary: dict[str, Any]) -> dict[str, Any]:
    rss = [n["peak_rss_mb"] for n in summary.get("nodes", {}).values() if n.get("peak_rss_mb") is not None]
    hub = summary.get("hub_process") or {}
    model_s = summary.get("model_time_s") or 0.0
    return {
        "ok": summary.get("ok", False),
        "problems": summary.get("problems", [])[:3],
        "attached": len(summary.get("nodes", {})),
        "model_time_s": model_s,
        "wall_time_s": summary.get("wall_time_s"),
        "wall_per_model_s": round(summary["wall_time_s"] / model_s, 3) if model_s else None,
        "robot_peak_rss_mb_max": max(rss, default=None),
        "robot_peak_rss_mb_median": statistics.median(rss) if rss else None,
        "hub_cpu_s": hub.get("cpu_s"),
        "digest": summary.get("digest"),
    }


def table(results: dict[str, Any]) -> list[str]:
    """One line per robot count and clock."""
    lines = [
        f"{'robots':>6s} {'clock':9s} {'ok':>3s} {'wall/model s':>12s} {'robot RSS max MB':>16s} "
        f"{'hub CPU s':>9s}  digest"
    ]
    for row in results["rows"]:
        for clock in ("model", "lockstep"):
            fig = row.get(clock)
            if fig is None:
                continue
            same = "" if clock == "model" else ("= model" if row.get("digests_equal") else "DIFFERS from model")
            ok = "yes" if fig["ok"] else "NO"
            lines.append(
                f"{row['robots']:6d} {clock:9s} {ok:>3s} {_num(fig['wall_per_model_s']):>12s} "
                f"{_num(fig['robot_peak_rss_mb_max'] if clock == 'lockstep' else None):>16s} "
                f"{_num(fig['hub_cpu_s'] if clock == 'lockstep' else None):>9s}  {(fig['digest'] or '')[:12]} {same}"
            )
    return lines


def _num(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def plot(results: dict[str, Any], path: Path) -> None:
    """Wall seconds per model second against robots, per clock, and robot process memory in lockstep."""
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (speed, memory) = plt.subplots(1, 2, figsize=(11, 4))
    for clock, style in (("model", "o-"), ("lockstep", "s-")):
        points = [(r["robots"], r[clock]["wall_per_model_s"]) for r in results["rows"] if r.get(clock)]
        points = [(n, v) for n, v in points if v is not None]
        if points:
            speed.plot(*zip(*points, strict=True), style, label=f"--clock {clock}")
    speed.set_xscale("log")
    speed.set_yscale("log")
    for axis in (speed.xaxis, speed.yaxis):  # plain numbers on log axes, not 5x10^0
        axis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
        axis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    speed.axhline(1.0, color="grey", lw=0.8, ls="--")
    speed.set_xlabel("robots")
    speed.set_ylabel("wall seconds per model second")
    speed.set_title("time to run one model second")
    speed.legend()
    speed.grid(alpha=0.3)
    points = [(r["robots"], r["lockstep"]["robot_peak_rss_mb_max"]) for r in results["rows"] if r.get("lockstep")]
    points = [(n, v) for n, v in points if v is not None]
    if points:
        memory.plot(*zip(*points, strict=True), "s-")
    memory.axhline(50.0, color="grey", lw=0.8, ls="--", label="target 50 MB")
    memory.set_ylim(0, None)
    memory.legend()
    memory.set_xlabel("robots")
    memory.set_ylabel("MB")
    memory.set_title("peak RSS of a robot process (lockstep)")
    memory.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
