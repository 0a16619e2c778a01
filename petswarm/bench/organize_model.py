"""``petswarm bench organize --clock model``: the organizing experiment on model time, in this one process.

The same experiment as over processes (``petswarm.bench.organize``): per slave count a fresh environment with
n + 1 robots built from the same ``petswarm robot`` command lines, then ``--runs`` rounds of organize,
disperse, a pause and a bounded wait until every robot is back. The environment and the robots run on a
``ModelClockLoop`` (``petswarm.lab.model_run``), so the figures are a function of the seed and the options:
the same command gives the same table on any machine, loaded or idle. Times are model time.
"""

from __future__ import annotations

import asyncio
import os
import time
from pathlib import Path
from typing import Any

from petswarm.bench import organize as bench
from petswarm.bench.hub import progress
from petswarm.bench.organize import OrganizeOptions
from petswarm.bench.organize_report import report, summarise, write_results
from petswarm.clock import ModelClockLoop
from petswarm.lab.model_run import (
    ENDPOINT,
    MemoryAir,
    RunningRobot,
    cancel_leftovers,
    start_robot,
    unwind,
)
from petswarm.lab.processes import Interrupts
from petswarm.lab.robot_command import robot_config
from radio_hub.hosting import EnvironmentConfig, apply_profile, load_config
from radio_hub.values import HubUnavailable

ATTACH_S = 0.1
"""Model time between starting the robots and the first organization (every robot attaches at once)."""


async def _command(robot: RunningRobot, timeout: float, cmd: str, **args: Any) -> dict[str, Any]:
    """A control command; an error answer, a gone robot or a hang (model time) comes back as ``{"error": ...}``."""
    try:
        async with asyncio.timeout(timeout):
            return await robot.command(cmd, **args)
    except (HubUnavailable, TimeoutError) as err:
        return {"error": f"{type(err).__name__}: {err}"}


class ModelSwarm:
    """An environment on model time, its n + 1 robots, and the bench's view of them for one slave count."""

    def __init__(self, air: MemoryAir, slaves: int, robots: dict[int, RunningRobot]) -> None:
        self.air = air
        self.slaves = slaves
        self.robots = robots
        self.counters: dict[str, dict[str, int]] = {}

    async def command(self, rid: int, cmd: str, timeout: float, **args: Any) -> dict[str, Any]:
        """A control command to robot ``rid``."""
        return await _command(self.robots[rid], timeout, cmd, **args)

    def stats(self) -> dict[str, Any]:
        """The environment's counters now, as the hub's stats query answers."""
        return self.air.env.stats(self.air.now_us())

    def snapshot(self, counters: tuple[str, ...]) -> None:
        """Remember the robots' MAC counters, to tell what one organize or disperse cost."""
        nodes = self.stats()["nodes"]
        self.counters = {name: {k: node.get(k, 0) for k in counters} for name, node in nodes.items()}

    def evidence(self, seconds: float, counters: tuple[str, ...]) -> dict[str, Any]:
        """The air's transmissions that ended in the last ``seconds`` and each robot's MAC counters' gain."""
        stats = self.stats()
        since_us = stats["now_us"] - seconds * 1e6
        air = [tx for tx in self.air.env.air()["transmissions"] if tx["end_us"] >= since_us]
        return {"mac": bench.counters_gained(stats["nodes"], self.counters, counters), "air": air}


def environment(config: Path | None, profile: str) -> EnvironmentConfig:
    """The hub's tables: the bench's config file (``--mac-ack off``), else the defaults; then the profile's."""
    return apply_profile(load_config(config) if config is not None else EnvironmentConfig(), profile)


def measure_count(
    n: int, args: OrganizeOptions, config: Path | None, interrupts: Interrupts | None = None
) -> dict[str, Any]:
    """n + 1 robots on a fresh environment in model time, ``runs`` organizations per protocol; ``interrupts``:
    the bench's stop signals, raised between two passes of the loop (never lost in a weakref callback)."""
    loop = ModelClockLoop()
    if interrupts is not None:
        loop.checkpoint = interrupts.check
    finished = False
    try:
        result = loop.run_until_complete(_measure(n, args, config))
        finished = True
        return result
    finally:
        if not finished:
            loop.checkpoint = None  # the signal was raised: unwinding the robots is not cut short by it again
            unwind(loop)
        loop.close()


async def _measure(n: int, args: OrganizeOptions, config: Path | None) -> dict[str, Any]:
    world = f"bench-org-model-{args.seed}-n{n}"
    progress(f"{n} slave(s): {n + 1} robots on model time")
    air = MemoryAir(environment(config, args.profile), args.seed)
    try:
        robots = {}
        for rid in range(bench.MASTER, n + 2):
            robots[rid] = await start_robot(robot_config(bench.robot_options(rid, ENDPOINT, world, args)), air)
        swarm = ModelSwarm(air, n, robots)
        await asyncio.sleep(ATTACH_S)
        records = []
        for index in range(args.runs):
            for protocol in bench.protocols_of(args.protocol):
                records.append(await organize_once(swarm, protocol, index))
            if (index + 1) % bench.PROGRESS_EVERY == 0 or index + 1 == args.runs:
                so_far = bench.so_far(records, bench.protocols_of(args.protocol))
                progress(f"{n} slave(s): run {index + 1}/{args.runs}  {so_far}")
        stats = swarm.stats()
        for robot in robots.values():
            await robot.stop()
        await cancel_leftovers(asyncio.get_running_loop())
    finally:
        air.coordinator.close()
    return {"slaves": n, "world": world, "records": records, "hub": bench.hub_figures(stats), "config": stats["config"]}


async def organize_once(swarm: ModelSwarm, protocol: str, index: int) -> dict[str, Any]:
    """Organize a swarm of n, disperse it, wait until every robot is back; one raw record (model time)."""
    loop = asyncio.get_running_loop()
    record: dict[str, Any] = {"slaves": swarm.slaves, "protocol": protocol, "run": index}
    slaves = {rid: r for rid, r in swarm.robots.items() if rid != bench.MASTER}
    record["waiting_before"] = sum(1 for rid, r in slaves.items() if not misplaced(r, rid))
    swarm.snapshot(bench.MAC_COUNTERS)
    t0 = loop.time()
    answer = await swarm.command(
        bench.MASTER, "organize", bench.ORGANIZE_TIMEOUT_S, count=swarm.slaves, protocol=protocol
    )
    record["command_s"] = round(loop.time() - t0, 6)
    if "error" in answer:
        record.update(ok=False, complete=False, error=answer["error"])
    else:
        record.update(ok=True, complete=len(answer["members"]) == swarm.slaves, **bench.organization_figures(answer))
        if not record["complete"] or record["retries"]:
            record["evidence"] = swarm.evidence(record["command_s"] + bench.AIR_MARGIN_S, bench.MAC_COUNTERS)
    record["dispersal"] = await disperse(swarm) if answer.get("members") else None
    await asyncio.sleep(bench.PAUSE_S)
    record["settle"] = await settle(swarm)
    return record


async def disperse(swarm: ModelSwarm) -> dict[str, Any]:
    """End the swarm; its figures or the error (and the air, when it needed a retry)."""
    loop = asyncio.get_running_loop()
    swarm.snapshot(bench.MAC_COUNTERS)
    t0 = loop.time()
    answer = await swarm.command(bench.MASTER, "disperse", bench.ORGANIZE_TIMEOUT_S)
    if "error" in answer:
        return {"ok": False, "error": answer["error"]}
    figures = {k: answer[k] for k in ("disperse_time_s", "retries", "unconfirmed")}
    if answer["retries"]:
        figures["evidence"] = swarm.evidence(loop.time() - t0 + bench.AIR_MARGIN_S, bench.MAC_COUNTERS)
    return {"ok": True, **figures}


async def settle(swarm: ModelSwarm) -> dict[str, Any]:
    """Poll (model time) until the master drives with its user and every slave waits on the waiting PAN."""
    loop = asyncio.get_running_loop()
    t0 = loop.time()
    stuck: dict[int, str] = {}
    while loop.time() - t0 < bench.SETTLE_TIMEOUT_S:
        stuck = {rid: state for rid, robot in swarm.robots.items() if (state := misplaced(robot, rid))}
        if not stuck:
            return {"ok": True, "settle_s": round(loop.time() - t0, 4)}
        await asyncio.sleep(bench.SETTLE_POLL_S)
    return {"ok": False, "settle_s": round(loop.time() - t0, 4), "stuck": stuck}


def misplaced(robot: RunningRobot, rid: int) -> str:
    """'' when the robot is where a new organization expects it, else what it is instead."""
    return bench.misplaced_as(robot.robot.status(), rid)


def run_counts(args: OrganizeOptions, out: Path) -> dict[str, Any]:
    """Every slave count in turn on model time, then the summary (as ``organize.run_counts`` over processes)."""
    started = time.monotonic()
    load_average = os.getloadavg()[0]
    config = bench.write_no_ack_config(out) if args.mac_ack == "off" else None
    interrupts = Interrupts(at_safe_points=True)
    try:
        per_count = [measure_count(n, args, config, interrupts) for n in args.slaves]
    finally:
        with interrupts.deferred():  # a second signal waits for the loop's unwinding
            pass
    records = [r for count in per_count for r in count["records"]]
    return {
        "settings": bench.settings(args, per_count[0]["config"], load_average),
        "summary": summarise(records, bench.protocols_of(args.protocol), args.slaves),
        "hub": {str(c["slaves"]): c["hub"] for c in per_count},
        "runs": records,
        "elapsed_s": time.monotonic() - started,
    }


def bench_organize(args: OrganizeOptions) -> int:
    """``petswarm bench organize --clock model``: measure every slave count, print the table, write JSON and plot."""
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = run_counts(args, out)
    write_results(results, out)
    report(results, args.json)
    return 0
