"""``petswarm report RUN``: read a run record, print its summary, render its plots to PNG.

Works on a finished run and on one that was killed midway (only the summary it wrote while running, or
none: the events still tell the story).
A scenario run also leaves the hub's ground truth (``world.jsonl``); from it come the driving figures, the
bodies' paths (``trajectories.png``) and each slave's formation error over time (``formation_error.png``); a
surround run (robots in IR beacon mode round a user) also gets the swarm and its human at six instants
(``surround_snapshots.png``, as the surround paper's Fig. 8).
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from petswarm.lab.metrics import describe_driving, driving_metrics, read_world, rotation_starts
from petswarm.lab.palette import OUTCOME_COLOURS, STATE_COLOURS
from petswarm.lab.records import read_events
from petswarm.lab.supervision import verdict
from petswarm.lab.surround_plots import is_surround_run, plot_snapshots


@dataclass
class ReportOptions:
    """What ``petswarm report`` is asked to do."""

    run: str
    """A run record directory."""
    out: str | None = None
    """Directory for the plots (None: the run directory)."""
    json: bool = False


def report_command(args: ReportOptions) -> int:
    """Print and plot one run record (``--json``: its figures and the plots' paths as JSON); 2 when the
    directory is not a run record."""
    run = Path(args.run)
    if not (run / "manifest.json").exists():
        print(f"petswarm report: {run} is not a run record (no manifest.json)", file=sys.stderr)
        return 2
    manifest = json.loads((run / "manifest.json").read_text())
    summary_file = run / "summary.json"
    summary = json.loads(summary_file.read_text()) if summary_file.exists() else None
    # robot-2 before robot-10: by length, then name
    files = sorted((run / "events").glob("*.jsonl"), key=lambda p: (len(p.stem), p.stem))
    events = {p.stem: read_events(p) for p in files}
    out = Path(args.out) if args.out else run
    out.mkdir(parents=True, exist_ok=True)
    plots = [out / "report.png"]
    plot(summary, events, plots[0])
    driving = None
    if (run / "world.jsonl").exists():
        driving, world_plots = plot_world(run / "world.jsonl", summary, out)
        plots += world_plots
    if getattr(args, "json", False):
        states = {name: [e["to"] for e in evs if e["kind"] == "state"] for name, evs in events.items()}
        report = {"run": str(run), "manifest": manifest, "summary": summary, "states": states}
        print(json.dumps({**report, "driving": driving, "plots": [str(p) for p in plots]}, indent=2))
        return 0
    for line in describe(manifest, summary, events):
        print(line)
    if driving is not None:
        print(describe_driving(driving) if driving else f"{run / 'world.jsonl'}: no world ticks")
    print("plots: " + ", ".join(str(p) for p in plots))
    return 0


def plot_world(world_log: Path, summary: dict[str, Any] | None, out: Path) -> tuple[dict[str, Any], list[Path]]:
    """Driving figures of a scenario run ({} without world ticks), and its trajectory and formation-error
    plots drawn in ``out`` (their paths)."""
    world = read_world(world_log)
    if not world:
        return {}, []
    driving = driving_metrics(world)
    faults = (summary or {}).get("faults") or []
    plots = [out / "trajectories.png", out / "formation_error.png"]
    plot_trajectories(world, plots[0])
    plot_formation_error(driving, rotation_starts(world), faults, plots[1])
    if is_surround_run(world):
        # the swarm and its human at a few instants, as the surround paper's Fig. 8
        name = (summary or {}).get("scenario")
        title = _snapshot_title(name if isinstance(name, str) else None)
        plots.append(plot_snapshots(world, out / "surround_snapshots.png", title=title))
    return driving, plots


def _snapshot_title(name: str | None) -> str:
    return f"{name or 'surround run'}: robots (blue), the human (red, arrow his heading), swarm centre (x)"


def describe(manifest: dict[str, Any], summary: dict[str, Any] | None, events: dict[str, list]) -> list[str]:
    """The run in text: what was asked, how it ended, what each robot went through."""
    opts = manifest["options"]
    lines = [
        f"run of {manifest['started']}: {opts['robots']} robots, seed {manifest['seed']}, "
        f"world {manifest['world']}, petswarm {manifest['versions'].get('petswarm')}"
    ]
    if summary is None:
        lines.append("no summary: the run was killed before it finished; the events below are all there is")
    elif summary.get("running"):
        lines.append(
            f"the run was killed before it finished, {summary.get('elapsed_s', 0):g} s in (its last summary was "
            "written while it ran); the events below tell the rest"
        )
    else:
        lines.append(verdict({"problems": [], **summary, "ok": bool(summary.get("ok"))}))
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
    for death in (summary or {}).get("deaths", []):
        lines.append(f"  {death['process']} died during the run ({death['cause']}, {death['elapsed_s']:g} s in)")
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
        values = [summary["nodes"][n][key] for n in names]
        ax.bar([x + i * width for x in range(len(names))], values, width, label=key, color=OUTCOME_COLOURS[key])
    ax.set_xticks([x + 0.4 - width / 2 for x in range(len(names))], names, rotation=30)
    ax.legend(fontsize=8)
    ax.set(title="radio per node (frames)")


HEADING_EVERY_S = 3.0
"""Heading arrows this far apart in model time: a few per path at walking speed (~1.5 m), not a hedge."""
HEADING_MIN_MOVE_M = 0.3
"""...and only once the body has moved two robot diameters since the last arrow, so they do not pile up."""
REFERENCE_EVERY_S = 0.5
"""A slave's reference drawn twice a second: dense enough to read as a track, faint enough not to hide the path."""
USER_COLOUR = "#000000"


def plot_trajectories(world: list[dict[str, Any]], path: Path) -> None:
    """Every body's path over the obstacles: the user in black, robots coloured, the master starred."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(9, 8))
    draw_trajectories(ax, world)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_formation_error(
    driving: dict[str, Any], turn_starts: list[float], faults: list[dict[str, Any]], path: Path
) -> None:
    """Each slave's distance from its reference over time, with the user's turns and the faults marked."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(11, 4.5))
    for node, series in driving.get("formation_error_series", {}).items():
        if series:
            t, err = zip(*series, strict=True)
            ax.plot(t, err, lw=1.2, color=robot_colour(node), label=_name("robot", node))
    for i, t0 in enumerate(turn_starts):
        ax.axvline(t0, color="#555555", ls="--", lw=0.8, label="user turns" if i == 0 else None)
    for i, fault in enumerate(faults):
        ax.axvline(float(fault.get("at", 0.0)), color="#c44e52", ls=":", lw=1.2, label="faults" if i == 0 else None)
    if not driving.get("formation_error_series"):
        ax.text(0.5, 0.5, "no slave had a reference", ha="center", va="center", transform=ax.transAxes)
    ax.set_ylim(bottom=0.0)  # a distance: its zero is the formation held
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")
    ax.set(xlabel="model time (s)", ylabel="distance from reference (m)", title="formation error per slave")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def draw_trajectories(ax: Any, world: list[dict[str, Any]]) -> None:
    """The paths on ``ax``, with a legend that names every body and every marker drawn on a path."""
    paths = _paths(world)
    _draw_obstacles(ax, next((t["obstacles"] for t in reversed(world) if t.get("obstacles")), []))
    for (kind, node), ticks in sorted(paths.items(), key=lambda kv: (kv[0][0] != "user", len(kv[0][1]), kv[0][1])):
        _draw_path(ax, kind, node, ticks, USER_COLOUR if kind == "user" else robot_colour(node))
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    bodies, _ = ax.get_legend_handles_labels()
    ax.legend(handles=[*bodies, *_marker_handles()], fontsize=8, loc="best")
    ax.set(xlabel="x east (m)", ylabel="y north (m)", title="paths")


def _marker_handles() -> list[Any]:
    """Legend entries for the markers every path carries, in grey: each path draws them in its own colour."""
    from matplotlib.lines import Line2D

    grey = "#666666"
    return [
        Line2D([], [], ls="none", marker="o", color=grey, ms=6, label="start"),
        Line2D([], [], ls="none", marker="s", color=grey, mec="black", ms=6, label="end"),
        Line2D([], [], ls="none", marker="*", color=grey, mec="black", ms=12, label="end, as the master"),
        Line2D([], [], ls="none", marker=r"$\rightarrow$", color=grey, ms=10, label="heading"),
        Line2D([], [], ls="none", marker="o", color=grey, alpha=0.3, ms=4, label="slave's reference"),
    ]


def _paths(world: list[dict[str, Any]]) -> dict[tuple[str, str], list[tuple[float, dict[str, Any]]]]:
    # the user and robot 1 may share the id "1": a body is its kind and its id
    paths: dict[tuple[str, str], list[tuple[float, dict[str, Any]]]] = {}
    for tick in world:
        for body in tick["bodies"]:
            paths.setdefault((body["kind"], body["id"]), []).append((tick["t_us"] / 1e6, body))
    return paths


def _draw_path(ax: Any, kind: str, node: str, ticks: list[tuple[float, dict[str, Any]]], colour: Any) -> None:
    xs = [b["x"] for _, b in ticks]
    ys = [b["y"] for _, b in ticks]
    was_master = any(b.get("role") == "master" for _, b in ticks)
    label = "user" if kind == "user" else _name(kind, node) + (" (master)" if was_master else "")
    ax.plot(xs, ys, color=colour, lw=2.2 if kind == "user" else 1.3, ls="--" if kind == "user" else "-", label=label)
    ax.plot(xs[0], ys[0], "o", color=colour, ms=6)
    ax.plot(xs[-1], ys[-1], "*" if was_master else "s", color=colour, ms=14 if was_master else 6, mec="black")
    arrows = [*_every(ticks, HEADING_EVERY_S, HEADING_MIN_MOVE_M), ticks[-1]]
    ax.quiver(
        [b["x"] for _, b in arrows],
        [b["y"] for _, b in arrows],
        [math.cos(b["yaw"]) for _, b in arrows],
        [math.sin(b["yaw"]) for _, b in arrows],
        color=colour,
        angles="xy",
        scale_units="xy",
        scale=5.0,
        width=0.003,
    )
    refs = [b["reference"] for _, b in _every(ticks, REFERENCE_EVERY_S) if b.get("reference") is not None]
    if refs:
        ax.scatter([r[0] for r in refs], [r[1] for r in refs], s=8, color=colour, alpha=0.3, lw=0)


def robot_colour(node: str) -> Any:
    """The same colour for a robot in every plot: tab10 by the number in its id ("robot-2" and "2" alike)."""
    import matplotlib

    digits = "".join(c for c in node if c.isdigit())
    index = int(digits) - 1 if digits else sum(map(ord, node))
    return matplotlib.colormaps["tab10"](index % 10)


def _name(kind: str, node: str) -> str:
    # hubs name robots "2" or "robot-2"; the plots say "robot-2" either way
    return node if node.startswith(kind) else f"{kind}-{node}"


def _every(
    ticks: list[tuple[float, dict[str, Any]]], period_s: float, min_move_m: float = 0.0
) -> list[tuple[float, dict[str, Any]]]:
    # a body standing still would pile arrows on one spot: the next one also waits until it has moved
    kept: list[tuple[float, dict[str, Any]]] = []
    for t, body in ticks:
        last = kept[-1][1] if kept else None
        if last is None or (
            t >= kept[-1][0] + period_s and math.hypot(body["x"] - last["x"], body["y"] - last["y"]) >= min_move_m
        ):
            kept.append((t, body))
    return kept


def _draw_obstacles(ax: Any, obstacles: list[dict[str, Any]]) -> None:
    from matplotlib.patches import Circle, Rectangle

    style = {"facecolor": "#cccccc", "edgecolor": "#666666"}
    for ob in obstacles:
        if ob["kind"] == "circle":
            ax.add_patch(Circle((ob["x"], ob["y"]), ob["r"], **style))
        elif ob["kind"] == "rect":
            x0, y0 = min(ob["x0"], ob["x1"]), min(ob["y0"], ob["y1"])
            ax.add_patch(Rectangle((x0, y0), abs(ob["x1"] - ob["x0"]), abs(ob["y1"] - ob["y0"]), **style))
        elif ob["kind"] == "wall":
            ax.plot([ob["x0"], ob["x1"]], [ob["y0"], ob["y1"]], color="#444444", lw=3)


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def matplotlib_patch(colour: str, label: str) -> Any:
    """A legend swatch."""
    from matplotlib.patches import Patch

    return Patch(color=colour, label=label)
