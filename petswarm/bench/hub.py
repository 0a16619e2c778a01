"""``petswarm bench hub``: what the radio hub costs over plain zenoh, and how many frames/s it carries.

One run measures, each on a fresh hub child process:

1. round trip robot -> hub -> robot against a plain zenoh echo through the same router (the hub is the
   router), interleaved round by round; the radio round trip is also given with the modelled air time
   (CSMA backoff, airtime) taken out, since that delay is the emulation's intent, not overhead;
2. frames/s delivered with ``--nodes`` attached nodes in sender/receiver pairs that each have their own
   air (pairs 1000 m apart, spread over channels 11-26), driven by a few load-generator processes,
   next to the model's own air capacity so a reader sees whether the hub or the model was the limit.

Figures go to stdout (stderr with ``--json``), progress to stderr, ``<out>/bench_hub.json`` and
``<out>/bench_hub.png`` to disk. Each figure carries the machine's 1-minute load average over its phase (a
loaded machine's figures are not a quiet one's), and ``--check`` makes the exit status say whether every
target was met (``targets``): the bench is its own watchdog. The echo node and the load generators
(``petswarm.bench.nodes``) are children started as ``python -m cli.bench_nodes echo|load ...``; the output
is ``petswarm.bench.report``.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import os
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import zenoh

from petswarm.bench.nodes import (
    IN_FLIGHT,
    PAIR_SPACING_M,
    BenchFailed,
    RttSamples,
    bench_key,
    echo_main,
    load_main,
    load_psdu_len,
    load_slices,
    ping_rounds,
)
from petswarm.bench.report import report, write_results
from petswarm.lab.processes import Supervisor, free_tcp_port, run_supervised
from radio_hub.interface import WORLD_THREAD, Keys, open_session, query_hub
from radio_hub.values import HubUnavailable, RadioError, airtime_us

MODULE = "cli.bench_nodes"
"""The children's entry (``python -m MODULE echo|load ...``): their command line is parsed in ``cli/``."""
WARMUP_ROUNDS = 20
RTT_TARGET_RATIO = 1.5
FPS_TARGET = 10000.0
"""Frames/s the hub must carry with 50 nodes, or the model's air capacity where that is lower."""
LAG_TARGET_US = 2000.0
"""The hub's delivery lag p99 over the throughput phase."""
LOAD_PROCESSES = max(2, min(4, os.cpu_count() or 2))
"""Load generators: single-threaded Python each, so more of them than CPUs only adds switching."""
LOAD_WARMUP_S = 1.0
SAMPLE_EVERY_S = 0.5
STARTUP_TIMEOUT_S = 20.0
AIR_LIMITED_SHARE = 0.85
"""Delivered frames/s at or above this share of the model's capacity means the air was the limit."""


def load_average() -> float:
    """The machine's 1-minute load average (NaN where the platform has none)."""
    try:
        return os.getloadavg()[0]
    except OSError:
        return math.nan


def progress(text: str) -> None:
    """Progress lines go to stderr so stdout holds only the figures (or the JSON)."""
    print(f"[bench] {text}", file=sys.stderr, flush=True)


def per_frame_model_us(config: dict[str, Any], psdu_len: int) -> float:
    """Mean model time per back-to-back no-ACK frame on a free channel: backoff, CCA, turnaround, airtime."""
    mac = config["mac"]
    backoff = 0.0
    if mac["csma_enabled"]:
        backoff = ((1 << mac["min_be"]) - 1) / 2 * mac["unit_backoff_us"] + mac["cca_us"]
    return backoff + mac["turnaround_us"] + airtime_us(psdu_len)


# == hubs and child process plumbing =================================================================


@dataclass
class HubRun:
    """A hub child process and the bench's client session to it."""

    name: str
    endpoint: str
    keys: Keys
    session: zenoh.Session
    pid: int

    def stats(self) -> dict[str, Any]:
        """The hub's counters (the hub answers queries between frames, so allow for a busy hub)."""
        return query_hub(self.session, self.keys.stats, timeout=5.0)


def start_hub(
    sup: Supervisor,
    name: str,
    world: str,
    seed: int,
    config: Path | None,
    profile: str = "ideal",
    floor: bool = False,
) -> HubRun:
    """Spawn ``petswarm hub`` (with ``profile``; with ``floor`` the hub that models nothing, the floor) on a
    free port and wait until it answers a stats query."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    args = ["hub", "--listen", endpoint, "--world", world, "--seed", str(seed), "--profile", profile]
    args += ["--floor"] if floor else []
    proc = sup.spawn(name, args + (["--config", str(config)] if config else []))
    deadline = time.monotonic() + STARTUP_TIMEOUT_S
    while time.monotonic() < deadline:
        check_alive(sup, [name])
        session = _answering_hub(endpoint, Keys(world))
        if session is not None:
            return HubRun(name, endpoint, Keys(world), session, proc.pid)
        time.sleep(0.1)
    raise BenchFailed(f"{name} did not come up within {STARTUP_TIMEOUT_S} s:\n{sup.log_tail(name)}")


def _answering_hub(endpoint: str, keys: Keys) -> zenoh.Session | None:
    """A client session to a hub that answers, or None while it does not (yet)."""
    try:
        session = open_session("client", endpoint)
    except HubUnavailable:
        return None
    try:
        query_hub(session, keys.stats, timeout=1.0)
    except HubUnavailable:
        session.close()
        return None
    return session


def check_alive(sup: Supervisor, names: list[str]) -> None:
    """Raise BenchFailed with its log tail if one of ``names`` has exited."""
    for name, code in sup.dead().items():
        if name in names:
            raise BenchFailed(f"{name} exited with code {code}:\n{sup.log_tail(name)}")


def wait_attached(sup: Supervisor, hub: HubRun, count: int, children: list[str]) -> None:
    """Until ``count`` nodes are attached to ``hub``."""
    deadline = time.monotonic() + STARTUP_TIMEOUT_S
    seen = -1
    while time.monotonic() < deadline:
        check_alive(sup, [hub.name, *children])
        attached = sum(1 for n in hub.stats()["nodes"].values() if n["attached"])
        if attached != seen and count > 2:
            progress(f"{attached}/{count} nodes attached")
        seen = attached
        if attached >= count:
            return
        time.sleep(0.2)
    raise BenchFailed(f"only {seen}/{count} nodes attached within {STARTUP_TIMEOUT_S} s")


def cpu_seconds(pid: int, thread: int | None = None) -> float:
    """User + system CPU time of a process (or one of its threads) from /proc; NaN where unavailable."""
    path = f"/proc/{pid}/task/{thread}/stat" if thread else f"/proc/{pid}/stat"
    try:
        fields = Path(path).read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return math.nan
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def machine_cpu() -> tuple[float, float]:
    """Busy and total CPU time of the whole machine (every CPU, every process) from /proc/stat."""
    try:
        ticks = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    except (OSError, ValueError):
        return math.nan, math.nan
    idle = ticks[3] + (ticks[4] if len(ticks) > 4 else 0)
    return float(sum(ticks) - idle), float(sum(ticks))


@contextlib.contextmanager
def stopping(sup: Supervisor, names: list[str]) -> Iterator[list[str]]:
    """Stop the named children (nodes first, hub last) when the block ends, however it ends."""
    try:
        yield names
    finally:
        sup.stop(names[1:])
        sup.stop(names[:1])


# == phase 1: round trips ============================================================================


def rtt_phase(sup: Supervisor, world: str, args: HubBenchOptions, floor: bool = False) -> dict[str, Any]:
    """Hub (``floor``: the floor's), echo child, then interleaved round trips from this process."""
    tag = "floor-" if floor else ""
    progress(f"round trips{' [floor]' if floor else ''}: starting a hub and the echo node")
    load_before = load_average()
    hub = start_hub(sup, f"hub-{tag}rtt", world, args.seed, None, floor=floor)
    with stopping(sup, [hub.name, f"{tag}echo"]):
        try:
            sup.spawn_module(f"{tag}echo", MODULE, ["echo", "--hub", hub.endpoint, "--world", world])
            wait_attached(sup, hub, 1, [f"{tag}echo"])
            progress(f"round trips: {WARMUP_ROUNDS} warm-up + {args.rounds} per path")
            samples = asyncio.run(
                ping_rounds(hub.endpoint, world, args.rounds, WARMUP_ROUNDS, lambda n: progress(f"round trip {n}"))
            )
            stats = hub.stats()
        finally:
            hub.session.close()
    return {**rtt_summary(samples, stats), "load_average": {"start": load_before, "end": load_average()}}


def percentiles(values: list[float]) -> dict[str, float]:
    """p50/p90/p99, mean and count, in the values' unit."""
    if not values:
        return {"p50": math.nan, "p90": math.nan, "p99": math.nan, "mean": math.nan, "n": 0}
    p50, p90, p99 = np.percentile(np.array(values), [50, 90, 99])
    return {"p50": float(p50), "p90": float(p90), "p99": float(p99), "mean": float(np.mean(values)), "n": len(values)}


def rtt_summary(samples: RttSamples, stats: dict[str, Any]) -> dict[str, Any]:
    """The round-trip figures and the hub's delivery lag over the phase."""
    plain = percentiles(samples.plain_us)
    adjusted = percentiles(samples.radio_adjusted_us)
    ratio = adjusted["p50"] / plain["p50"] if plain["n"] and adjusted["n"] else math.nan
    return {
        "plain_us": plain,
        "radio_wall_us": percentiles(samples.radio_wall_us),
        "radio_adjusted_us": adjusted,
        "radio_model_us": percentiles(samples.radio_model_us),
        "txdone_excess_us": percentiles(samples.txdone_excess_us),
        "ratio_p50": ratio,
        "target_ratio": RTT_TARGET_RATIO,
        "pass": bool(ratio <= RTT_TARGET_RATIO),
        "lost": {"plain": samples.lost_plain, "radio": samples.lost_radio},
        "hub": _lag(stats),
        "config": stats["config"],
        "samples": {
            "plain_us": samples.plain_us,
            "radio_wall_us": samples.radio_wall_us,
            "radio_adjusted_us": samples.radio_adjusted_us,
            "txdone_excess_us": samples.txdone_excess_us,
        },
    }


def _lag(stats: dict[str, Any]) -> dict[str, Any]:
    hub = stats["hub"]
    return {k: hub[k] for k in ("lag_p50_us", "lag_p99_us", "lag_samples", "transport_gaps", "malformed")}


# == phase 2: throughput =============================================================================


@dataclass(frozen=True)
class Snapshot:
    """Hub counters and CPU clocks at one instant."""

    stats: dict[str, Any]
    hub_cpu_s: float
    hub_job_cpu_s: float
    hub_world_cpu_s: float
    gens_cpu_s: float
    machine: tuple[float, float]

    @property
    def delivered(self) -> int:
        """Frames delivered to receivers, over every node."""
        return sum(n["delivered"] for n in self.stats["nodes"].values())

    @property
    def sent(self) -> int:
        """Frames put on the air, over every node."""
        return sum(n["sent"] for n in self.stats["nodes"].values())

    @property
    def t_s(self) -> float:
        """The hub's model clock when it answered, in seconds."""
        return float(self.stats["now_us"]) / 1e6


def snapshot(sup: Supervisor, hub: HubRun, gens: list[str]) -> Snapshot:
    """Take the hub's counters and the CPU clocks of the hub, its job thread and the generators."""
    gens_cpu = sum(cpu_seconds(sup.children[g].pid) for g in gens)
    world = world_thread(hub.pid)
    world_cpu = math.nan if world is None else cpu_seconds(hub.pid, world)
    job_cpu = cpu_seconds(hub.pid, hub.pid)
    return Snapshot(hub.stats(), cpu_seconds(hub.pid), job_cpu, world_cpu, gens_cpu, machine_cpu())


def world_thread(pid: int) -> int | None:
    """The thread id of the hub's world thread (``radio_hub.shell.hub.WORLD_THREAD``), None if not found."""
    with contextlib.suppress(OSError):
        for task in Path(f"/proc/{pid}/task").iterdir():
            with contextlib.suppress(OSError):
                if (task / "comm").read_text().strip() == WORLD_THREAD:
                    return int(task.name)
    return None


def load_phase(
    sup: Supervisor,
    world: str,
    args: HubBenchOptions,
    label: str,
    config: Path | None,
    floor: bool = False,
) -> dict[str, Any]:
    """A fresh hub (``floor``: the floor's), the load generators, a warm-up, then a measured window of
    ``load_seconds``."""
    tag = world.rsplit("-", 1)[-1]
    progress(f"throughput [{label}]: starting a hub and {args.nodes} nodes")
    load_before = load_average()
    hub = start_hub(sup, f"hub-{tag}", world, args.seed, config, floor=floor)
    gens = [f"{tag}-gen{k}" for k in range(len(load_slices(args.nodes, LOAD_PROCESSES)))]
    with stopping(sup, [hub.name, *gens]):
        try:
            for name, (first, last) in zip(gens, load_slices(args.nodes, LOAD_PROCESSES), strict=True):
                argv = ["load", "--hub", hub.endpoint, "--world", world, "--first", str(first), "--last", str(last)]
                sup.spawn_module(name, MODULE, [*argv, "--nodes", str(args.nodes)])
            wait_attached(sup, hub, args.nodes, gens)
            hub.session.put(bench_key(world, "load/go"), b"go")
            time.sleep(LOAD_WARMUP_S)
            before, series, after = measure(sup, hub, gens, args.load_seconds)
            hub.session.put(bench_key(world, "load/stop"), b"stop")
        finally:
            hub.session.close()
    summary = load_summary(label, config, args.nodes, len(gens), before, after, series)
    return {**summary, "load_average": {"start": load_before, "end": load_average()}}


def measure(
    sup: Supervisor, hub: HubRun, gens: list[str], seconds: float
) -> tuple[Snapshot, list[tuple[float, float]], Snapshot]:
    """Counters before and after ``seconds`` of load, and delivered frames/s every half second between."""
    progress(f"measuring for {seconds:g} s")
    before = last = snapshot(sup, hub, gens)
    series: list[tuple[float, float]] = []
    end = time.monotonic() + seconds
    while (left := end - time.monotonic()) > 0:
        time.sleep(min(SAMPLE_EVERY_S, left))
        check_alive(sup, [hub.name, *gens])
        now = snapshot(sup, hub, gens)
        fps = (now.delivered - last.delivered) / max(now.t_s - last.t_s, 1e-9)
        series.append((now.t_s - before.t_s, fps))
        last = now
    return before, series, last


def load_summary(
    label: str,
    config_file: Path | None,
    nodes: int,
    processes: int,
    before: Snapshot,
    after: Snapshot,
    series: list[tuple[float, float]],
) -> dict[str, Any]:
    """Frames/s, the model's capacity, the hub's lag and where the CPU went."""
    window = after.t_s - before.t_s
    config = after.stats["config"]
    frame_us = per_frame_model_us(config, load_psdu_len())
    senders = nodes // 2
    capacity = senders * 1e6 / frame_us
    fps = (after.delivered - before.delivered) / window
    target = min(FPS_TARGET, capacity)
    channels = after.stats["channels"]
    delivered = max(after.delivered - before.delivered, 1)
    return {
        "label": label,
        "config_file": str(config_file) if config_file else None,
        "mac": {k: config["mac"][k] for k in ("min_be", "max_be", "csma_enabled")},
        "nodes": nodes,
        "pairs": senders,
        "load_processes": processes,
        "window_s": window,
        "delivered": after.delivered - before.delivered,
        "sent": after.sent - before.sent,
        "frames_per_s": fps,
        "sent_per_s": (after.sent - before.sent) / window,
        "model_frame_us": frame_us,
        "model_capacity_fps": capacity,
        "model_utilisation": fps / capacity,
        "target_fps": target,
        "pass": fps >= target,
        "hub": _lag(after.stats),
        "target_lag_p99_us": LAG_TARGET_US,
        "collided": sum(c["collided"] for c in channels.values()),
        "lost": sum(c["lost"] for c in channels.values()),
        "hub_cpu_pct": 100 * (after.hub_cpu_s - before.hub_cpu_s) / window,
        "hub_job_thread_cpu_pct": 100 * (after.hub_job_cpu_s - before.hub_job_cpu_s) / window,
        "load_gen_cpu_pct": 100 * (after.gens_cpu_s - before.gens_cpu_s) / window,
        "hub_cpu_us_per_frame": 1e6 * (after.hub_cpu_s - before.hub_cpu_s) / delivered,
        "hub_job_thread_us_per_frame": 1e6 * (after.hub_job_cpu_s - before.hub_job_cpu_s) / delivered,
        "hub_world_thread_us_per_frame": 1e6 * (after.hub_world_cpu_s - before.hub_world_cpu_s) / delivered,
        "load_gen_cpu_us_per_frame": 1e6 * (after.gens_cpu_s - before.gens_cpu_s) / delivered,
        "hub_down_messages_per_frame": _hub_count(after, before, "down_messages") / delivered,
        "hub_down_puts_per_frame": _hub_count(after, before, "down_puts") / delivered,
        "machine_cpu_busy_pct": 100 * (after.machine[0] - before.machine[0]) / (after.machine[1] - before.machine[1]),
        "series": [{"t_s": t, "fps": f} for t, f in series],
    }


def _hub_count(after: Snapshot, before: Snapshot, name: str) -> float:
    """How much one of the hub's counters grew over the window (NaN for a hub without it)."""
    return after.stats["hub"].get(name, math.nan) - before.stats["hub"].get(name, math.nan)


def air_limited(load: dict[str, Any]) -> bool:
    """True when the target was missed because the model's air, not the hub, set the pace."""
    if load["pass"]:
        return False
    return load["model_utilisation"] >= AIR_LIMITED_SHARE


def write_min_be0(out: Path) -> Path:
    """A hub config that only sets ``mac.min_be = 0`` (no initial backoff): more frames per second of air."""
    path = out / "bench_hub_min_be0.json"
    path.write_text(json.dumps({"mac": {"min_be": 0}}, indent=2) + "\n")
    return path


# == the whole run ===================================================================================


@dataclass
class HubBenchOptions:
    """What ``petswarm bench hub`` is asked to do."""

    rounds: int = 500
    """Round trips per path."""
    nodes: int = 50
    """Attached nodes in the load test."""
    load_seconds: float = 5.0
    seed: int = 1
    out: str = "bench-results"
    json: bool = False
    floor: bool = False
    """Also run both phases on a hub that carries frames without modelling the air."""
    check: bool = False
    """Exit 1 when a target is missed."""


def bench_hub(args: HubBenchOptions) -> int:
    """``petswarm bench hub``: run both phases, print the figures, write JSON and a plot."""
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = run_supervised(out, lambda sup: run_phases(sup, args, out), (BenchFailed, HubUnavailable, RadioError))
    if isinstance(results, int):
        return results
    write_results(results, out)
    report(results, args.json)
    if args.check:
        return check_targets(results)
    return 0


def targets(results: dict[str, Any]) -> list[dict[str, Any]]:
    """Each target of the bench with the figure measured, whether it was met and the load it was measured at.

    Throughput counts as met when one of the throughput runs met it (the defaults, or ``min_be = 0`` when the
    air was the limit); its lag target is that run's."""
    rtt, loads = results["rtt"], results["load"]
    best = max(loads, key=lambda load: (load["pass"], load["frames_per_s"]))
    lag = best["hub"]["lag_p99_us"]
    return [
        {
            "name": "rtt.ratio_p50",
            "value": rtt["ratio_p50"],
            "target": f"<= {RTT_TARGET_RATIO:g}",
            "pass": bool(rtt["pass"]),
            "load_average": rtt["load_average"],
        },
        {
            "name": f"throughput [{best['label']}] frames/s at {best['nodes']} nodes",
            "value": best["frames_per_s"],
            "target": f">= {best['target_fps']:.0f} (min of {FPS_TARGET:.0f} and the air's capacity)",
            "pass": bool(best["pass"]),
            "load_average": best["load_average"],
        },
        {
            "name": f"throughput [{best['label']}] hub lag p99 us",
            "value": lag,
            "target": f"<= {LAG_TARGET_US:.0f}",
            "pass": bool(lag <= LAG_TARGET_US),
            "load_average": best["load_average"],
        },
    ]


def check_targets(results: dict[str, Any]) -> int:
    """``--check``: 0 when every target was met, else 1 with each missed target named on stderr."""
    missed = [t for t in results["targets"] if not t["pass"]]
    for t in missed:
        load = t["load_average"]
        print(
            f"bench hub --check: MISS {t['name']} = {t['value']:.2f} (target {t['target']}; "
            f"load average {load['start']:.2f} -> {load['end']:.2f})",
            file=sys.stderr,
        )
    if not missed:
        print("bench hub --check: every target met", file=sys.stderr)
    return 1 if missed else 0


def run_phases(sup: Supervisor, args: HubBenchOptions, out: Path) -> dict[str, Any]:
    """Round trips, then throughput with the defaults and, if the air was the limit, with min_be = 0; with
    ``--floor`` both again on the hub that models nothing (``petswarm hub --floor``)."""
    base = f"bench-{os.getpid()}-{args.seed}"
    load_at_start = load_average()
    rtt = rtt_phase(sup, f"{base}-rtt", args)
    loads = [load_phase(sup, f"{base}-load", args, "defaults", None)]
    if air_limited(loads[0]):
        progress("the model's air capacity was the limit: again with mac.min_be = 0")
        loads.append(load_phase(sup, f"{base}-minbe0", args, "min_be=0", write_min_be0(out)))
    results = {
        "settings": settings(args, rtt["config"], load_at_start),
        "rtt": rtt,
        "load": loads,
        "throughput_pass": any(load["pass"] for load in loads),
    }
    if args.floor:
        progress("the floor: the same two phases on a hub that carries frames without modelling the air")
        floor_rtt = rtt_phase(sup, f"{base}-floor", args, floor=True)
        floor_load = load_phase(sup, f"{base}-floorload", args, "floor", None, floor=True)
        results["floor"] = {"rtt": floor_rtt, "load": floor_load}
    results["targets"] = targets(results)
    results["pass"] = all(t["pass"] for t in results["targets"])
    return results


def settings(args: HubBenchOptions, config: dict[str, Any], load_average: float) -> dict[str, Any]:
    """What the run was asked for, and the medium it ran on (the defaults unless a load entry says else)."""
    mac, rng = config["mac"], config["range"]
    return {
        "seed": args.seed,
        "rounds": args.rounds,
        "warmup_rounds": WARMUP_ROUNDS,
        "nodes": args.nodes,
        "load_seconds": args.load_seconds,
        "load_warmup_s": LOAD_WARMUP_S,
        "load_processes": len(load_slices(args.nodes, LOAD_PROCESSES)),
        "in_flight_per_sender": IN_FLIGHT,
        "pair_spacing_m": PAIR_SPACING_M,
        "load_psdu_bytes": load_psdu_len(),
        "cpus": os.cpu_count(),
        "load_average": load_average,
        "medium": {
            "min_be": mac["min_be"],
            "max_be": mac["max_be"],
            "unit_backoff_us": mac["unit_backoff_us"],
            "cca_us": mac["cca_us"],
            "turnaround_us": mac["turnaround_us"],
            "tx_range_m": rng["tx_range_m"],
            "interference_range_m": rng["interference_range_m"],
            "success_ratio_rx": rng["success_ratio_rx"],
            "loss_base": config["loss"]["base"],
        },
    }


# == child entry =====================================================================================


def run_child(role: str, hub: str, world: str, first: int = 0, last: int = 0, nodes: int = 0) -> int:
    """One of the benchmark's child processes (``python -m cli.bench_nodes echo|load ...``): the echo node, or
    the load generator of nodes ``first``..``last`` of ``nodes``; its exit code."""
    main = echo_main(hub, world) if role == "echo" else load_main(hub, world, first, last, nodes)
    try:
        return asyncio.run(main)
    except (HubUnavailable, RadioError) as err:
        print(f"bench {role}: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
