"""``petswarm report RUN``: read a run record, print its summary, render its plots to PNG.

Works on a finished run and on one that was killed midway (no summary: the events still tell the story).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from cli.records import read_events

STATE_COLOURS = {
    "waiting": "#bbbbbb",
    "following": "#4c72b0",
    "leading": "#55a868",
    "remote-control": "#8172b2",
    "organizing": "#dd8452",
    "master-driving": "#c44e52",
    "slave-driving": "#da8bc3",
}


def report_command(args: argparse.Namespace) -> int:
    """Print and plot one run record; 2 when the directory is not a run record."""
    run = Path(args.run)
    if not (run / "manifest.json").exists():
        print(f"petswarm report: {run} is not a run record (no manifest.json)", file=sys.stderr)
        return 2
    manifest = json.loads((run / "manifest.json").read_text())
    summary_file = run / "summary.json"
    summary = json.loads(summary_file.read_text()) if summary_file.exists() else None
    events = {p.stem: read_events(p) for p in sorted((run / "events").glob("*.jsonl"))}
    for line in describe(manifest, summary, events):
        print(line)
    out = Path(args.out) if args.out else run
    out.mkdir(parents=True, exist_ok=True)
    plot(summary, events, out / "report.png")
    print(f"plots: {out / 'report.png'}")
    return 0


def describe(manifest: dict[str, Any], summary: dict[str, Any] | None, events: dict[str, list]) -> list[str]:
    """The run in text: what was asked, how it ended, what each robot went through."""
    opts = manifest["options"]
    lines = [
        f"run of {manifest['started']}: {opts['robots']} robots, seed {manifest['seed']}, "
        f"world {manifest['world']}, petswarm {manifest['versions'].get('petswarm')}"
    ]
    if summary is None:
        lines.append("no summary: the run was killed before it finished; the events below are all there is")
    else:
        verdict = "OK" if summary.get("ok") else "PROBLEMS: " + "; ".join(summary.get("problems", []))
        lines.append(verdict)
        for name, n in summary.get("nodes", {}).items():
            lines.append(
                f"  {name:<10} sent {n['sent']:>5}  delivered {n['delivered']:>5}  collided {n['collided']:>5}"
                f"  lost {n['lost']:>4}  retries {n['mac_retries']:>4}"
            )
        organized = summary.get("organization")
        if organized and "members" in organized:
            lines.append(
                f"  swarm: members {organized['members']} in {organized['organize_time_s'] * 1000:.1f} ms, "
                f"{organized['retries']} retries"
            )
    for name, evs in events.items():
        states = [e["to"] for e in evs if e["kind"] == "state"]
        last = evs[-1]["kind"] if evs else "nothing"
        lines.append(f"  {name:<10} {len(evs):>5} events; states {' -> '.join(states) or '(none)'}; last: {last}")
    return lines


def plot(summary: dict[str, Any] | None, events: dict[str, list], path: Path) -> None:
    """Each robot's states over time and, when the run finished, the radio statistics per node."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (timeline, radio) = plt.subplots(1, 2, figsize=(14, 0.6 * max(len(events), 3) + 2.5))
    _plot_states(timeline, events)
    _plot_radio(radio, summary)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_states(ax: Any, events: dict[str, list]) -> None:
    t0 = min((evs[0]["t"] for evs in events.values() if evs), default=0.0)
    t_end = max((evs[-1]["t"] for evs in events.values() if evs), default=t0 + 1)
    for row, evs in enumerate(events.values()):
        spans = _state_spans(evs, t_end)
        for start, stop, state in spans:
            ax.barh(row, stop - start, left=start - t0, color=STATE_COLOURS.get(state, "#999999"), edgecolor="none")
    ax.set_yticks(range(len(events)), list(events))
    handles = [matplotlib_patch(c, s) for s, c in STATE_COLOURS.items()]
    ax.legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    ax.set(xlabel="s since the first event", title="robot states")


def _state_spans(evs: list[dict[str, Any]], t_end: float) -> list[tuple[float, float, str]]:
    start = next((e for e in evs if e["kind"] == "start"), None)
    if start is None:
        return []
    spans, since, state = [], start["t"], start.get("state", "waiting")
    for e in evs:
        if e["kind"] == "state":
            spans.append((since, e["t"], state))
            since, state = e["t"], e["to"]
    end = evs[-1]["t"] if evs[-1]["kind"] == "stop" else t_end
    spans.append((since, end, state))
    return spans


def _plot_radio(ax: Any, summary: dict[str, Any] | None) -> None:
    if not summary or not summary.get("nodes"):
        ax.text(0.5, 0.5, "no summary (run killed)", ha="center", va="center")
        ax.set_axis_off()
        return
    names = list(summary["nodes"])
    keys = ("sent", "delivered", "collided", "lost", "mac_retries")
    width = 0.8 / len(keys)
    for i, key in enumerate(keys):
        ax.bar([x + i * width for x in range(len(names))], [summary["nodes"][n][key] for n in names], width, label=key)
    ax.set_xticks([x + 0.4 - width / 2 for x in range(len(names))], names, rotation=30)
    ax.legend(fontsize=8)
    ax.set(title="radio per node (frames)")


def matplotlib_patch(colour: str, label: str) -> Any:
    """A legend swatch."""
    from matplotlib.patches import Patch

    return Patch(color=colour, label=label)
