"""``petswarm run --clock model``: the hub's environment and every robot and user in one process, on model time.

The environment (``radio_hub.environment``) is driven by a ``ModelClockLoop``: its next event is a timer on
the loop, and every node's ``RadioClient`` reaches it through a ``MemoryLink`` instead of zenoh. The robots and
the user are the very objects a robot or user process runs (built from the same command lines), so the only
difference from a wall-clock run is what carries messages and what moves time: nothing sleeps, a run goes as
fast as the CPU allows, and the same seed and options give the same run (``digest``) on any machine, loaded or
idle. Messages between a node and the environment take no time; the air's own timing (airtime, backoffs,
ACKs) is modelled in the environment as in the hub.
"""

from __future__ import annotations

import argparse
import asyncio
import functools
import math
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from cli.checker import check_record
from cli.digest import record_digest
from cli.metrics import driving_metrics, read_world
from cli.records import RunRecord
from cli.run import (
    FaultTimeline,
    RunOptions,
    _print,
    organize_and_disperse,
    organize_shortfall,
    ping_robot_argv,
    progress,
    statuses,
    summarise,
)
from petswarm.clock import MODEL_EPOCH_S, ModelClockLoop
from petswarm.control import RelayControl
from petswarm.robot import Robot
from petswarm.scenario import Scenario
from petswarm.sequence import EventLog
from petswarm.user import UserConfig, run_user
from radio_hub.coordinator import Coordinator
from radio_hub.environment import EnvironmentConfig, environment_from_dict, load_config
from radio_hub.interface import RadioClient, RadioIdentity

ENDPOINT = "memory"
"""What a model run records as its hub endpoint: there is no socket."""
CONTROL_IDENTITY = RadioIdentity("run", 0, 0, 0, kind="control")
"""The run's orchestrator as a node of the world: it only relays (commands to robots, questions to the hub)."""


class MemoryAir:
    """The coordinator's environment on the running ``ModelClockLoop``, its nodes linked in memory.

    "Every node is idle" is the loop having nothing ready: then held messages are released, or held node
    messages settled, before model time moves (``radio_hub.coordinator`` gives the rules).
    """

    def __init__(self, coordinator: Coordinator) -> None:
        self.loop = asyncio.get_running_loop()
        if not isinstance(self.loop, ModelClockLoop):
            raise TypeError("MemoryAir runs on a ModelClockLoop")
        self.coordinator = coordinator
        self.env = coordinator.env
        self._nodes: dict[str, Callable[[bytes], None]] = {}
        self._wake: asyncio.TimerHandle | None = None
        self._wake_us = 0
        self.loop.on_quiescent = self.quiescent
        self._schedule()

    def now_us(self) -> int:
        """Model time in microseconds."""
        return round(self.loop.time() * 1e6)

    def link(self) -> MemoryLink:
        """A new node's port to this environment."""
        return MemoryLink(self)

    def opened(self, node_id: str, on_down: Callable[[bytes], None]) -> None:
        """A node's link is open: deliver to ``on_down`` from now on."""
        self._nodes[node_id] = on_down

    def up(self, node_id: str, data: bytes) -> None:
        """A node's message, held until every node is idle."""
        self.coordinator.up(node_id, data)

    def gone(self, node_id: str, instance: str) -> None:
        """A node's link closed."""
        self._nodes.pop(node_id, None)
        self.coordinator.leave(node_id, instance)

    def quiescent(self) -> bool:
        """Nothing is ready: release what is held for nodes, else settle what nodes sent; True when something
        became ready."""
        delivered = False
        for node_id, messages in self.coordinator.take_downs().items():
            on_down = self._nodes.get(node_id)
            if on_down is None:  # a node that left meanwhile
                continue
            for data in messages:
                self.loop.call_soon(on_down, data)
            delivered = True
        if delivered:
            return True
        if self.coordinator.settle(self.now_us()):
            self._schedule()
            return self.quiescent()
        return False

    def _fire(self) -> None:
        self._wake = None
        self.coordinator.advance(self.now_us())
        self._schedule()

    def _schedule(self) -> None:
        # one timer on the loop, always at the environment's next event (an input may bring that forward)
        due = self.coordinator.next_event_us()
        if self._wake is not None:
            if self._wake_us <= due:
                return
            self._wake.cancel()
        self._wake_us = due
        self._wake = self.loop.call_at(due / 1e6, self._fire)


class MemoryLink:
    """A node's ``HubLink`` to a ``MemoryAir``."""

    def __init__(self, air: MemoryAir) -> None:
        self.air = air
        self.node_id = ""
        self.instance = ""

    def open(
        self, node_id: str, instance: str, on_down: Callable[[bytes], None], on_hub: Callable[[bool], None]
    ) -> None:
        """Register the node with the air (the hub is always present in memory)."""
        self.node_id, self.instance = node_id, instance
        self.air.opened(node_id, on_down)

    def put(self, data: bytes) -> None:
        """One message up, held until every node is idle."""
        self.air.up(self.node_id, data)

    async def close(self) -> None:
        """The node goes."""
        self.air.gone(self.node_id, self.instance)


def run_model(opts: RunOptions, scenario: Scenario | None) -> int:
    """The run in model time, printed as a wall-clock run's is; returns the exit code."""
    try:
        summary = execute(opts, scenario)
    except KeyboardInterrupt:
        progress("interrupted")
        return 130
    progress(
        f"{summary['model_time_s']:.1f} s of model time in {summary['wall_time_s']:.2f} s "
        f"({summary['speedup']:g}x); digest {summary['digest'][:16]}"
    )
    _print(summary, opts.as_json)
    return 0 if summary["ok"] else 1


def execute(opts: RunOptions, scenario: Scenario | None) -> dict[str, Any]:
    """Run in model time and leave the record (``summary.json`` too, also when interrupted); the summary."""
    if scenario is not None:
        opts = replace(opts, robots=scenario.robot_count, duration=scenario.duration_s)
    world = opts.world or f"model-{opts.seed}"
    record = RunRecord.create(opts, world, ENDPOINT)
    progress(f"world {world}, seed {opts.seed}, model time, record in {record.path}")
    started = time.perf_counter()
    loop = ModelClockLoop()
    summary: dict[str, Any] = {"ok": False, "problems": ["interrupted"], "seed": opts.seed}
    try:
        summary = loop.run_until_complete(_run(opts, scenario, world, record))
    finally:
        model_time_s = loop.time()
        loop.close()
        summary["clock"] = "model"
        summary["model_time_s"] = round(model_time_s, 6)
        summary["wall_time_s"] = round(time.perf_counter() - started, 3)
        summary["speedup"] = round(model_time_s / max(summary["wall_time_s"], 1e-9), 1)
        record.finish(summary, {})
    if scenario is not None:
        summary["driving"] = driving_metrics(read_world(record.path / "world.jsonl"))
    violations = check_record(record.path)
    summary["invariants"] = violations or "all hold"
    summary["problems"] += [f"invariant violated: {v}" for v in violations]
    summary["ok"] = not summary["problems"]
    summary["digest"] = record_digest(record.path)
    summary["record"] = str(record.path)
    record.finish(summary, {})
    return summary


async def _run(opts: RunOptions, scenario: Scenario | None, world: str, record: RunRecord) -> dict[str, Any]:
    coordinator = Coordinator(
        _environment(opts, scenario),
        opts.seed,
        wall_epoch_us=round(MODEL_EPOCH_S * 1e6),
        pcap_path=record.path / "air.pcap",
        world_log=record.path / "world.jsonl" if scenario is not None else None,
    )
    air = MemoryAir(coordinator)
    try:
        # every node starts at model time 0 and attaches in the same round, as lockstep processes do
        argvs = robot_argvs(opts, scenario, world, record)
        loop = asyncio.get_running_loop()
        robots = [loop.create_task(_run_robot(argv, air)) for argv in argvs.values()]
        user = _start_user(opts, scenario, world, record, air)
        radio = await RadioClient.connect(CONTROL_IDENTITY, world=world, link=air.link(), timeout=5.0)
        ctl = RelayControl(radio)
        summary = await orchestrate(opts, scenario, ctl, world)
        if user is not None:
            await user
        await asyncio.gather(*robots)
        await radio.close()
    finally:
        coordinator.close()
    return summary


def _environment(opts: RunOptions, scenario: Scenario | None) -> EnvironmentConfig:
    """The hub's tables: ``--config``, and the scenario's world (as ``petswarm hub --scenario`` takes them)."""
    config = load_config(opts.config) if opts.config else EnvironmentConfig()
    if scenario is None:
        return config
    tables = environment_from_dict(scenario.hub_tables())
    if opts.config:
        tables.medium, tables.ir = config.medium, config.ir
    return tables


def robot_argvs(
    opts: RunOptions, scenario: Scenario | None, world: str, record: RunRecord, endpoint: str = ENDPOINT
) -> dict[int, list[str]]:
    """The ``petswarm robot`` command lines of the run's robots, by id."""
    from cli.run_scenario import scenario_robot_argv

    if scenario is None:
        return {rid: ping_robot_argv(opts, rid, endpoint, world, record) for rid in range(1, opts.robots + 1)}
    count = scenario.robot_count
    return {rid: scenario_robot_argv(opts, scenario, rid, endpoint, world, record) for rid in range(1, count + 1)}


async def _run_robot(argv: list[str], air: MemoryAir) -> None:
    """The robot a ``petswarm robot`` command line describes, attached through memory, until told to stop."""
    from cli.main import robot_config

    config = robot_config(_parser().parse_args(argv))
    radio = await RadioClient.connect(config.identity(), world=config.world, link=air.link(), timeout=5.0)
    robot = Robot(config, radio)
    try:
        await robot.run()
    finally:
        await robot.close()


@functools.cache
def _parser() -> argparse.ArgumentParser:
    # building the CLI's parser costs milliseconds: once per run, not once per robot
    from cli.main import build_parser

    return build_parser()


def _start_user(
    opts: RunOptions, scenario: Scenario | None, world: str, record: RunRecord, air: MemoryAir
) -> asyncio.Task[int] | None:
    if scenario is None or scenario.user is None:
        return None
    config = UserConfig(
        scenario.user, ENDPOINT, world, scenario.duration_s, opts.seed, beacon=scenario.surround_enabled
    )
    sink = open(record.events_of(scenario.user.node_id), "a")  # noqa: SIM115 (closed when the user is done)
    task = asyncio.get_running_loop().create_task(run_user(config, EventLog(sink=sink), link=air.link()))
    task.add_done_callback(lambda _task: sink.close())
    return task


async def orchestrate(opts: RunOptions, scenario: Scenario | None, ctl: RelayControl, world: str) -> dict[str, Any]:
    """What a model or lockstep run does, on model time, through the relay: wait for the robots, the
    traffic or scenario phase with its faults, the summary, then every robot told to stop."""
    await _wait_attached(ctl, opts.robots)
    faults = FaultTimeline(list(opts.faults) + (list(scenario.faults) if scenario is not None else []))
    if scenario is None:
        summary = await _ping_and_organize(opts, ctl, faults, world)
    else:
        summary = await _follow_scenario(opts, scenario, ctl, faults, world)
    for rid in range(1, opts.robots + 1):
        await ctl.command(rid, "stop")
    return summary


async def _wait_attached(ctl: RelayControl, robots: int) -> None:
    while True:
        stats = await ctl.hub("stats")
        attached = sum(1 for node in stats["nodes"].values() if node["attached"])
        if attached >= robots:
            progress(f"{attached}/{robots} robots attached")
            return
        await ctl.sleep(0.1)


async def _apply_faults(ctl: RelayControl, faults: FaultTimeline, elapsed: float) -> None:
    for at, request in faults.take_due(elapsed):
        answer = await ctl.hub("chaos", request=request)
        faults.applied_or_refused(at, request, answer)


async def _ping_and_organize(opts: RunOptions, ctl: RelayControl, faults: FaultTimeline, world: str) -> dict[str, Any]:
    notes = organize_shortfall(opts)
    for note in notes:
        progress(f"warning: {note}")
    start = asyncio.get_running_loop().time()
    for second in range(1, math.ceil(opts.duration) + 1):
        until = min(float(second), opts.duration)
        while (elapsed := asyncio.get_running_loop().time() - start) < until:
            await _apply_faults(ctl, faults, elapsed)
            await ctl.sleep(min(0.1, until - elapsed))
        _report(await ctl.hub("stats"), f"t={until:5.1f}/{opts.duration:g}s")
    await _apply_faults(ctl, faults, float("inf"))  # what is left acts on the swarm phase
    swarm = await organize_and_disperse(ctl, opts) if opts.organize else {}
    summary = await _summary(opts, ctl, world)
    summary["faults"] = faults.applied
    summary["notes"] = notes
    problems = summary["problems"] + swarm.pop("problems", [])
    summary.update(swarm, problems=problems, ok=not problems)
    return summary


async def _follow_scenario(
    opts: RunOptions, scenario: Scenario, ctl: RelayControl, faults: FaultTimeline, world: str
) -> dict[str, Any]:
    loop = asyncio.get_running_loop()
    start = loop.time()
    next_report = 5.0
    while (elapsed := loop.time() - start) < scenario.duration_s:
        await _apply_faults(ctl, faults, elapsed)
        await ctl.sleep(min(0.1, scenario.duration_s - elapsed))
        if loop.time() - start >= next_report:
            progress(f"t={next_report:5.1f}/{scenario.duration_s:g}s")
            next_report += 5.0
    summary = await _summary(opts, ctl, world)
    summary["problems"] = [p for p in summary["problems"] if "heard every other" not in p]  # no ping phase here
    summary.update(scenario=scenario.name, faults=faults.applied, duration_s=scenario.duration_s)
    summary["ok"] = not summary["problems"]
    return summary


async def _summary(opts: RunOptions, ctl: RelayControl, world: str) -> dict[str, Any]:
    stats = {"world": world, **await ctl.hub("stats")}
    return summarise(stats, await statuses(ctl, opts.robots), opts, world, ENDPOINT)


def _report(stats: dict[str, Any], what: str) -> None:
    totals = {"sent": 0, "delivered": 0, "collided": 0, "lost": 0}
    for node in stats["nodes"].values():
        for name in totals:
            totals[name] += node.get(name, 0)
    progress(
        f"{what}  sent {totals['sent']}  delivered {totals['delivered']}  "
        f"collided {totals['collided']}  lost {totals['lost']}"
    )
