"""``petswarm run SCENARIO``: hub, robots and the user of a scenario file, end to end.

The hub takes the scenario's world (obstacles, tables) and writes the ground truth to the record's
``world.jsonl``; robots start where the scenario puts them; the user process walks the path and makes
the watch requests (follow, organize, drive, disperse...); the scenario's fault timeline is applied
through the hub's chaos queryable. When the user is done the run is summarised: the radio counters of
``petswarm run`` plus the driving metrics (formation error, user-master distance, reaction times,
collisions, swarm extent and connectivity) computed from the ground truth.
"""

from __future__ import annotations

import time
from typing import Any

import zenoh

from petswarm.lab.metrics import driving_metrics, read_world
from petswarm.lab.records import RunRecord
from petswarm.lab.robot_command import RobotOptions
from petswarm.lab.run import (
    HEARING_PROBLEMS,
    FaultTimeline,
    RunContext,
    RunOptions,
    _summarise,
    _wait_for_robots,
    hub_chaos,
    progress,
    roster_argv,
    supervise,
)
from petswarm.lab.supervision import Supervision
from petswarm.scenario import Scenario
from radio_hub.interface import Keys


def run_scenario(opts: RunOptions, scenario: Scenario) -> int:
    """Run the scenario; returns the exit code (1 when a process failed or an invariant broke)."""
    opts = opts.for_scenario(scenario)
    progress(f"scenario {scenario.name}: {scenario.robot_count} robots, {scenario.duration_s:g} s")

    def hub_extra(record: RunRecord) -> list[str]:
        users = [] if scenario.user is None else [scenario.user.node_id]
        roster = roster_argv(scenario.robot_count, *users)
        return ["--scenario", str(scenario.path), "--world-log", str(record.path / "world.jsonl"), *roster]

    def after_stop(summary: dict[str, Any], record: RunRecord) -> None:
        summary["driving"] = driving_metrics(read_world(record.path / "world.jsonl"))

    return supervise(opts, "scn", hub_extra, lambda ctx: _drive(ctx, scenario), after_stop)


def _drive(ctx: RunContext, scenario: Scenario) -> dict[str, Any]:
    """Robots where the scenario puts them, the user walking its path, the fault timeline; the summary."""
    opts, endpoint, world = ctx.opts, ctx.endpoint, ctx.world
    for rid in range(1, scenario.robot_count + 1):
        ctx.sup.spawn(f"robot-{rid}", scenario_robot_options(opts, scenario, rid, endpoint, world, ctx.record).argv())
    _wait_for_robots(ctx.watch, ctx.session, ctx.keys, scenario.robot_count, opts.startup_timeout)
    if scenario.user is not None:
        user_args = ["user", "--scenario", str(scenario.path), "--hub", endpoint, "--world", world]
        user_args += ["--seed", str(opts.seed), "--record", str(ctx.record.events_of(scenario.user.node_id))]
        user_args += ["--profile", opts.profile] if opts.profile != "ideal" else []
        ctx.sup.spawn("user", [*user_args, "--duration", str(scenario.duration_s)])
    timeline = FaultTimeline(list(scenario.faults) + list(opts.faults))
    _follow(ctx.watch, ctx.session, ctx.keys, scenario.duration_s, timeline)
    summary = _summarise(ctx.session, ctx.keys, opts, world, endpoint, ctx.watch.dead_robots())
    summary["problems"] = [p for p in summary["problems"] if p not in HEARING_PROBLEMS]  # no ping phase here
    summary.update(scenario=scenario.name, faults=timeline.applied, duration_s=scenario.duration_s)
    summary["ok"] = not summary["problems"]
    return summary


def scenario_robot_options(
    opts: RunOptions, scenario: Scenario, rid: int, endpoint: str, world: str, record: RunRecord
) -> RobotOptions:
    """The options of robot ``rid`` where the scenario puts it."""
    from petswarm.controllers.surround import SurroundConfig

    x, y, heading = scenario.robot_poses[rid - 1]
    surround = scenario.surround_enabled
    law = scenario.surround_law() if surround else {}
    return RobotOptions(
        id=rid,
        hub=endpoint,
        world=world,
        pos=(x, y),
        heading=heading,
        seed=opts.seed,
        protocol=opts.protocol,
        formation="surround" if surround else "swarm",
        surround_human=scenario.user.node_id if surround and scenario.user is not None else "user",
        surround_config=SurroundConfig.from_dict(law) if law else None,
        ping_interval=scenario.ping_interval or 0.0,
        profile=opts.profile,
        link_key=opts.link_key,
        link_mic=opts.link_mic if opts.link_key else RobotOptions.link_mic,
        record=str(record.events_of(f"robot-{rid}")),
    )


def _follow(watch: Supervision, session: zenoh.Session, keys: Keys, duration: float, timeline: FaultTimeline) -> None:
    """Apply the fault timeline and report progress until the user is done (or the duration is over)."""
    start = time.monotonic()
    next_report = start
    while (elapsed := time.monotonic() - start) < duration + 2.0:
        dead = watch.sup.dead()
        if "user" in dead and dead["user"] == 0:
            return
        watch.check()
        timeline.apply_due(hub_chaos(session, keys), elapsed)
        if time.monotonic() >= next_report:
            progress(f"t={elapsed:5.1f}/{duration:g}s")
            next_report += 5.0
        time.sleep(0.1)
