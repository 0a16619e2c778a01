"""``petswarm bench reaction``: the swarm paper's reaction-time experiment, over real processes.

Each trial is one rotation of a standing user in front of a leading swarm of 3 (``scenarios/reaction.toml``:
six rotations per run). A trial's times come from the run's ground truth (``petswarm.lab.metrics.reactions``):
from the start of the user's rotation to the first tick at which the master, and each slave, turns at
``REACTION_OMEGA_RPS`` (a turn that starts after the user's does: one already under way is not a reaction).
Scenario runs (seeds ``seed``, ``seed + 1``, ...) are repeated until ``--runs``
trials are in; the CDFs of master and slave reaction times and of slave-minus-master are drawn and saved.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from petswarm.bench import paper
from petswarm.lab.metrics import REACTION_OMEGA_RPS
from petswarm.lab.output import emit, save
from radio_hub.values import lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "reaction.toml"


@dataclass
class ReactionOptions:
    """What ``petswarm bench reaction`` is asked to do."""

    runs: int = 50
    """Trials (user rotations) to measure."""
    scenario: str = str(SCENARIO)
    seed: int = 1
    out: str = "bench-results"
    json: bool = False
    profile: str = "ideal"
    clock: str = "model"
    """``model`` (each run in model time) or ``wall`` (processes over zenoh)."""


def bench_reaction(args: ReactionOptions) -> int:
    """Run scenario runs until ``args.runs`` trials are measured; print, save JSON and the CDF plot."""
    trials: list[dict[str, Any]] = []
    failures: list[str] = []
    seed = args.seed
    with tempfile.TemporaryDirectory(prefix="petswarm-reaction-") as tmp:
        while len(trials) < args.runs and len(failures) < 3:
            record = Path(tmp) / f"run-{seed}"
            print(f"[bench reaction] run seed {seed}: {len(trials)}/{args.runs} trials so far", file=sys.stderr)
            summary = _run(args.scenario, seed, record, args.clock, args.profile)
            if summary is None or not summary.get("ok"):
                why = "no summary (the run failed)" if summary is None else "; ".join(summary.get("problems", []))
                failures.append(f"seed {seed}: {why}")
            else:
                trials += [{**r, "seed": seed} for r in summary["driving"]["reactions"]]
            seed += 1
    trials = trials[: args.runs]
    results = summarise(trials)
    results.update(scenario=args.scenario, first_seed=args.seed, failed_runs=failures, clock=args.clock)
    results.update(profile=args.profile, paper=paper_rows(results))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    save(results, out, "bench_reaction", plot_cdfs, {**results, "trials": trials})
    emit(table(results), results, args.json)
    return 0 if trials and not failures else 1


def _run(scenario: str, seed: int, record: Path, clock: str, profile: str) -> dict[str, Any] | None:
    argv = [sys.executable, "-m", "cli", "run", scenario, "--seed", str(seed), "--json", "--record", str(record)]
    argv += ["--clock", clock, "--profile", profile]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=600)
    try:
        return json.loads(done.stdout)
    except json.JSONDecodeError:
        return None


def paper_rows(results: dict[str, Any]) -> list[dict[str, Any]]:
    """The paper's 90th percentiles beside this bench's."""
    labels = {"master_s": "reaction p90, master (s)", "slave_s": "reaction p90, slaves (s)"}
    labels["slave_minus_master_s"] = "reaction p90, slave - master (s)"
    return [
        paper.row(label, paper.REACTION_P90_S[key], (results[key] or {}).get("p90")) for key, label in labels.items()
    ]


def summarise(trials: list[dict[str, Any]]) -> dict[str, Any]:
    """Percentiles of master, slave and slave-minus-master times (s), and the samples for the CDFs."""
    master = [t["master_s"] for t in trials if t.get("master_s") is not None]
    slaves = [s for t in trials for s in t["slaves_s"].values() if s is not None]
    gaps = [g for t in trials for g in t["slave_minus_master_s"].values()]
    missed = sum(t.get("master_s") is None for t in trials) + sum(
        s is None for t in trials for s in t["slaves_s"].values()
    )
    return {
        "trials": len(trials),
        "threshold_rps": REACTION_OMEGA_RPS,
        "missed_reactions": missed,
        "master_s": _stats(master),
        "slave_s": _stats(slaves),
        "slave_minus_master_s": _stats(gaps),
        "samples": {"master_s": master, "slave_s": slaves, "slave_minus_master_s": gaps},
    }


def _stats(values: list[float]) -> dict[str, float] | None:
    if not values:
        return None
    a = np.asarray(values, dtype=float)
    return {
        "n": len(values),
        "mean": round(float(a.mean()), 3),
        "p10": round(float(np.percentile(a, 10)), 3),
        "p50": round(float(np.percentile(a, 50)), 3),
        "p90": round(float(np.percentile(a, 90)), 3),
        "max": round(float(a.max()), 3),
    }


def table(results: dict[str, Any]) -> list[str]:
    """The figures as a person reads them."""
    lines = [
        f"reaction to the user's rotation ({results['trials']} trials, turning at >= {results['threshold_rps']} rad/s)",
        f"{'':<22}{'n':>5}{'mean':>8}{'p10':>8}{'p50':>8}{'p90':>8}{'max':>8}   seconds",
    ]
    for key, label in (("master_s", "master"), ("slave_s", "slaves"), ("slave_minus_master_s", "slave - master")):
        s = results[key]
        if s is None:
            lines.append(f"{label:<22}  no samples")
            continue
        lines.append(
            f"{label:<22}{s['n']:>5}{s['mean']:>8.3f}{s['p10']:>8.3f}{s['p50']:>8.3f}{s['p90']:>8.3f}{s['max']:>8.3f}"
        )
    lines.append(f"missed reactions (no turn within 5 s): {results['missed_reactions']}")
    lines += [f"failed run (not counted): {failure}" for failure in results.get("failed_runs", [])]
    if "paper" in results:
        lines += ["", *paper.lines(results["paper"], results["profile"])]
    return lines


def plot_cdfs(results: dict[str, Any], path: Path) -> None:
    """The three CDFs of the paper's figure, side by side."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    samples = results["samples"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for key, label in (("master_s", "master"), ("slave_s", "slaves")):
        _cdf(axes[0], samples[key], label)
    axes[0].set(xlabel="time from the start of the user's rotation (s)", ylabel="CDF", title="reaction time")
    _cdf(axes[1], samples["slave_minus_master_s"], "slave - master")
    _paper_p90(axes[0], ("master_s", "slave_s"))
    _paper_p90(axes[1], ("slave_minus_master_s",))
    axes[1].set(xlabel="slave reaction minus master reaction (s)", title="slave - master")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right")
    fig.suptitle(
        f"petswarm bench reaction: {results['trials']} user rotations, leading swarm of 3, "
        f"profile {results.get('profile', 'ideal')}"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _paper_p90(ax: Any, keys: tuple[str, ...]) -> None:
    """The paper's 90th percentiles as points at CDF 0.9."""
    xs = [paper.REACTION_P90_S[k] for k in keys]
    ax.plot(xs, [0.9] * len(xs), "k*", markersize=11, label="paper, p90 (Figs. 20-21)")


def _cdf(ax: Any, values: list[float], label: str) -> None:
    if not values:
        return
    xs = np.sort(np.asarray(values, dtype=float))
    ax.step(xs, np.arange(1, len(xs) + 1) / len(xs), where="post", label=f"{label} (n={len(xs)})")
