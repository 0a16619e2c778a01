"""``petswarm bench start``: what starting robot processes costs, forked from the fork server or started anew.

Each round starts ``--robots`` robot processes through a ``Supervisor`` twice, once forked
(``petswarm.lab.forking``) and once exec'd (``Supervisor(fork=False)``), alternating which goes first so that
the machine's load falls on both alike. The robots are given a hub nobody serves, so each one imports its code,
reads its options and then waits (it says so in its log): what is measured is a robot's start and nothing else.
Per way: CPU seconds of all processes involved (the fork server's own included), the wall time until every
robot waits, and each robot's peak resident memory (VmHWM) and proportional share (Pss: pages shared with the
server count in part).
"""

from __future__ import annotations

import resource
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from petswarm.lab.output import emit, save
from petswarm.lab.processes import Supervisor, free_tcp_port

WAYS = ("forked", "exec")
READY_WITHIN_S = 60.0
"""How long a round waits for every robot to say it waits for its hub."""


@dataclass
class StartOptions:
    """What ``petswarm bench start`` is asked to do."""

    robots: int = 20
    """Robots per start."""
    rounds: int = 3
    """Rounds of both ways."""
    out: str = "bench-results"
    json: bool = False


def bench_start(args: StartOptions) -> int:
    """Start the robots both ways, round after round; print, save JSON and a plot. 1 if a start failed."""
    samples: dict[str, list[dict[str, Any]]] = {way: [] for way in WAYS}
    with tempfile.TemporaryDirectory(prefix="petswarm-start-") as tmp:
        for n in range(args.rounds):
            order = WAYS if n % 2 == 0 else WAYS[::-1]
            for way in order:
                print(
                    f"[bench start] round {n + 1}/{args.rounds}: {args.robots} robots {way}",
                    file=sys.stderr,
                    flush=True,
                )
                samples[way].append(start_robots(args.robots, way == "forked", Path(tmp) / f"{way}-{n}"))
    results = {"robots": args.robots, "rounds": args.rounds, "ways": {w: summarise(s) for w, s in samples.items()}}
    results["samples"] = samples
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    save(results, out, "bench_start", plot)
    emit(table(results), {k: v for k, v in results.items() if k != "samples"}, args.json)
    return 0 if all(s["ready"] for way in samples.values() for s in way) else 1


def start_robots(count: int, fork: bool, logs: Path) -> dict[str, Any]:
    """Start ``count`` waiting robots, one way; their CPU, time to be ready and memory."""
    before = _children_cpu()
    sup = Supervisor(logs, fork=fork)
    started = time.monotonic()
    try:
        names = [f"robot-{rid}" for rid in range(1, count + 1)]
        for rid, name in enumerate(names, start=1):
            hub = f"tcp/127.0.0.1:{free_tcp_port()}"
            sup.spawn(name, ["robot", "--id", str(rid), "--hub", hub, "--world", "bench-start"])
        ready = _wait_ready(sup, names)
        ready_s = time.monotonic() - started
        memory = [_memory_mb(sup.children[name].pid) for name in names]
    finally:
        sup.stop_all()
    cpu = _children_cpu() - before
    return {
        "ready": ready,
        "ready_s": round(ready_s, 3),
        "cpu_s": round(cpu, 3),
        "cpu_per_robot_s": round(cpu / count, 4),
        "peak_rss_mb": statistics.median(m["rss"] for m in memory),
        "pss_mb": statistics.median(m["pss"] for m in memory),
    }


def summarise(samples: list[dict[str, Any]]) -> dict[str, Any]:
    """Medians over the rounds."""
    keys = ("ready_s", "cpu_s", "cpu_per_robot_s", "peak_rss_mb", "pss_mb")
    return {k: round(statistics.median(s[k] for s in samples), 4) for k in keys}


def table(results: dict[str, Any]) -> list[str]:
    """One line per way."""
    lines = [
        f"{results['robots']} robots, median of {results['rounds']} rounds",
        f"{'way':8s} {'CPU s/robot':>11s} {'ready s':>8s} {'peak RSS MB':>11s} {'Pss MB':>7s}",
    ]
    for way, fig in results["ways"].items():
        lines.append(
            f"{way:8s} {fig['cpu_per_robot_s']:11.3f} {fig['ready_s']:8.2f} {fig['peak_rss_mb']:11.1f} "
            f"{fig['pss_mb']:7.1f}"
        )
    return lines


def plot(results: dict[str, Any], path: Path) -> None:
    """CPU per robot and memory per robot, each way, as bars with every round's sample as a dot."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = (("cpu_per_robot_s", "CPU seconds per robot"), ("ready_s", "seconds until all wait"), ("pss_mb", "Pss MB"))
    fig, axes = plt.subplots(1, len(panels), figsize=(11, 3.6))
    for axis, (key, title) in zip(axes, panels, strict=True):
        for x, way in enumerate(WAYS):
            axis.bar(x, results["ways"][way][key], color=("tab:green", "tab:grey")[x], alpha=0.7)
            axis.plot([x] * len(results["samples"][way]), [s[key] for s in results["samples"][way]], "k.")
        axis.set_xticks(range(len(WAYS)), WAYS)
        axis.set_title(title)
        axis.grid(alpha=0.3, axis="y")
    fig.suptitle(f"starting {results['robots']} robot processes (median of {results['rounds']} rounds)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _wait_ready(sup: Supervisor, names: list[str]) -> bool:
    deadline = time.monotonic() + READY_WITHIN_S
    waiting: set[str] = set()
    while time.monotonic() < deadline:
        waiting |= {n for n in names if n not in waiting and "waiting for a hub" in sup.log_tail(n, 3)}
        if len(waiting) == len(names):
            return True
        if sup.dead():
            return False
        time.sleep(0.02)
    return False


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _memory_mb(pid: int) -> dict[str, float]:
    """VmHWM and Pss of a live process, in MB (nan where /proc does not say)."""
    found = {"rss": float("nan"), "pss": float("nan")}
    for path, field, key in ((f"/proc/{pid}/status", "VmHWM:", "rss"), (f"/proc/{pid}/smaps_rollup", "Pss:", "pss")):
        try:
            for line in Path(path).read_text().splitlines():
                if line.startswith(field):
                    found[key] = int(line.split()[1]) / 1024
        except OSError:
            pass
    return found
