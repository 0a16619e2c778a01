"""``petswarm run --clock lockstep``: hub and robot processes over zenoh, on model time the hub owns.

The processes are those of a wall-clock run, started with ``--clock lockstep``; the orchestration is the
model-time run's (``petswarm.lab.model_run.orchestrate``), run here on a lockstep loop as the world's ``run`` node, so
commands, faults and the summary's questions happen at the same model instants as in ``--clock model`` and
the record's digest is the same.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

from petswarm.clock import LockstepLoop
from petswarm.control import RelayControl
from petswarm.lab.digest import record_digest
from petswarm.lab.metrics import driving_metrics, read_world
from petswarm.lab.model_run import CONTROL_IDENTITY, orchestrate, run_robots
from petswarm.lab.records import RunRecord
from petswarm.lab.run import RunContext, RunOptions, progress, roster_argv, supervise
from petswarm.scenario import Scenario
from radio_hub.interface import LockstepLink, RadioClient, query_hub


def run_lockstep(opts: RunOptions, scenario: Scenario | None) -> int:
    """The run in lockstep time; returns the exit code."""
    if scenario is not None:
        opts = opts.for_scenario(scenario)
    has_user = scenario is not None and scenario.user is not None
    nodes = opts.robots + 1 + (1 if has_user else 0)
    started = time.perf_counter()
    clock: dict[str, float] = {}

    def hub_extra(record: RunRecord) -> list[str]:
        extra = ["--clock", "lockstep", "--expect", str(nodes)]
        users = [scenario.user.node_id] if scenario is not None and scenario.user is not None else []
        extra += roster_argv(opts.robots, *users, CONTROL_IDENTITY.node_id)
        extra += [] if opts.dead_after_s is None else ["--dead-after", str(opts.dead_after_s)]
        if scenario is not None:
            extra += ["--scenario", str(scenario.path), "--world-log", str(record.path / "world.jsonl")]
        return extra

    def phase(ctx: RunContext) -> dict[str, Any]:
        for rid, robot in run_robots(opts, scenario, ctx.world, ctx.record, ctx.endpoint).items():
            ctx.sup.spawn(f"robot-{rid}", replace(robot, clock="lockstep").argv())
        if scenario is not None and scenario.user is not None:
            user = ["user", "--scenario", str(scenario.path), "--hub", ctx.endpoint, "--world", ctx.world]
            user += ["--seed", str(opts.seed), "--record", str(ctx.record.events_of(scenario.user.node_id))]
            user += ["--profile", opts.profile] if opts.profile != "ideal" else []
            ctx.sup.spawn("user", [*user, "--duration", str(scenario.duration_s), "--clock", "lockstep"])
        ctx.watch.check()
        ctx.watch.write_progress(force=True)  # the summary written as the run goes names every process from now on
        progress(f"lockstep: model time starts when the {nodes_line(opts.robots, has_user)} are there")
        loop = LockstepLoop()
        try:
            summary = loop.run_until_complete(_orchestrate(ctx, scenario))
        finally:
            clock["model_time_s"] = loop.time()
            loop.close()
        ctx.watch.world_over = True  # the nodes leave by themselves now
        hub = query_hub(ctx.session, ctx.keys.stats, timeout=10.0)
        summary["hub_process"] = hub.get("process")
        lockstep = hub.get("lockstep", {})
        summary["gone"] = lockstep.get("dead", [])
        summary["lockstep"] = {
            key: lockstep.get(key)
            for key in ("rounds", "stale_idles", "grants", "down_puts", "down_messages", "up_puts")
        }
        for gone in summary["gone"]:
            progress(f"{gone['node']} was taken as gone at model time {gone['model_time_s']:.3f} s: {gone['why']}")
        return summary

    def after_stop(summary: dict[str, Any], record: RunRecord) -> None:
        if scenario is not None:
            summary["driving"] = driving_metrics(read_world(record.path / "world.jsonl"))
        summary["clock"] = "lockstep"
        summary["model_time_s"] = round(clock.get("model_time_s", 0.0), 6)
        summary["wall_time_s"] = round(time.perf_counter() - started, 3)
        summary["wall_per_model_s"] = round(summary["wall_time_s"] / max(summary["model_time_s"], 1e-9), 3)
        summary["digest"] = record_digest(record.path)

    return supervise(opts, "lock", hub_extra, phase, after_stop)


def nodes_line(robots: int, has_user: bool) -> str:
    """The nodes a lockstep hub waits for, counted as they are: the robots, the user when there is one, and
    this run's orchestrator."""
    parts = [f"{robots} robot{'s' if robots != 1 else ''}", *(["the user"] if has_user else []), "this run"]
    total = robots + 1 + (1 if has_user else 0)
    return f"{total} nodes ({', '.join(parts)})"


async def _orchestrate(ctx: RunContext, scenario: Scenario | None) -> dict[str, Any]:
    link = LockstepLink(ctx.session, ctx.keys, owns_session=False)
    radio = await RadioClient.connect(CONTROL_IDENTITY, world=ctx.world, link=link, timeout=5.0)
    try:
        return await orchestrate(ctx.opts, scenario, RelayControl(radio), ctx.world, lambda: _died(ctx))
    finally:
        await radio.close()


def _died(ctx: RunContext) -> set[int]:
    """The robots whose processes died so far, as the run's supervision sees them (RunAborted if the run cannot
    go on): the hub has taken them as gone, and the run asks nothing more of them. A robot the hub took as gone
    that is still alive (stopped, cut off) is not among them: it fails the run's checks."""
    ctx.watch.check()
    return ctx.watch.dead_robots()
