"""``petswarm bench ir``: accuracy of IR relative location, per estimator, with the swarm paper's protocol.

One robot transmits at the centre (the origin, heading 0); a receiving robot stands at 40-200 cm in
20 cm steps and at 0-180 degrees in 30 degree steps around it, facing ``--heading`` (0 degrees, as
placed in the paper, or ``random``: a fresh heading per measurement, so bearings fall between sectors
too); ``--runs`` sweeps (measurements) per point. Each sweep goes through the light model
(``radio_hub.physics.light``) and both estimators (``petswarm.managers.ir_estimator``) in this one process, vectorised
across all sweeps; the over-the-wire run through real processes is a separate bench.

Figures: RMSE of the distance (cm) and of the direction (degrees: the error of the estimated bearing of
the transmitter, which is also the angular error of the estimated position) per estimator, overall and
per distance. The table goes to stdout (stderr with ``--json``, which prints the JSON on stdout),
progress to stderr, ``<out>/bench_ir.json`` and ``<out>/bench_ir.png`` (true vs estimated receiver
positions for both estimators, and RMSE against distance) to disk.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from petswarm.bench import paper
from petswarm.lab.output import emit, save
from petswarm.managers.ir_estimator import METHODS, IrEstimates, estimate_many
from radio_hub.datasheet import IrConfig
from radio_hub.values import lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

DISTANCES_CM = tuple(range(40, 201, 20))
ANGLES_DEG = tuple(range(0, 181, 30))
RANDOM_HEADING = "random"


def progress(text: str) -> None:
    """Progress lines go to stderr so stdout holds only the figures (or the JSON)."""
    print(f"[bench] {text}", file=sys.stderr, flush=True)


def heading_arg(text: str) -> float | str:
    """``--heading``: degrees, or ``random``."""
    if text == RANDOM_HEADING:
        return text
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is neither degrees nor 'random'") from None


@dataclass
class IrOptions:
    """What ``petswarm bench ir`` is asked to do (its options, as a notebook gives them)."""

    runs: int = 300
    """Sweeps per point."""
    seed: int = 1
    heading: float | str = 0.0
    """Receiver heading in degrees, or ``random`` per sweep."""
    out: str = "bench-results"
    json: bool = False
    profile: str = "ideal"
    wire: bool = True
    """Also run the token cycle through real hub and robot processes."""
    wire_seconds: float = 6.0
    members: tuple[int, int] = (2, 10)
    """Swarm sizes of the token-cycle run, LOW-HIGH."""


def bench_ir(args: IrOptions) -> int:
    """Run the experiment, print the table, write JSON and plot; 0 on success."""
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    heading = getattr(args, "heading", 0.0)
    started = time.monotonic()
    profile = getattr(args, "profile", "ideal")
    results = run_experiment(args.runs, args.seed, heading, profiled_ir(profile))
    results["settings"]["profile"] = profile
    results["paper"] = paper_rows(results)
    if getattr(args, "wire", False):
        from petswarm.bench.ir_token import run_wire_benches

        low, high = args.members
        try:
            results["over_the_wire"] = run_wire_benches(args.seed, out, args.wire_seconds, range(low, high + 1))
        except (RuntimeError, KeyboardInterrupt) as err:  # BenchFailed is a RuntimeError
            print(f"petswarm bench ir: the over-the-wire runs failed: {err}", file=sys.stderr)
            return 1

    results["settings"]["elapsed_s"] = round(time.monotonic() - started, 3)
    write_results(results, out)
    report(results, args.json)
    return 0


# == the experiment ===================================================================================


def profiled_ir(profile: str) -> IrConfig:
    """The IR module as the hub emulates it under ``profile`` (its noise); the robots' calibration stays the
    datasheet's ``IrConfig()`` whatever the profile."""
    from radio_hub.hosting import profile_tables  # the hub's profiles: loaded when the bench runs, not to parse

    return dataclasses.replace(IrConfig(), **profile_tables(profile).get("ir", {})).validate()


def paper_rows(results: dict[str, Any]) -> list[dict[str, Any]]:
    """Table 4's RMSE with equations (1)-(3) beside this bench's ``paper`` estimator."""
    overall = results["methods"]["paper"]["overall"]
    return [
        paper.row("IR RMSE, distance (cm), eqs. (1)-(3)", paper.IR_RMSE["distance_cm"], overall["distance_rmse_cm"]),
        paper.row(
            "IR RMSE, direction (deg), eqs. (1)-(3)", paper.IR_RMSE["direction_deg"], overall["direction_rmse_deg"]
        ),
    ]


def run_experiment(runs: int, seed: int, heading: float | str, config: IrConfig) -> dict[str, Any]:
    """All points x ``runs`` sweeps through the light model (``config``: the module as emulated) and every
    estimator (calibrated with the datasheet's ``IrConfig()``); the summary as a dict."""
    from radio_hub.hosting import receiver_readings  # the hub's light model: loaded to run, not to parse

    rng = np.random.default_rng(seed)
    dist_m, angle_rad = _placements(runs)
    heading_rad = _headings(heading, dist_m.size, rng)
    receivers = np.column_stack([dist_m * np.cos(angle_rad), dist_m * np.sin(angle_rad), heading_rad])
    true_bearing = angle_rad + np.pi - heading_rad  # the transmitter, seen from the receiver
    progress(f"{dist_m.size} sweeps: {len(DISTANCES_CM)} distances x {len(ANGLES_DEG)} angles x {runs} runs")
    readings = receiver_readings(np.zeros((1, 3)), receivers, config, rng)
    methods = {}
    for method in METHODS:
        progress(f"estimating with {method}")
        est = estimate_many(readings, IrConfig(), method)
        methods[method] = _summary(est, dist_m, true_bearing, heading_rad, runs)
    settings = {
        "runs": runs,
        "seed": seed,
        "heading": heading,
        "distances_cm": list(DISTANCES_CM),
        "angles_deg": list(ANGLES_DEG),
        "ir": config.to_dict(),
    }
    return {"settings": settings, "methods": methods}


def _placements(runs: int) -> tuple[np.ndarray, np.ndarray]:
    """Distance (m) and angle (rad) of every sweep, point by point (distance-major), ``runs`` each."""
    d, a = np.meshgrid(np.array(DISTANCES_CM) / 100, np.radians(ANGLES_DEG), indexing="ij")
    return np.repeat(d.ravel(), runs), np.repeat(a.ravel(), runs)


def _headings(heading: float | str, count: int, rng: np.random.Generator) -> np.ndarray:
    if heading == RANDOM_HEADING:
        return rng.uniform(0, 2 * np.pi, count)
    return np.full(count, math.radians(float(heading)))


def _summary(
    est: IrEstimates,
    dist_m: np.ndarray,
    true_bearing: np.ndarray,
    heading_rad: np.ndarray,
    runs: int,
) -> dict[str, Any]:
    """RMSE overall, per distance and per point; the estimated receiver positions for the plot."""
    dist_err_cm = (est.distance_m - dist_m) * 100
    dir_err_deg = np.degrees(np.angle(np.exp(1j * (est.bearing_rad - true_bearing))))
    world = heading_rad + est.bearing_rad  # the receiver sits opposite the transmitter's bearing
    x_cm, y_cm = -est.distance_m * np.cos(world) * 100, -est.distance_m * np.sin(world) * 100
    shape = (len(DISTANCES_CM), len(ANGLES_DEG), runs)
    grid = [a.reshape(shape) for a in (dist_err_cm, dir_err_deg, est.valid)]
    per_point = [
        {"distance_cm": cm, "angle_deg": deg, **_errors(*(g[i, j] for g in grid))}
        for i, cm in enumerate(DISTANCES_CM)
        for j, deg in enumerate(ANGLES_DEG)
    ]
    per_distance = [{"distance_cm": cm, **_errors(*(g[i].ravel() for g in grid))} for i, cm in enumerate(DISTANCES_CM)]
    return {
        "overall": _errors(dist_err_cm, dir_err_deg, est.valid),
        "per_distance": per_distance,
        "per_point": per_point,
        "estimated_cm": {"x": x_cm[est.valid].tolist(), "y": y_cm[est.valid].tolist()},
    }


def _errors(dist_err_cm: np.ndarray, dir_err_deg: np.ndarray, valid: np.ndarray) -> dict[str, Any]:
    """RMSE and mean (bias) of both errors over the sweeps with an estimate, and how many had none."""
    d, a = dist_err_cm[valid], dir_err_deg[valid]
    if not d.size:
        return {"distance_rmse_cm": math.nan, "direction_rmse_deg": math.nan, "n": 0, "no_signal": int(valid.size)}
    return {
        "distance_rmse_cm": float(np.sqrt(np.mean(d**2))),
        "distance_bias_cm": float(d.mean()),
        "direction_rmse_deg": float(np.sqrt(np.mean(a**2))),
        "direction_bias_deg": float(a.mean()),
        "n": int(d.size),
        "no_signal": int(valid.size - d.size),
    }


# == output ===========================================================================================


def write_results(results: dict[str, Any], out: Path) -> None:
    """``bench_ir.json`` (summary; estimated positions only in the plot) and ``bench_ir.png``."""
    save(results, out, "bench_ir", plot, _slim(results))


def _slim(results: dict[str, Any]) -> dict[str, Any]:
    methods = {m: {k: v for k, v in s.items() if k != "estimated_cm"} for m, s in results["methods"].items()}
    return {**results, "methods": methods}


def plot(results: dict[str, Any], path: Path) -> None:
    """True vs estimated receiver positions per estimator (top), RMSE of distance and direction (bottom)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(METHODS), figsize=(6.5 * len(METHODS), 11))
    for ax, method in zip(axes[0], METHODS, strict=True):
        _plot_points(ax, method, results["methods"][method])
    _plot_rmse(axes[1][0], results, "distance_rmse_cm", "distance RMSE (cm)")
    _plot_rmse(axes[1][1], results, "direction_rmse_deg", "direction RMSE (degrees)")
    for ax, key in ((axes[1][0], "distance_cm"), (axes[1][1], "direction_deg")):
        ax.axhline(paper.IR_RMSE[key], color="black", linestyle="--", label="paper, eqs. (1)-(3), overall (Table 4)")
        ax.legend(fontsize=8)
    s = results["settings"]
    fig.suptitle(
        f"petswarm bench ir: {s['runs']} sweeps per point, heading {s['heading']}, seed {s['seed']}, "
        f"profile {s.get('profile', 'ideal')}"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_points(ax: Any, method: str, summary: dict[str, Any]) -> None:
    est = summary["estimated_cm"]
    ax.scatter(est["x"], est["y"], s=1, alpha=0.15, color="tab:blue", label="estimated", rasterized=True)
    d, a = np.meshgrid(DISTANCES_CM, np.radians(ANGLES_DEG))
    ax.scatter(d * np.cos(a), d * np.sin(a), marker="x", color="black", s=25, label="true")
    ax.scatter([0], [0], marker="*", color="tab:red", s=120, label="transmitter")
    o = summary["overall"]
    ax.set(
        xlabel="x (cm)",
        ylabel="y (cm)",
        title=f"{method}: RMSE {o['distance_rmse_cm']:.1f} cm, {o['direction_rmse_deg']:.2f} deg",
    )
    ax.set(xlim=(-240, 240), ylim=(-70, 240))
    ax.set_aspect("equal")
    legend = ax.legend(fontsize=8, loc="upper left")
    legend.legend_handles[0].set_sizes([12])
    legend.legend_handles[0].set_alpha(1)
    ax.grid(alpha=0.3)


def _plot_rmse(ax: Any, results: dict[str, Any], key: str, label: str) -> None:
    for method in METHODS:
        rows = results["methods"][method]["per_distance"]
        ax.plot([r["distance_cm"] for r in rows], [r[key] for r in rows], marker="o", label=method)
    ax.set(xlabel="true distance (cm)", ylabel=label, title=label + " per distance")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)


def report(results: dict[str, Any], as_json: bool) -> None:
    """The table on stdout; with ``as_json`` the JSON on stdout and the table on stderr."""
    emit(table(results), _slim(results), as_json)


def table(results: dict[str, Any]) -> list[str]:
    """Every figure as text lines: settings, then RMSE per distance and overall for each estimator."""
    s, methods = results["settings"], results["methods"]
    ir = s["ir"]
    lines = [
        f"petswarm bench ir: {s['runs']} sweeps per point, {len(s['distances_cm'])} distances x "
        f"{len(s['angles_deg'])} angles, receiver heading {s['heading']}, seed {s['seed']}",
        f"IR module: {ir['power_counts_at_1m']:g} counts at 1 m (inverse square), range {ir['max_range_m']:g} m, "
        f"noise {ir['relative_noise']:.0%} + {ir['noise_floor_counts']:g} counts, ambient {ir['ambient_counts']:g}, "
        f"full scale {ir['saturation_counts']:g}",
        "",
        f"{'':>9}" + "".join(f"{m + ' dist cm':>15}{m + ' dir deg':>15}" for m in METHODS),
    ]
    rows = zip(*(methods[m]["per_distance"] for m in METHODS), strict=True)
    for group in rows:
        lines.append(f"{group[0]['distance_cm']:>6} cm" + "".join(_cells(r) for r in group))
    lines.append(f"{'overall':>9}" + "".join(_cells(methods[m]["overall"]) for m in METHODS))
    missed = {m: methods[m]["overall"]["no_signal"] for m in METHODS}
    lines.append("RMSE of distance (cm) and direction (degrees); sweeps without an estimate: " + str(missed))
    if "paper" in results:
        lines += ["", *paper.lines(results["paper"], s.get("profile", "ideal"))]
    wire = results.get("over_the_wire")
    if wire:
        from petswarm.bench.ir_token import wire_lines

        lines += wire_lines(wire["wire"], wire["token_cycle"])
    return lines


def _cells(row: dict[str, Any]) -> str:
    return f"{row['distance_rmse_cm']:>15.2f}{row['direction_rmse_deg']:>15.2f}"


def members_range(text: str) -> tuple[int, int]:
    try:
        low, high = (int(p) for p in text.split("-"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a range LOW-HIGH such as 2-10") from None
    if not 2 <= low <= high <= 32:
        raise argparse.ArgumentTypeError("swarm sizes must satisfy 2 <= LOW <= HIGH <= 32")
    return low, high
