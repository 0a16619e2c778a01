"""``petswarm bench organize``: network-organizing time against the number of slaves, per protocol.

The swarm paper's experiment: a master connected to its user organizes a swarm of n slaves (n = 1..5),
50 times each; the figures are the mean, minimum and maximum organizing time and how often an
organization needed a retry. Here both organizing protocols (``paper``: answer at once; ``slotted``:
answer in address slots) run side by side on the same processes.

For every slave count: a fresh hub child and n + 1 robot children (robot 1 connected to user 1, the
master; robots 2..n+1 waiting on the default grid, all inside the available region). Then, ``--runs``
times, each protocol in turn (paper, slotted, paper, ...: machine noise hits both alike): organize,
disperse, a short pause and a bounded wait until every robot is back where it started. A command that
fails is recorded with its error and the run goes on; a process that dies ends the bench.

Figures go to stdout (stderr with ``--json``), progress to stderr, ``<out>/bench_organize.json`` and
``<out>/bench_organize.png`` to disk, each robot's event log to ``<out>/events/``; the output is
``petswarm.bench.organize_report``.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from petswarm import control
from petswarm.bench.hub import HubRun, check_alive, progress, start_hub, stopping, wait_attached
from petswarm.bench.nodes import BenchFailed
from petswarm.bench.organize_report import report, summarise, write_results
from petswarm.lab.processes import Supervisor, run_supervised
from petswarm.lab.robot_command import RobotOptions
from petswarm.managers.exchange import StepTiming
from petswarm.managers.formation import PROTOCOLS, FormationConfig
from petswarm.profiles import robot_profile
from radio_hub.interface import query_hub
from radio_hub.values import HubUnavailable, RadioError

MAX_SLAVES = 14
"""Robots 2..15 stand within 6.7 m of the master on the default grid: inside the default -70 dBm region."""
MASTER = 1
USER = 1
WAITING_PAN = FormationConfig().waiting_pan
ORGANIZE_TIMEOUT_S = 60.0
STATUS_TIMEOUT_S = 2.0
STARTUP_TIMEOUT_S = 20.0
PAUSE_S = 0.2
"""After a disperse: lets late frames of the last organization drain before the robots are checked."""
SETTLE_TIMEOUT_S = 5.0
"""A member that missed the disperse leaves on its own after 2 s without a roster; allow for that."""
SETTLE_POLL_S = 0.05
PROGRESS_EVERY = 10
AIR_MARGIN_S = 0.05
"""Air log kept for an incomplete or retried organization or dispersal: its command time plus this."""
MAC_COUNTERS = ("mac_retries", "no_ack", "channel_access_failures", "collided", "lost")


def slave_counts(text: str) -> list[int]:
    """``1-5``, ``3`` or ``1,3,5``: the slave counts to measure, sorted, each 1..MAX_SLAVES."""
    counts: set[int] = set()
    for part in text.split(","):
        low, dash, high = part.strip().partition("-")
        try:
            first = int(low)
            last = int(high) if dash else first
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not N, A-B or N,M,... (e.g. 1-5)") from None
        if first > last:
            raise argparse.ArgumentTypeError(f"{part.strip()!r}: the range runs backwards")
        if first < 1 or last > MAX_SLAVES:
            raise argparse.ArgumentTypeError(
                f"slave counts must be 1..{MAX_SLAVES} (robots beyond that stand outside the available region)"
            )
        counts.update(range(first, last + 1))
    return sorted(counts)


def protocols_of(choice: str) -> tuple[str, ...]:
    """``both`` or one protocol name."""
    return PROTOCOLS if choice == "both" else (choice,)


# == one slave count ==================================================================================


@dataclass
class Swarm:
    """A hub child, its n + 1 robot children and the bench's session to them, for one slave count."""

    hub: HubRun
    slaves: int
    names: list[str]
    """Child names: the hub first, then the robots."""
    counters: dict[str, dict[str, int]] = field(default_factory=dict)
    """The robots' MAC counters at the hub when the current organize or disperse began."""

    @property
    def robot_ids(self) -> range:
        """The master (1) and the slaves (2..n+1)."""
        return range(MASTER, self.slaves + 2)

    def command(self, rid: int, cmd: str, timeout: float = STATUS_TIMEOUT_S, **args: Any) -> dict[str, Any]:
        """A control command to one robot; a robot that does not answer comes back as ``{"error": ...}``."""
        try:
            return control.command(self.hub.session, self.hub.keys, rid, cmd, timeout, **args)
        except HubUnavailable as err:
            return {"error": str(err)}

    def snapshot(self) -> None:
        """Remember the robots' MAC counters, to tell what one organize or disperse cost."""
        try:
            nodes = self.hub.stats()["nodes"]
        except HubUnavailable:
            nodes = {}
        self.counters = {name: {k: node.get(k, 0) for k in MAC_COUNTERS} for name, node in nodes.items()}


@dataclass
class OrganizeOptions:
    """What ``petswarm bench organize`` is asked to do (``bench_organize`` here on the wall clock,
    ``petswarm.bench.organize_model.bench_organize`` on model time)."""

    slaves: list[int] = field(default_factory=lambda: [1, 2, 3, 4, 5])
    runs: int = 50
    """Organizations per count and protocol."""
    protocol: str = "both"
    """``paper``, ``slotted`` or ``both``."""
    mac_ack: str = "on"
    clock: str = "model"
    step_deadline: float | None = None
    """Seconds each organizing step waits before retrying (None: the robot's)."""
    step_retries: int | None = None
    profile: str = "ideal"
    seed: int = 1
    link_key: str | None = None
    """A network key file: 802.15.4 link security on."""
    link_mic: int = 4
    out: str = "bench-results"
    json: bool = False


def robot_options(rid: int, endpoint: str, world: str, args: OrganizeOptions) -> RobotOptions:
    """The options of robot ``rid``: robot 1 is the master (connected to the user), the rest wait."""
    return RobotOptions(
        id=rid,
        hub=endpoint,
        world=world,
        seed=args.seed,
        profile=args.profile,
        link_key=args.link_key,
        link_mic=args.link_mic if args.link_key else RobotOptions.link_mic,
        user=USER if rid == MASTER else 0,
        step_deadline=args.step_deadline,
        step_retries=RobotOptions.step_retries if args.step_retries is None else args.step_retries,
    )


def wait_serving(sup: Supervisor, swarm: Swarm) -> None:
    """Until every robot answers ``status`` (attached is not enough: the control channel comes after)."""
    deadline = time.monotonic() + STARTUP_TIMEOUT_S
    pending = set(swarm.robot_ids)
    while pending and time.monotonic() < deadline:
        check_alive(sup, swarm.names)
        pending = {rid for rid in pending if "error" in swarm.command(rid, "status", timeout=1.0)}
        if pending:
            time.sleep(0.1)
    if pending:
        raise BenchFailed(f"robots {sorted(pending)} did not answer within {STARTUP_TIMEOUT_S} s")


def measure_count(sup: Supervisor, n: int, args: OrganizeOptions, out: Path, config: Path | None) -> dict[str, Any]:
    """A fresh hub and n + 1 robots, ``runs`` organizations per protocol; the raw records and hub figures."""
    world = f"bench-org-{os.getpid()}-{args.seed}-n{n}"
    progress(f"{n} slave(s): starting a hub and {n + 1} robots")
    hub = start_hub(sup, f"hub-n{n}", world, args.seed, config, args.profile)
    names = [hub.name, *(f"n{n}-robot-{rid}" for rid in range(MASTER, n + 2))]
    with stopping(sup, names):
        try:
            swarm = Swarm(hub, n, names)
            for rid, name in zip(swarm.robot_ids, names[1:], strict=True):
                sup.spawn(name, robot_options(rid, hub.endpoint, hub.keys.world, args).argv())
            wait_attached(sup, hub, n + 1, names[1:])
            wait_serving(sup, swarm)
            records = run_series(sup, swarm, args)
            stats = hub.stats()
            save_events(swarm, out / "events")
        finally:
            hub.session.close()
    return {"slaves": n, "world": world, "records": records, "hub": hub_figures(stats), "config": stats["config"]}


def run_series(sup: Supervisor, swarm: Swarm, args: OrganizeOptions) -> list[dict[str, Any]]:
    """``runs`` rounds of organize + disperse, the protocols interleaved round by round."""
    protocols = protocols_of(args.protocol)
    records: list[dict[str, Any]] = []
    for index in range(args.runs):
        for protocol in protocols:
            check_alive(sup, swarm.names)
            waiting = waiting_after(records[-1] if records else None, swarm.slaves)
            records.append({"waiting_before": waiting, **organize_once(swarm, protocol, index)})
        if (index + 1) % PROGRESS_EVERY == 0 or index + 1 == args.runs:
            progress(f"{swarm.slaves} slave(s): run {index + 1}/{args.runs}  " + so_far(records, protocols))
    return records


def waiting_after(previous: dict[str, Any] | None, slaves: int) -> int:
    """Slaves waiting on the waiting PAN once ``previous`` (None: nothing yet) had settled: all of them
    unless some were stuck elsewhere when the bench stopped waiting for them."""
    if previous is None:
        return slaves
    stuck = previous["settle"].get("stuck", {})
    return slaves - sum(1 for rid in stuck if int(rid) != MASTER)


def so_far(records: list[dict[str, Any]], protocols: tuple[str, ...]) -> str:
    """Mean organizing time (complete organizations), retried, incomplete and failed, for progress lines."""
    parts = []
    for protocol in protocols:
        mine = [r for r in records if r["protocol"] == protocol]
        ok = [r for r in mine if r["ok"]]
        times = [r["organize_time_s"] for r in ok if r["complete"]]
        mean = sum(times) / len(times) * 1000 if times else float("nan")
        retried = sum(1 for r in ok if r["retries"])
        incomplete = len(ok) - len(times)
        parts.append(
            f"{protocol}: mean {mean:.1f} ms, retried {retried}, incomplete {incomplete}, failed {len(mine) - len(ok)}"
        )
    return "; ".join(parts)


# == one organization =================================================================================


def organize_once(swarm: Swarm, protocol: str, index: int) -> dict[str, Any]:
    """Organize a swarm of n, disperse it, wait until every robot is back; one raw record."""
    record: dict[str, Any] = {"slaves": swarm.slaves, "protocol": protocol, "run": index}
    swarm.snapshot()
    t0 = time.monotonic()
    answer = swarm.command(MASTER, "organize", ORGANIZE_TIMEOUT_S, count=swarm.slaves, protocol=protocol)
    record["command_s"] = round(time.monotonic() - t0, 6)
    if "error" in answer:
        record.update(ok=False, complete=False, error=answer["error"])
    else:
        record.update(ok=True, complete=len(answer["members"]) == swarm.slaves, **organization_figures(answer))
        if not record["complete"] or record["retries"]:
            record["evidence"] = evidence(swarm, record["command_s"] + AIR_MARGIN_S)
    record["dispersal"] = disperse(swarm) if answer.get("members") else None
    time.sleep(PAUSE_S)
    record["settle"] = settle(swarm)
    return record


def organization_figures(answer: dict[str, Any]) -> dict[str, Any]:
    """The figures the master returns that the bench keeps."""
    keys = ("session", "organize_time_s", "retries", "step_retries", "candidates", "available", "members")
    keys += ("missing", "refused")
    return {k: answer.get(k) for k in keys}


def evidence(swarm: Swarm, seconds: float) -> dict[str, Any]:
    """For an odd organize or disperse: the hub's transmissions that ended in the last ``seconds`` of model
    time, and what each robot's MAC counters gained since ``swarm.snapshot()``."""
    try:
        stats = swarm.hub.stats()
        log = query_hub(swarm.hub.session, swarm.hub.keys.air, timeout=5.0)["transmissions"]
    except HubUnavailable as err:
        return {"error": str(err)}
    since_us = stats["now_us"] - seconds * 1e6
    gained = counters_gained(stats["nodes"], swarm.counters, MAC_COUNTERS)
    return {"mac": gained, "air": [tx for tx in log if tx["end_us"] >= since_us]}


def counters_gained(
    nodes: dict[str, dict[str, Any]], before: dict[str, dict[str, int]], counters: tuple[str, ...]
) -> dict[str, dict[str, int]]:
    """Per node, the ``counters`` that grew since ``before`` and by how much (nodes with no gain left out)."""
    gained = {}
    for name, node in nodes.items():
        was = before.get(name, {})
        delta = {k: node.get(k, 0) - was.get(k, 0) for k in counters}
        if any(delta.values()):
            gained[name] = {k: v for k, v in delta.items() if v}
    return gained


def disperse(swarm: Swarm) -> dict[str, Any]:
    """End the swarm; its figures or the error (and the air, when it needed a retry)."""
    swarm.snapshot()
    t0 = time.monotonic()
    answer = swarm.command(MASTER, "disperse", ORGANIZE_TIMEOUT_S)
    if "error" in answer:
        return {"ok": False, "error": answer["error"]}
    figures = {k: answer[k] for k in ("disperse_time_s", "retries", "unconfirmed")}
    if answer["retries"]:
        figures["evidence"] = evidence(swarm, time.monotonic() - t0 + AIR_MARGIN_S)
    return {"ok": True, **figures}


def settle(swarm: Swarm) -> dict[str, Any]:
    """Poll until the master drives with its user and every slave waits on the waiting PAN (bounded)."""
    t0 = time.monotonic()
    stuck: dict[int, str] = {}
    while time.monotonic() - t0 < SETTLE_TIMEOUT_S:
        stuck = {rid: state for rid in swarm.robot_ids if (state := misplaced(swarm, rid))}
        if not stuck:
            return {"ok": True, "settle_s": round(time.monotonic() - t0, 4)}
        time.sleep(SETTLE_POLL_S)
    return {"ok": False, "settle_s": round(time.monotonic() - t0, 4), "stuck": stuck}


def misplaced(swarm: Swarm, rid: int) -> str:
    """'' when the robot is where a new organization expects it, else what it is instead."""
    status = swarm.command(rid, "status")
    return status["error"] if "error" in status else misplaced_as(status, rid)


def misplaced_as(status: dict[str, Any], rid: int) -> str:
    """'' when a robot with this ``status`` is where a new organization expects it, else what it is instead."""
    state, pan = status["state"], status["radio"]["pan_id"]
    wanted = "following" if rid == MASTER else "waiting"
    return "" if state == wanted and pan == WAITING_PAN else f"{state} on PAN {pan:#06x}"


def hub_figures(stats: dict[str, Any]) -> dict[str, Any]:
    """Counters summed over the robots for the whole slave count (every organization and dispersal)."""
    totals: dict[str, int] = {}
    for node in stats["nodes"].values():
        for name, value in node.items():
            if isinstance(value, int) and not isinstance(value, bool):
                totals[name] = totals.get(name, 0) + value
    hub = stats["hub"]
    lag = {k: hub.get(k, 0) for k in ("lag_p50_us", "lag_p99_us", "transport_gaps", "malformed")}
    return {"robots": totals, "hub": lag}


def save_events(swarm: Swarm, folder: Path) -> None:
    """Every robot's event log as ``<folder>/n<slaves>-robot-<id>.json`` (evidence for odd runs)."""
    folder.mkdir(parents=True, exist_ok=True)
    for rid in swarm.robot_ids:
        answer = swarm.command(rid, "events", timeout=10.0)
        path = folder / f"n{swarm.slaves}-robot-{rid}.json"
        path.write_text(json.dumps(answer.get("events", answer), indent=1) + "\n")


# == the whole run ====================================================================================


def write_no_ack_config(out: Path) -> Path:
    """A hub config that only turns MAC acknowledgements off."""
    path = out / "bench_organize_mac_ack_off.json"
    path.write_text(json.dumps({"mac": {"ack_enabled": False}}, indent=2) + "\n")
    return path


def settings(args: OrganizeOptions, config: dict[str, Any], load_average: float) -> dict[str, Any]:
    """What the bench was asked for and the medium the hub reported."""
    step = StepTiming(robot_profile(args.profile).step_deadline_s or StepTiming().deadline_s)
    mac, rng, path_loss = config["mac"], config["range"], config["path_loss"]
    return {
        "seed": args.seed,
        "clock": args.clock,
        "profile": args.profile,
        "runs": args.runs,
        "slaves": args.slaves,
        "protocols": list(protocols_of(args.protocol)),
        "mac_ack": args.mac_ack,
        "step_deadline_s": args.step_deadline if args.step_deadline is not None else step.deadline_s,
        "step_retries": args.step_retries if args.step_retries is not None else step.max_retries,
        "step_defaults": args.step_deadline is None and args.step_retries is None,
        "slot_ms": FormationConfig().slot_ms,
        "pause_s": PAUSE_S,
        "cpus": os.cpu_count(),
        "load_average": load_average,
        "medium": {
            "ack_enabled": mac["ack_enabled"],
            "min_be": mac["min_be"],
            "max_be": mac["max_be"],
            "max_csma_backoffs": mac["max_csma_backoffs"],
            "max_frame_retries": mac["max_frame_retries"],
            "ack_wait_us": mac["ack_wait_us"],
            "tx_range_m": rng["tx_range_m"],
            "success_ratio_rx": rng["success_ratio_rx"],
            "shadowing_sigma_db": path_loss["shadowing_sigma_db"],
            "loss_base": config["loss"]["base"],
        },
    }


def run_counts(sup: Supervisor, args: OrganizeOptions, out: Path) -> dict[str, Any]:
    """Every slave count in turn, then the summary."""
    load_average = os.getloadavg()[0]
    config = write_no_ack_config(out) if args.mac_ack == "off" else None
    per_count = [measure_count(sup, n, args, out, config) for n in args.slaves]
    records = [r for count in per_count for r in count["records"]]
    return {
        "settings": settings(args, per_count[0]["config"], load_average),
        "summary": summarise(records, protocols_of(args.protocol), args.slaves),
        "hub": {str(c["slaves"]): c["hub"] for c in per_count},
        "runs": records,
    }


def bench_organize(args: OrganizeOptions) -> int:
    """``petswarm bench organize``: measure every slave count, print the table, write JSON and a plot."""
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = run_supervised(out, lambda sup: run_counts(sup, args, out), (BenchFailed, HubUnavailable, RadioError))
    if isinstance(results, int):
        return results
    write_results(results, out)
    report(results, args.json)
    return 0
