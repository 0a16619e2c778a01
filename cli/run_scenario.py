"""``petswarm run SCENARIO``: hub, robots and the user of a scenario file, end to end.

The hub takes the scenario's world (obstacles, tables) and writes the ground truth to the record's
``world.jsonl``; robots start where the scenario puts them; the user process walks the path and makes
the watch requests (follow, organize, drive, disperse...); the scenario's fault timeline is applied
through the hub's chaos queryable. When the user is done the run is summarised: the radio counters of
``petswarm run`` plus the driving metrics (formation error, user-master distance, reaction times,
collisions, swarm extent and connectivity) computed from the ground truth.
"""

from __future__ import annotations

import os
import signal
import time
from dataclasses import replace
from typing import Any

import zenoh

from cli.checker import check_record
from cli.metrics import driving_metrics, read_world
from cli.processes import Supervisor, free_tcp_port, raise_interrupt
from cli.records import RunRecord
from cli.run import (
    FaultTimeline,
    RunFailed,
    RunOptions,
    _check_alive,
    _print,
    _summarise,
    _wait_for_hub,
    _wait_for_robots,
)
from cli.run import progress as _progress
from petswarm.scenario import Scenario
from radio_hub.interface import HubUnavailable, Keys


def run_scenario(opts: RunOptions, scenario: Scenario) -> int:
    """Run the scenario; returns the exit code (1 when a process failed or an invariant broke)."""
    opts = replace(opts, robots=scenario.robot_count, duration=scenario.duration_s)
    world = opts.world or f"scn-{os.getpid()}-{opts.seed}"
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    keys = Keys(world)
    record = RunRecord.create(opts, world, endpoint)
    sup = Supervisor(record.path / "logs")
    previous = signal.signal(signal.SIGTERM, raise_interrupt)
    session: zenoh.Session | None = None
    summary: dict[str, Any] = {"ok": False, "problems": ["the run did not finish"], "seed": opts.seed}
    timeline = FaultTimeline(list(scenario.faults) + list(opts.faults))
    try:
        _progress(f"scenario {scenario.name}: world {world}, seed {opts.seed}, record in {record.path}")
        hub_args = ["hub", "--listen", endpoint, "--world", world, "--seed", str(opts.seed)]
        hub_args += ["--scenario", str(scenario.path), "--world-log", str(record.path / "world.jsonl")]
        hub_args += ["--pcap", opts.pcap or str(record.path / "air.pcap")]
        sup.spawn("hub", hub_args + (["--config", opts.config] if opts.config else []))
        session = _wait_for_hub(sup, endpoint, keys, opts.startup_timeout)
        for rid, (x, y, heading) in enumerate(scenario.robot_poses, start=1):
            args = ["robot", "--id", str(rid), "--hub", endpoint, "--world", world, f"--pos={x},{y}"]
            args += ["--heading", str(heading), "--seed", str(opts.seed), "--protocol", opts.protocol]
            sup.spawn(f"robot-{rid}", [*args, "--record", str(record.events_of(f"robot-{rid}"))])
        _wait_for_robots(sup, session, keys, scenario.robot_count, opts.startup_timeout)
        if scenario.user is not None:
            user_args = ["user", "--scenario", str(scenario.path), "--hub", endpoint, "--world", world]
            user_args += ["--seed", str(opts.seed), "--record", str(record.events_of(scenario.user.node_id))]
            sup.spawn("user", [*user_args, "--duration", str(scenario.duration_s)])
        _follow(sup, session, keys, scenario.duration_s, timeline)
        summary = _summarise(session, keys, opts, world, endpoint)
        summary["problems"] = [p for p in summary["problems"] if "heard every other" not in p]  # no ping phase here
        summary.update(scenario=scenario.name, faults=timeline.applied, duration_s=scenario.duration_s)
    except (RunFailed, HubUnavailable) as err:
        _progress(f"failed: {err}")
        summary["problems"] = [f"failed: {err}"]
        return 1
    except KeyboardInterrupt:
        _progress("interrupted; stopping every process")
        summary["problems"] = ["interrupted"]
        return 130
    finally:
        if session is not None:
            session.close()
        codes = sup.stop_all()
        signal.signal(signal.SIGTERM, previous)
        record.finish(summary, codes)
    summary["driving"] = driving_metrics(read_world(record.path / "world.jsonl"))
    violations = check_record(record.path)
    summary["invariants"] = violations or "all hold"
    summary["problems"] += [f"invariant violated: {v}" for v in violations]
    summary["ok"] = not summary["problems"]
    record.finish(summary, codes)
    _print(summary, opts.as_json)
    if not opts.as_json:
        print(describe_driving(summary["driving"]))
    _progress(f"stopped {len(codes)} processes; record in {record.path}")
    return 0 if summary["ok"] else 1


def _follow(sup: Supervisor, session: zenoh.Session, keys: Keys, duration: float, timeline: FaultTimeline) -> None:
    """Apply the fault timeline and report progress until the user is done (or the duration is over)."""
    start = time.monotonic()
    next_report = start
    while (elapsed := time.monotonic() - start) < duration + 2.0:
        dead = sup.dead()
        if "user" in dead and dead["user"] == 0:
            return
        _check_alive(sup)
        timeline.apply_due(session, keys, elapsed)
        if time.monotonic() >= next_report:
            _progress(f"t={elapsed:5.1f}/{duration:g}s")
            next_report += 5.0
        time.sleep(0.1)


def describe_driving(driving: dict[str, Any]) -> str:
    """A few lines a person reads after a scenario run."""
    lines = [f"collisions {driving.get('collisions', 0)}"]
    error = driving.get("formation_error_all_m")
    if error:
        lines.append(f"formation error (all slaves): median {error['median']:.3f} m, p90 {error['p90']:.3f} m")
    distance = driving.get("user_master_distance_m")
    if distance:
        lines.append(f"user-master distance: median {distance['median']:.2f} m, p90 {distance['p90']:.2f} m")
    for reaction in driving.get("reactions", []):
        lines.append(
            f"user turn at {reaction['user_turn_at_s']:.1f} s: master reacted after {reaction['master_s']} s, "
            f"slaves {reaction['slaves_s']}"
        )
    return "\n".join(lines)
