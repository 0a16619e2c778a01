"""A campaign's results: the table (cases, failures by property, family and fault kind), the JSON of every case,
and a plot of failures by family and fault kind."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path
from typing import Any

from petswarm.explore.generate import FAMILIES, FAULT_KINDS


def _kinds(result: dict[str, Any]) -> list[str]:
    """A case's fault kinds as the generator names them (a kill's restart and the wearable's return are part of it)."""
    return [k for k in result.get("fault_kinds", []) if k in FAULT_KINDS] or ["none"]


def table(results: list[dict[str, Any]], wall_s: float) -> str:
    """The campaign in words: totals, rate, and failures by property, family and fault kind."""
    n = len(results)
    failed = [r for r in results if not r["ok"]]
    cpu = sorted(r["cpu_s"] for r in results) or [0.0]
    lines = [
        f"{n} cases, {len(failed)} failed; wall {wall_s:.1f} s ({n / max(wall_s, 1e-9) * 3600:.0f} cases/h); "
        f"CPU per case median {cpu[len(cpu) // 2]:.2f} s, max {cpu[-1]:.2f} s; "
        f"model time {sum(r['model_time_s'] for r in results):.0f} s",
        "",
        f"{'family':<10} {'cases':>6} {'failed':>6}",
    ]
    fam_cases = Counter(r["family"] for r in results)
    fam_failed = Counter(r["family"] for r in failed)
    lines += [f"{f:<10} {fam_cases[f]:>6} {fam_failed[f]:>6}" for f in FAMILIES if fam_cases[f]]
    lines += ["", f"{'fault kind':<14} {'cases':>6} {'failed':>6}"]
    kind_cases = Counter(k for r in results for k in _kinds(r))
    kind_failed = Counter(k for r in failed for k in _kinds(r))
    lines += [f"{k:<14} {kind_cases[k]:>6} {kind_failed[k]:>6}" for k in (*FAULT_KINDS, "none") if kind_cases[k]]
    props = Counter(f["property"] for r in failed for f in r["failures"])
    if props:
        lines += ["", f"{'property failed':<26} {'cases':>6}"]
        lines += [f"{p:<26} {c:>6}" for p, c in props.most_common()]
        lines += ["", "failures (what, when, who):"]
        for r in sorted(failed, key=lambda r: r["index"]):
            for f in r["failures"]:
                v = f["violations"][0]
                when = "" if v["when"] is None else f" at {v['when']:.3f} s"
                who = f" [{', '.join(v['who'])}]" if v["who"] else ""
                what = v["what"].splitlines()[0]
                lines.append(f"  case {r['index']} ({r['family']}): {f['property']}{when}{who}: {what}")
                if r.get("replay"):
                    lines.append(f"    replay: {r['replay']}")
    return "\n".join(lines)


def write_json(path: Path, meta: dict[str, Any], results: list[dict[str, Any]]) -> None:
    """Every case's seed, index, family, digest, verdicts and times, sorted by index."""
    path.write_text(json.dumps({**meta, "cases": sorted(results, key=lambda r: r["index"])}, indent=1) + "\n")


def plot(path: Path, results: list[dict[str, Any]]) -> None:
    """Cases and failures by family and by fault kind, as two bar charts in one PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    for ax, key, names in (
        (axes[0], lambda r: [r["family"]], FAMILIES),
        (axes[1], _kinds, (*FAULT_KINDS, "none")),
    ):
        cases = Counter(k for r in results for k in key(r))
        failed = Counter(k for r in results if not r["ok"] for k in key(r))
        shown = [n for n in names if cases[n]]
        ax.bar(shown, [cases[n] for n in shown], color="#c8d6e5", label="cases")
        ax.bar(shown, [failed[n] for n in shown], color="#d63031", label="failed")
        ax.tick_params(axis="x", rotation=45)
        ax.legend()
    axes[0].set_title("by family")
    axes[1].set_title("by fault kind")
    fig.suptitle(f"petswarm explore: {sum(not r['ok'] for r in results)} of {len(results)} cases failed")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
