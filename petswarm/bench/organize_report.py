"""Output of ``petswarm bench organize``: the summary per protocol and slave count, the table, JSON and plot."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from petswarm.bench import paper
from petswarm.lab.output import emit, save

STEPS = ("scan", "query", "notice")
BROADCAST = 0xFFFF
MASTER = 1
MAX_ODD_LINES = 30


# == summary ==========================================================================================


def summarise(records: list[dict[str, Any]], protocols: tuple[str, ...], counts: list[int]) -> list[dict[str, Any]]:
    """One row per (protocol, slave count): organizing times, retry probability, failures."""
    return [
        summary_row([r for r in records if r["protocol"] == protocol and r["slaves"] == n], protocol, n)
        for n in counts
        for protocol in protocols
    ]


def summary_row(records: list[dict[str, Any]], protocol: str, slaves: int) -> dict[str, Any]:
    """Times (ms) over the complete organizations; retry figures over every organization that answered."""
    ok = [r for r in records if r["ok"]]
    complete = [r for r in ok if r["complete"]]
    no_retry = [r["organize_time_s"] * 1000 for r in complete if not r["retries"]]
    dispersals = [r["dispersal"] for r in records if r["dispersal"] and r["dispersal"]["ok"]]
    return {
        "protocol": protocol,
        "slaves": slaves,
        "runs": len(records),
        "failed": len(records) - len(ok),
        "incomplete": len(ok) - len(complete),
        "short": len(ended_short(records)),
        "scan_missed": sum(1 for r in ok if len(r["candidates"] or ()) < slaves),
        "time_ms": stats_ms([r["organize_time_s"] * 1000 for r in complete]),
        "min_no_retry_ms": min(no_retry) if no_retry else math.nan,
        "retry_probability": sum(1 for r in ok if r["retries"]) / len(ok) if ok else math.nan,
        "mean_retries": float(np.mean([r["retries"] for r in ok])) if ok else math.nan,
        "retries_by_step": {s: sum(r["step_retries"].get(s, 0) for r in ok) for s in STEPS},
        "organizations_retried_by_step": {s: sum(1 for r in ok if r["step_retries"].get(s, 0)) for s in STEPS},
        "disperse_retries": sum(d["retries"] for d in dispersals),
        "disperse_failed": sum(1 for r in records if r["dispersal"] and not r["dispersal"]["ok"]),
        "unsettled": sum(1 for r in records if not r["settle"]["ok"]),
        "errors": sorted({r["error"] for r in records if not r["ok"]}),
    }


def paper_rows(summary: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Fig. 22's minimum organizing time beside this bench's fastest organization without a retry, per slave
    count the paper measured (the paper's protocol only)."""
    rows = []
    for r in summary:
        if r["protocol"] != "paper" or r["slaves"] not in paper.ORGANIZE_MIN_S:
            continue
        fastest = r["min_no_retry_ms"] / 1000 if not math.isnan(r["min_no_retry_ms"]) else None
        figure = f"organizing time, min, {r['slaves']} slave(s) (s)"
        rows.append(paper.row(figure, paper.ORGANIZE_MIN_S[r["slaves"]], fastest))
    return rows


def ended_short(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Organizations that ended with fewer members than requested although as many robots were waiting."""
    return [
        r
        for r in records
        if r["ok"] and len(r["members"] or ()) < r["slaves"] and r.get("waiting_before", r["slaves"]) >= r["slaves"]
    ]


def stats_ms(values: list[float]) -> dict[str, float]:
    """Mean, min, p50, max and count."""
    if not values:
        return {"mean": math.nan, "min": math.nan, "p50": math.nan, "max": math.nan, "n": 0}
    a = np.array(values)
    return {
        "mean": float(a.mean()),
        "min": float(a.min()),
        "p50": float(np.median(a)),
        "max": float(a.max()),
        "n": int(a.size),
    }


def rows_by(summary: list[dict[str, Any]]) -> dict[tuple[str, int], dict[str, Any]]:
    """The summary keyed by (protocol, slaves)."""
    return {(row["protocol"], row["slaves"]): row for row in summary}


# == files ============================================================================================


def write_results(results: dict[str, Any], out: Path) -> None:
    """``bench_organize.json`` (settings, summary, the paper's figures beside, every run's raw figures) and
    ``bench_organize.png``."""
    results["paper"] = paper_rows(results["summary"])
    save(results, out, "bench_organize", plot)


def plot(results: dict[str, Any], path: Path) -> None:
    """Organizing time vs slaves with min-max bars per protocol, and the retry probability per slave count."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = results["settings"]
    fig, (times, retries) = plt.subplots(1, 2, figsize=(12, 4.8))
    _plot_times(times, results["summary"], s["protocols"], s["slaves"])
    _plot_retries(retries, results["summary"], s["protocols"], s["slaves"])
    fig.suptitle(
        f"petswarm bench organize: {s['runs']} organizations per point, MAC ACK {s['mac_ack']}, "
        f"step deadline {s['step_deadline_s'] * 1000:g} ms x {s['step_retries']} retries, seed {s['seed']}, "
        f"profile {s.get('profile', 'ideal')}",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _offsets(protocols: list[str]) -> dict[str, float]:
    width = 0.8 / max(len(protocols), 1)
    return {p: (k - (len(protocols) - 1) / 2) * width for k, p in enumerate(protocols)}


def _plot_times(ax: Any, summary: list[dict[str, Any]], protocols: list[str], counts: list[int]) -> None:
    rows = rows_by(summary)
    for protocol, dx in _offsets(protocols).items():
        t = [rows[(protocol, n)]["time_ms"] for n in counts]
        mean = np.array([x["mean"] for x in t])
        low = mean - np.array([x["min"] for x in t])
        high = np.array([x["max"] for x in t]) - mean
        x = np.array(counts) + dx * 0.3
        ax.errorbar(x, mean, yerr=[low, high], marker="o", capsize=5, label=f"{protocol}: mean, min-max")
    known = [n for n in counts if n in paper.ORGANIZE_MIN_S]
    if known:
        minima = [paper.ORGANIZE_MIN_S[n] * 1000 for n in known]
        ax.plot(known, minima, "k*", markersize=10, label="paper, min (Fig. 22)")
        mins = [rows[("paper", n)]["min_no_retry_ms"] for n in known if ("paper", n) in rows]
        if len(mins) == len(known):
            ax.plot(known, mins, "v", color="tab:blue", label="paper protocol here, min without retry")
    ax.set(xlabel="number of slaves", ylabel="organizing time (ms)", title="Network-organizing time")
    ax.set_xticks(counts)
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)


def _plot_retries(ax: Any, summary: list[dict[str, Any]], protocols: list[str], counts: list[int]) -> None:
    rows = rows_by(summary)
    width = 0.8 / max(len(protocols), 1)
    top = 0.0
    for protocol, dx in _offsets(protocols).items():
        prob = np.nan_to_num([rows[(protocol, n)]["retry_probability"] for n in counts])
        bars = ax.bar(np.array(counts) + dx, prob, width=width, label=protocol)
        ax.bar_label(bars, labels=[f"{p:.2f}" for p in prob], fontsize=7)
        top = max(top, float(prob.max(initial=0.0)))
    ax.set(xlabel="number of slaves", ylabel="fraction of organizations with a retry", title="Retry probability")
    ax.set_xticks(counts)
    ax.set_ylim(0, min(1.1, max(0.25, top * 1.25)))
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, axis="y")


# == table ============================================================================================


def report(results: dict[str, Any], as_json: bool) -> None:
    """The table on stdout; with ``as_json`` the JSON (without the raw runs) on stdout and the table on stderr."""
    emit(table(results), {k: v for k, v in results.items() if k != "runs"}, as_json)


def table(results: dict[str, Any]) -> list[str]:
    """Every figure as text lines."""
    s = results["settings"]
    return [
        *_settings_lines(s),
        "",
        *_time_lines(results["summary"], s["protocols"], s["slaves"]),
        "",
        *_retry_lines(results["summary"], s["protocols"], s["slaves"]),
        "",
        *_hub_lines(results["hub"]),
        "",
        *odd_lines(results["runs"]),
        "",
        *(paper.lines(results["paper"], s.get("profile", "ideal")) if results.get("paper") else []),
        f"wall time {results['elapsed_s']:.1f} s; raw figures of every run in {results['files']['json']}",
    ]


def _settings_lines(s: dict[str, Any]) -> list[str]:
    m = s["medium"]
    step = "robot defaults" if s["step_defaults"] else "given"
    return [
        f"petswarm bench organize: seed {s['seed']}, {s.get('clock', 'wall')} time, profile "
        f"{s.get('profile', 'ideal')}, {s['runs']} organizations "
        "per protocol and slave count "
        f"(protocols interleaved run by run: {', '.join(s['protocols'])}), slaves {_counts(s['slaves'])}, "
        f"MAC ACK {s['mac_ack']}",
        f"organizing steps: deadline {s['step_deadline_s'] * 1000:g} ms, {s['step_retries']} retries ({step}); "
        f"slotted protocol slot {s['slot_ms']} ms; {s['pause_s']:g} s pause after each disperse; "
        f"{s['cpus']} CPUs (1-min load average {s['load_average']:.2f} at start)",
        f"medium: ACK {'on' if m['ack_enabled'] else 'off'}, min_be {m['min_be']}, max_be {m['max_be']}, "
        f"max CSMA backoffs {m['max_csma_backoffs']}, max frame retries {m['max_frame_retries']}, "
        f"ACK wait {m['ack_wait_us']} us, tx range {m['tx_range_m']:g} m, rx success at range edge "
        f"{m['success_ratio_rx']:g}, shadowing {m['shadowing_sigma_db']:g} dB, base loss {m['loss_base']:g}",
    ]


def _counts(counts: list[int]) -> str:
    if counts == list(range(counts[0], counts[-1] + 1)) and len(counts) > 1:
        return f"{counts[0]}-{counts[-1]}"
    return ",".join(str(n) for n in counts)


def _block_header(protocols: list[str], width: int) -> str:
    return (f"{'':<7}" + "".join(f" | {p:^{width}}" for p in protocols)).rstrip()


def _protocol_table(
    title: str, head: str, cell: Any, summary: list[dict[str, Any]], protocols: list[str], counts: list[int]
) -> list[str]:
    """A table with one block of ``head`` columns per protocol and one line per slave count."""
    rows = rows_by(summary)
    lines = [title, _block_header(protocols, len(head)), f"{'slaves':<7}" + "".join(f" | {head}" for _ in protocols)]
    for n in counts:
        lines.append(f"{n:<7}" + "".join(f" | {cell(rows[(p, n)])}" for p in protocols))
    return lines


def _time_cell(r: dict[str, Any]) -> str:
    t = r["time_ms"]
    return (
        f"{t['mean']:>7.1f}{t['min']:>7.1f}{t['p50']:>7.1f}{t['max']:>7.1f}"
        f"{r['retry_probability']:>9.2f}{r['mean_retries']:>8.2f}"
    )


def _retry_cell(r: dict[str, Any]) -> str:
    by_step = "/".join(str(r["retries_by_step"][s]) for s in STEPS)
    orgs = "/".join(str(r["organizations_retried_by_step"][s]) for s in STEPS)
    return (
        f"{by_step:>14}{orgs:>12}{r['incomplete']:>8}{r['short']:>6}{r['failed']:>7}{r['unsettled']:>10}"
        f"{r['disperse_retries']:>9}"
    )


def _time_lines(summary: list[dict[str, Any]], protocols: list[str], counts: list[int]) -> list[str]:
    head = f"{'mean':>7}{'min':>7}{'p50':>7}{'max':>7}{'P(retry)':>9}{'retries':>8}"
    title = "organizing time (ms, over complete organizations) and retries (per organization that answered)"
    return _protocol_table(title, head, _time_cell, summary, protocols, counts)


def _retry_lines(summary: list[dict[str, Any]], protocols: list[str], counts: list[int]) -> list[str]:
    head = (
        f"{'retries s/q/n':>14}{'orgs s/q/n':>12}{'incompl':>8}{'short':>6}{'failed':>7}{'unsettled':>10}"
        f"{'disp rtr':>9}"
    )
    title = (
        "where the retries were (scan/query/notice: retries in total, organizations with one), incomplete "
        "organizations, short ones (incomplete although enough robots waited), failed commands, robots not "
        "back in 5 s, dispersal retries"
    )
    lines = _protocol_table(title, head, _retry_cell, summary, protocols, counts)
    short, runs = sum(r["short"] for r in summary), sum(r["runs"] for r in summary)
    lines.append(f"ended short of the requested count while enough robots waited: {short} of {runs} organizations")
    errors = sorted({e for r in summary for e in r["errors"]})
    return lines + [f"error: {e}" for e in errors]


def _hub_lines(hub: dict[str, Any]) -> list[str]:
    lines = ["hub counters per slave count, summed over the robots (both protocols, organizing and dispersing)"]
    lines.append(
        f"{'slaves':<7}{'sent':>7}{'delivered':>10}{'collided':>9}{'lost':>6}{'mac rtr':>8}{'no ack':>7}"
        f"{'cca fail':>9}{'lag p50':>9}{'lag p99':>9}{'gaps':>6}"
    )
    for n, h in hub.items():
        c, lag = h["robots"], h["hub"]
        lines.append(
            f"{n:<7}{c.get('sent', 0):>7}{c.get('delivered', 0):>10}{c.get('collided', 0):>9}{c.get('lost', 0):>6}"
            f"{c.get('mac_retries', 0):>8}{c.get('no_ack', 0):>7}{c.get('channel_access_failures', 0):>9}"
            f"{lag['lag_p50_us']:>7.0f}us{lag['lag_p99_us']:>7.0f}us{lag['transport_gaps']:>6}"
        )
    return lines


# == odd runs =========================================================================================


def odd_lines(records: list[dict[str, Any]]) -> list[str]:
    """One line per failed, incomplete, retried or unsettled organization, with what the hub saw."""
    lines = []
    for r in records:
        tag = f"{r['protocol']}, {r['slaves']} slave(s), run {r['run']}"
        if not r["ok"]:
            lines.append(f"{tag}: failed: {r['error']}")
        elif not r["complete"]:
            lines.append(f"{tag}: incomplete, members {r['members']}: {why_incomplete(r)}")
        elif r["retries"]:
            steps = ", ".join(f"{k} {v}" for k, v in r["step_retries"].items() if v)
            lines.append(f"{tag}: retried ({steps}); gave up or lost: {mac_failures(r.get('evidence') or {})}")
        dispersal = r["dispersal"]
        if dispersal and not dispersal["ok"]:
            lines.append(f"{tag}: disperse failed: {dispersal['error']}")
        elif dispersal and dispersal["retries"]:
            found = dispersal.get("evidence") or {}
            lines.append(f"{tag}: disperse retried {dispersal['retries']}x; gave up or lost: {mac_failures(found)}")
        if not r["settle"]["ok"]:
            lines.append(f"{tag}: not back after {r['settle']['settle_s']:g} s: {r['settle']['stuck']}")
    if not lines:
        return ["odd organizations: none (no failure or retry, every organization complete, every robot back)"]
    more = [f"... and {len(lines) - MAX_ODD_LINES} more in the JSON"] if len(lines) > MAX_ODD_LINES else []
    head = "odd organizations (failed, incomplete, retried; dispersals retried; robots not back)"
    return [head, *lines[:MAX_ODD_LINES], *more]


def mac_failures(found: dict[str, Any]) -> str:
    """Robots whose MAC gave up on a frame (no ACK after every retry, no clear channel) or lost a reception
    (a lost broadcast is never retried by the MAC)."""
    parts, collided = [], []
    for name, gained in sorted(found.get("mac", {}).items()):
        failed = {k: v for k, v in gained.items() if k in ("no_ack", "channel_access_failures", "lost")}
        if failed:
            parts.append(f"{name} " + ", ".join(f"{k} {v}" for k, v in failed.items()))
        if gained.get("collided"):
            collided.append(f"{name} {gained['collided']}")
    if parts:
        return "; ".join(parts)
    return "none; receptions collided at " + ", ".join(collided) if collided else "none"


def why_incomplete(r: dict[str, Any]) -> str:
    """Which robots the master lost at which step, and for those it never heard, what the air log shows."""
    expected = set(range(MASTER + 1, r["slaves"] + 2))
    candidates, available = set(r["candidates"] or ()), set(r["available"] or ())
    found = r.get("evidence") or {}
    parts = [f"robot {rid} {scan_fate(found, rid)}" for rid in sorted(expected - candidates)]
    if candidates - available:
        parts.append(f"no join answer from {sorted(candidates - available)} (refused: {r['refused'] or 'none'})")
    if r["missing"]:
        parts.append(f"chosen but never confirmed: {r['missing']}")
    return "; ".join(parts) or "unexplained"


def scan_fate(found: dict[str, Any], rid: int) -> str:
    """What became of the scan broadcast at robot ``rid`` and of its answers, from the hub's air log."""
    air = found.get("air", [])
    mac = found.get("mac", {}).get(f"robot-{rid}", {})
    counted = f" [its MAC over the organization: {', '.join(f'{k} {v}' for k, v in mac.items()) or 'nothing'}]"
    return _scan_fate(air, rid) + counted


def _scan_fate(air: list[dict[str, Any]], rid: int) -> str:
    sweeps = [tx for tx in air if tx["src"] == MASTER and tx["dst"] == BROADCAST and tx["type"] == "data"]
    if not sweeps:
        return "never answered the scan (no air log)"
    scan = sweeps[0]
    heard = scan["outcomes"].get(f"robot-{rid}", "out of range")
    if heard != "delivered":
        return f"never answered the scan: the scan broadcast (no ACK) was {heard} at it"
    end = sweeps[1]["start_us"] if len(sweeps) > 1 else math.inf
    replies = [
        tx["outcomes"].get(f"robot-{MASTER}", "?")
        for tx in air
        if tx["src"] == rid and tx["dst"] == MASTER and scan["end_us"] <= tx["start_us"] < end
    ]
    if not replies:
        return "heard the scan, but no reply of its went on the air before the query"
    return f"heard the scan; its reply reached the master as {'/'.join(replies)} ({len(replies)} attempts)"
