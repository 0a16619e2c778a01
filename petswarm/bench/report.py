"""Output of ``petswarm bench hub``: the table of figures, the JSON file and the plot."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from petswarm.lab.output import emit, save
from radio_hub.values import airtime_us


def write_results(results: dict[str, Any], out: Path) -> None:
    """``bench_hub.json`` (with raw samples) and ``bench_hub.png``."""
    save(results, out, "bench_hub", plot)


def plot(results: dict[str, Any], path: Path) -> None:
    """RTT CDFs of both paths, the per-pass excess over the model, and delivered frames/s over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rtt = results["rtt"]
    fig, (cdf, hist, thr) = plt.subplots(1, 3, figsize=(16, 4.8))
    for name, label in (
        ("plain_us", "plain zenoh echo"),
        ("radio_adjusted_us", "radio via hub, air time removed"),
        ("radio_wall_us", "radio via hub, wall"),
    ):
        _plot_cdf(cdf, rtt["samples"][name], label)
    if "floor" in results:
        _plot_cdf(cdf, results["floor"]["rtt"]["samples"]["radio_adjusted_us"], "radio via the floor hub, adjusted")
    cdf.set(xscale="log", xlabel="round trip (us)", ylabel="fraction of rounds", title="Round trip CDF")
    cdf.legend(fontsize=8)
    cdf.grid(alpha=0.3)
    excess = np.array(rtt["samples"]["txdone_excess_us"])
    top = float(np.percentile(excess, 99)) if excess.size else 1.0
    hist.hist(excess[excess <= top], bins=60, color="tab:orange")
    hub = rtt["hub"]
    hist.set(
        xlabel="send -> TxDone, wall minus model (us; up to p99)",
        ylabel="rounds",
        title=f"One pass through the hub (hub lag p50 {hub['lag_p50_us']:.0f} us, p99 {hub['lag_p99_us']:.0f} us)",
    )
    _plot_throughput(thr, results["load"] + ([results["floor"]["load"]] if "floor" in results else []))
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_cdf(ax: Any, samples: list[float], label: str) -> None:
    values = np.sort(np.array(samples))
    ax.plot(values, np.arange(1, len(values) + 1) / max(len(values), 1), label=label)


def _plot_throughput(ax: Any, loads: list[dict[str, Any]]) -> None:
    for load in loads:
        line = ax.plot([s["t_s"] for s in load["series"]], [s["fps"] for s in load["series"]], marker="o")[0]
        if load["label"] != "floor":  # the floor hub models no air: it has no capacity
            capacity = f"{load['label']}: model capacity"
            ax.axhline(load["model_capacity_fps"], ls=":", color=line.get_color(), label=capacity)
        line.set_label(f"{load['label']}: delivered")
    ax.axhline(loads[0]["target_fps"], ls="--", color="grey", label="target")
    ax.set(xlabel="s into the window", ylabel="frames/s", title=f"Delivered frames/s, {loads[0]['nodes']} nodes")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)


def report(results: dict[str, Any], as_json: bool) -> None:
    """The table on stdout; with ``as_json`` the JSON (without raw samples) on stdout and the table on stderr."""
    shown = {**results, "rtt": _without_samples(results["rtt"])}
    if "floor" in results:
        shown["floor"] = {**results["floor"], "rtt": _without_samples(results["floor"]["rtt"])}
    emit(table(results), shown, as_json)


def _without_samples(rtt: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in rtt.items() if k != "samples"}


def table(results: dict[str, Any]) -> list[str]:
    """Every figure as text lines."""
    lines = [*_settings_lines(results["settings"]), "", *_rtt_lines(results["rtt"]), "", *_load_lines(results)]
    if "floor" in results:
        lines += ["", *_floor_lines(results)]
    if "targets" in results:
        lines += ["", *_target_lines(results["targets"])]
    return lines


def _load(load: dict[str, float]) -> str:
    """A phase's 1-minute load average, at its start and its end."""
    return f"load {load['start']:.2f}->{load['end']:.2f}"


def _target_lines(targets: list[dict[str, Any]]) -> list[str]:
    lines = ["targets (each with the machine's 1-minute load average over its phase)"]
    for t in targets:
        lines.append(
            f"  {_verdict(t['pass'])}  {t['name']}: {t['value']:.2f} (target {t['target']}; {_load(t['load_average'])})"
        )
    return lines


def _settings_lines(s: dict[str, Any]) -> list[str]:
    m = s["medium"]
    return [
        f"petswarm bench hub: seed {s['seed']}, {s['rounds']} rounds (+{s['warmup_rounds']} warm-up), "
        f"{s['nodes']} nodes for {s['load_seconds']:g} s (+{s['load_warmup_s']:g} s warm-up) "
        f"from {s['load_processes']} load processes, {s['in_flight_per_sender']} sends in flight per sender, "
        f"{s['cpus']} CPUs (1-min load average {s['load_average']:.2f} at start)",
        f"medium (defaults): min_be {m['min_be']}, max_be {m['max_be']}, unit backoff {m['unit_backoff_us']} us, "
        f"CCA {m['cca_us']} us, turnaround {m['turnaround_us']} us, tx range {m['tx_range_m']:g} m, "
        f"interference {m['interference_range_m']:g} m, rx success at range edge {m['success_ratio_rx']:g}, "
        f"base loss {m['loss_base']:g}",
        f"bench frames: no-ACK unicast, nodes 1 m apart; load frames {s['load_psdu_bytes']} B PSDU "
        f"({airtime_us(s['load_psdu_bytes'])} us on air), pairs {s['pair_spacing_m']:g} m apart on channels 11-26",
    ]


def _rtt_lines(rtt: dict[str, Any]) -> list[str]:
    rows = (
        ("plain zenoh echo", "plain_us"),
        ("radio via hub, wall", "radio_wall_us"),
        ("  of which modelled air", "radio_model_us"),
        ("radio via hub, adjusted", "radio_adjusted_us"),
        ("send->TxDone beyond model", "txdone_excess_us"),
    )
    lines = [f"{'round trip (us)':<28}{'p50':>9}{'p90':>9}{'p99':>9}{'mean':>9}{'n':>7}"]
    for label, key in rows:
        p = rtt[key]
        lines.append(f"{label:<28}{p['p50']:>9.0f}{p['p90']:>9.0f}{p['p99']:>9.0f}{p['mean']:>9.0f}{p['n']:>7}")
    verdict = "PASS" if rtt["pass"] else "MISS"
    hub = rtt["hub"]
    lines += [
        f"ratio adjusted/plain p50: {rtt['ratio_p50']:.2f}  (target <= {rtt['target_ratio']:g})  {verdict}  "
        f"({_load(rtt['load_average'])})",
        f"lost rounds: plain {rtt['lost']['plain']}, radio {rtt['lost']['radio']}; hub delivery lag over the phase: "
        f"p50 {hub['lag_p50_us']:.0f} us, p99 {hub['lag_p99_us']:.0f} us ({hub['lag_samples']} samples)",
    ]
    return lines


def _floor_lines(results: dict[str, Any]) -> list[str]:
    """The floor hub's figures beside the real hub's: what is left for a faster hub to win."""
    rtt, load = results["floor"]["rtt"], results["floor"]["load"]
    real_rtt, real_load = results["rtt"], results["load"][0]
    return [
        "the floor: a hub that answers each frame the moment it arrives and models nothing (petswarm hub "
        "--floor), same nodes and generators",
        f"  round trip ratio adjusted/plain p50: {rtt['ratio_p50']:.2f} (plain {rtt['plain_us']['p50']:.0f} us, "
        f"radio {rtt['radio_adjusted_us']['p50']:.0f} us); the real hub's {real_rtt['ratio_p50']:.2f} is "
        f"{real_rtt['ratio_p50'] / rtt['ratio_p50']:.2f}x the floor  ({_load(rtt['load_average'])})",
        f"  throughput {load['frames_per_s']:.0f} frames/s, CPU per frame: hub {load['hub_cpu_us_per_frame']:.0f} us, "
        f"load generators {load['load_gen_cpu_us_per_frame']:.0f} us; the real hub carries "
        f"{real_load['frames_per_s'] / load['frames_per_s']:.2f}x the floor's frames/s  "
        f"({_load(load['load_average'])})",
        "  a target beyond the floor cannot be met by a faster model: the transport, the nodes' own work and "
        "the machine's CPUs set it",
    ]


def _verdict(ok: bool) -> str:
    return "PASS" if ok else "MISS"


def _load_lines(results: dict[str, Any]) -> list[str]:
    loads = results["load"]
    head = (
        f"{'throughput':<12}{'frames/s':>10}{'capacity':>10}{'util':>7}{'lag p50':>9}{'lag p99':>9}"
        f"{'hub cpu':>9}{'job thr':>9}{'gens cpu':>10}{'box busy':>10}  result"
    )
    lines = [f"throughput: {loads[0]['pairs']} sender/receiver pairs, frames delivered per second at the hub", head]
    for load in loads:
        hub = load["hub"]
        lines.append(
            f"{load['label']:<12}{load['frames_per_s']:>10.0f}{load['model_capacity_fps']:>10.0f}"
            f"{load['model_utilisation']:>7.0%}{hub['lag_p50_us']:>7.0f}us{hub['lag_p99_us']:>7.0f}us"
            f"{load['hub_cpu_pct']:>8.0f}%{load['hub_job_thread_cpu_pct']:>8.0f}%{load['load_gen_cpu_pct']:>9.0f}%"
            f"{load['machine_cpu_busy_pct']:>9.0f}%  {_verdict(load['pass'])} (target >= {load['target_fps']:.0f}/s)"
            f"  {_load(load['load_average'])}"
        )
        lines.append(
            f"{'':<12}CPU per delivered frame: hub {load['hub_cpu_us_per_frame']:.0f} us "
            f"(job thread {load['hub_job_thread_us_per_frame']:.0f} us, "
            f"world thread {load.get('hub_world_thread_us_per_frame', float('nan')):.0f} us), "
            f"load generators {load['load_gen_cpu_us_per_frame']:.0f} us (load-robust, unlike frames/s); "
            f"hub messages to nodes {load.get('hub_down_messages_per_frame', float('nan')):.2f} per frame in "
            f"{load.get('hub_down_puts_per_frame', float('nan')):.2f} puts"
        )
        lines.append(
            f"{'':<12}{load['delivered']} delivered / {load['sent']} sent in {load['window_s']:.2f} s of hub clock; "
            f"collided {load['collided']}, lost {load['lost']} since the hub started"
        )
        if load["config_file"]:
            lines.append(f"{'':<12}hub --config {load['config_file']} (mac.min_be = {load['mac']['min_be']})")
    lines.append(
        "capacity = pairs x 1e6 / mean model time per frame (backoff + CCA + turnaround + airtime); "
        "util near 100% means the model's air was the limit, well below means the hub or the generators were"
    )
    lines.append(
        "hub cpu / job thr / gens cpu: % of one core used by the hub process, its job thread and all load "
        "generators; box busy: % of all CPUs of the machine (any process) over the window"
    )
    return lines
