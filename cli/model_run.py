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

import asyncio
import contextvars
import time
import weakref
from collections.abc import Callable, Coroutine
from contextlib import AsyncExitStack
from dataclasses import dataclass, field, replace
from pathlib import Path
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
    ping_robot_argv,
    progress,
    statuses,
    summarise,
)
from petswarm.clock import MODEL_EPOCH_S, ModelClockLoop
from petswarm.robot import Robot, RobotConfig
from petswarm.scenario import Scenario
from petswarm.sequence import EventLog
from petswarm.user import UserConfig, run_user
from radio_hub.environment import Environment, EnvironmentConfig, environment_from_dict, load_config
from radio_hub.interface import HubUnavailable, RadioClient

ENDPOINT = "memory"
"""What a model run records as its hub endpoint: there is no socket."""


class MemoryAir:
    """The environment on the running ``ModelClockLoop``, its nodes linked in memory (a ``Downlink``).

    ``pcap_path`` and ``world_log``: where the air's frames and the world's ground truth go (a run's record);
    None keeps them in memory only (tests)."""

    def __init__(
        self, config: EnvironmentConfig, seed: int, *, pcap_path: Path | None = None, world_log: Path | None = None
    ) -> None:
        self.loop = asyncio.get_running_loop()
        if not isinstance(self.loop, ModelClockLoop):
            raise TypeError("MemoryAir runs on a ModelClockLoop")
        self.env = Environment(
            config, seed, self, wall_epoch_us=round(MODEL_EPOCH_S * 1e6), pcap_path=pcap_path, world_log=world_log
        )
        self._nodes: dict[str, Callable[[bytes], None]] = {}
        self._wake: asyncio.TimerHandle | None = None
        self._wake_us = 0
        self._schedule()

    def now_us(self) -> int:
        """Model time in microseconds."""
        return round(self.loop.time() * 1e6)

    def link(self) -> MemoryLink:
        """A new node's port to this environment."""
        return MemoryLink(self)

    # -- Downlink ---------------------------------------------------------------------------------------

    def send(self, node_id: str, data: bytes) -> None:
        """Hand a message to the node's loop callback (after whatever is already due at this instant)."""
        on_down = self._nodes.get(node_id)
        if on_down is not None:
            self.loop.call_soon(on_down, data)

    def forget(self, node_id: str) -> None:
        """Nothing is kept per node beyond its link, which goes when the node closes it."""

    def publish_world(self, state: dict[str, Any]) -> None:
        """No viewers in memory: the record's world.jsonl holds the ground truth."""

    # -- from the nodes -----------------------------------------------------------------------------------

    def up(self, node_id: str, data: bytes) -> None:
        """A node's message reaches the environment now."""
        self.env.receive(node_id, data, self.now_us())
        self._schedule()

    def opened(self, node_id: str, on_down: Callable[[bytes], None]) -> None:
        """A node's link is open: deliver to ``on_down`` from now on."""
        self._nodes[node_id] = on_down

    def gone(self, node_id: str, instance: str) -> None:
        """A node's link closed (its liveliness ended)."""
        self._nodes.pop(node_id, None)
        self.env.node_gone(node_id, instance, self.now_us())
        self._schedule()

    def chaos(self, request: dict[str, Any]) -> dict[str, Any]:
        """A chaos request (``{"op": "add", "fault": {...}}``, ``{"op": "clear"}``...) now, as the hub's chaos
        queryable takes it; the answer, with ``error`` when the request was refused."""
        answer = self.env.chaos_request(request, self.now_us(), MODEL_EPOCH_S + self.now_us() / 1e6)
        self._schedule()  # a fault may change what is due next
        return answer

    # -- the schedule ---------------------------------------------------------------------------------------

    def _fire(self) -> None:
        self._wake = None
        self.env.advance(self.now_us())
        self._schedule()

    def _schedule(self) -> None:
        # one timer on the loop, always at the environment's next event (an input may bring that forward)
        due = self.env.next_event_us()
        if self._wake is not None:
            if self._wake_us <= due:
                return
            self._wake.cancel()
        self._wake_us = due
        self._wake = self.loop.call_at(due / 1e6, self._fire)


class MemoryLink:
    """A node's ``HubLink`` to a ``MemoryAir``: messages go both ways through the loop, in order."""

    def __init__(self, air: MemoryAir) -> None:
        self.air = air
        self.node_id = ""
        self.instance = ""
        self.closed = False

    def open(
        self, node_id: str, instance: str, on_down: Callable[[bytes], None], on_hub: Callable[[bool], None]
    ) -> None:
        """Register the node with the air (the hub is always present in memory)."""
        self.node_id, self.instance = node_id, instance
        self.air.opened(node_id, on_down)

    def put(self, data: bytes) -> None:
        """One message up, delivered after whatever is already due at this instant; nothing once closed (a node
        that has gone sends nothing more, whatever its leftover tasks try)."""
        if not self.closed:
            self.air.loop.call_soon(self.air.up, self.node_id, data)

    async def close(self) -> None:
        """The node goes: the environment detaches it once its last messages are in."""
        self.closed = True
        self.air.loop.call_soon(self.air.gone, self.node_id, self.instance)


_OWNER: contextvars.ContextVar[RunningRobot | None] = contextvars.ContextVar("model_robot", default=None)
"""The robot whose code is running: every task created meanwhile belongs to it (``RunningRobot.tasks``)."""


def _owned_task_factory(
    loop: asyncio.AbstractEventLoop, coro: Coroutine[Any, Any, Any], context: contextvars.Context | None = None
) -> asyncio.Task[Any]:
    """asyncio's own tasks, each noted by the robot that created it (a task inherits its creator's context), so
    that a robot can be stopped or killed as a whole, as the end of its process would end all its tasks."""
    task = asyncio.Task(coro, loop=loop, context=context)
    owner = context.get(_OWNER) if context is not None else _OWNER.get()
    if owner is not None:
        owner.adopt(task)
    return task


def _own_timers(loop: asyncio.AbstractEventLoop) -> None:
    """Make every timer the running robot's code sets (``call_later``, ``call_at``; a sleep's too) its own, as
    ``_owned_task_factory`` does for tasks: a killed robot's pending timeout must not fire into it."""
    plain_call_at = loop.call_at

    def call_at(when: float, callback: Callable[..., Any], *args: Any, context: Any = None) -> asyncio.TimerHandle:
        handle = plain_call_at(when, callback, *args, context=context)
        owner = context.get(_OWNER) if context is not None else _OWNER.get()
        if owner is not None:
            owner.timers.add(handle)
        return handle

    loop.call_at = call_at  # type: ignore[method-assign]


@dataclass
class RunningRobot:
    """A ``Robot`` running on a ``MemoryAir``: the object a robot process runs, and every task it started."""

    robot: Robot
    task: asyncio.Task[None] | None = None
    tasks: set[asyncio.Task[Any]] = field(default_factory=set)
    """Every live task the robot's code created (its managers' loops, rounds, rosters, handlers)."""
    timers: weakref.WeakSet[asyncio.TimerHandle] = field(default_factory=weakref.WeakSet)
    """Its pending timers (a fired one is dropped with the loop's last reference to it)."""
    gone: bool = False
    """Stopped or killed: it takes no more commands, and a task it would still start is cancelled at once."""

    def adopt(self, task: asyncio.Task[Any]) -> None:
        """``task`` was created by this robot's code."""
        if self.gone:
            task.cancel()  # a dead robot's leftover timer starts nothing
            return
        self.tasks.add(task)
        task.add_done_callback(self.tasks.discard)

    async def command(self, cmd: str, **args: Any) -> dict[str, Any]:
        """One control command, as the robot process's control queryable would carry it out (the tasks it
        starts, such as an organized swarm's rosters, are the robot's). HubUnavailable once it is gone."""
        if self.gone:
            raise HubUnavailable(f"robot {self.robot.config.robot_id} is gone")
        token = _OWNER.set(self)
        try:
            return await self.robot.handle({"cmd": cmd, **args})
        finally:
            _OWNER.reset(token)

    async def stop(self) -> None:
        """A clean stop, as on SIGTERM: the robot's loops end, its record gets its last event, its radio
        detaches; then whatever else it had started ends, as at the end of its process."""
        self.robot.stopping.set()
        try:
            if self.task is not None:
                await self.task
            await self.robot.close()
        finally:
            self._end()

    async def kill(self) -> None:
        """As SIGKILL: every task of the robot ends at once, with no last event and no detach; the environment
        forgets the node as the hub does when a process's liveliness ends."""
        self._end()
        await self.robot.rf.radio.close(detach=False)
        sink, self.robot.log.sink = self.robot.log.sink, None
        if sink is not None:
            sink.close()
        await asyncio.sleep(0)  # the cancelled tasks unwind now, not at some later step of the caller

    def _end(self) -> None:
        self.gone = True
        for timer in list(self.timers):
            timer.cancel()
        for task in list(self.tasks):
            task.cancel()


async def start_robot(config: RobotConfig, air: MemoryAir) -> RunningRobot:
    """A real ``Robot`` with ``config``, attached to ``air`` through memory and running (stop or kill it)."""
    loop = asyncio.get_running_loop()
    if loop.get_task_factory() is None:
        loop.set_task_factory(_owned_task_factory)  # type: ignore[arg-type]
        _own_timers(loop)
    radio = await RadioClient.connect(config.identity(), world=config.world, link=air.link(), timeout=5.0)
    running = RunningRobot(Robot(config, radio))
    token = _OWNER.set(running)
    try:
        running.task = loop.create_task(running.robot.run())
    finally:
        _OWNER.reset(token)
    return running


def start_user(config: UserConfig, air: MemoryAir, log: EventLog) -> asyncio.Task[int]:
    """The user process's coroutine (person, belt and watch) on ``air``; the task ends when the walk is over."""
    return asyncio.get_running_loop().create_task(run_user(config, log, link=air.link()))


def robot_config_of(argv: list[str]) -> RobotConfig:
    """The robot a ``petswarm robot`` command line describes."""
    from cli.main import build_parser, robot_config

    return robot_config(build_parser().parse_args(argv))


async def cancel_leftovers(loop: asyncio.AbstractEventLoop) -> None:
    """Cancel every task still pending and let them unwind, as ``asyncio.run`` does before it closes its loop
    (a closed loop with pending tasks warns "Task was destroyed but it is pending")."""
    current = asyncio.current_task()
    leftovers = [t for t in asyncio.all_tasks(loop) if t is not current]
    for task in leftovers:
        task.cancel()
    await asyncio.gather(*leftovers, return_exceptions=True)


@dataclass
class ModelControl:
    """``RunControl`` in model time: commands are calls on the robot objects."""

    robots: dict[int, RunningRobot] = field(default_factory=dict)

    async def command(self, robot: int, cmd: str, timeout: float = 5.0, **args: Any) -> dict[str, Any]:
        """One control command, as a robot process's control queryable would carry it out."""
        target = self.robots.get(robot)
        if target is None:
            raise HubUnavailable(f"no robot {robot} in this model run")
        async with asyncio.timeout(timeout):
            return await target.command(cmd, **args)

    async def sleep(self, seconds: float) -> None:
        """Model time goes on."""
        await asyncio.sleep(seconds)


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
        loop.run_until_complete(cancel_leftovers(loop))
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
    world_log = record.path / "world.jsonl" if scenario is not None else None
    air = MemoryAir(_environment(opts, scenario), opts.seed, pcap_path=record.path / "air.pcap", world_log=world_log)
    ctl = ModelControl()
    async with AsyncExitStack() as stack:
        stack.callback(air.env.close)
        argvs = _robot_argvs(opts, scenario, world, record)
        for rid, argv in argvs.items():
            ctl.robots[rid] = await _start_robot(argv, air, stack)
        progress(f"{len(ctl.robots)}/{len(argvs)} robots attached")
        if scenario is None:
            summary = await _ping_and_organize(opts, air, ctl, world)
        else:
            summary = await _drive(opts, scenario, air, ctl, world, record)
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


def _robot_argvs(opts: RunOptions, scenario: Scenario | None, world: str, record: RunRecord) -> dict[int, list[str]]:
    from cli.run_scenario import scenario_robot_argv

    if scenario is None:
        return {rid: ping_robot_argv(opts, rid, ENDPOINT, world, record) for rid in range(1, opts.robots + 1)}
    count = scenario.robot_count
    return {rid: scenario_robot_argv(opts, scenario, rid, ENDPOINT, world, record) for rid in range(1, count + 1)}


async def _start_robot(argv: list[str], air: MemoryAir, stack: AsyncExitStack) -> RunningRobot:
    """The robot a ``petswarm robot`` command line describes, attached through memory and running; stopped
    when ``stack`` closes."""
    running = await start_robot(robot_config_of(argv), air)
    stack.push_async_callback(running.stop)
    return running


async def _ping_and_organize(opts: RunOptions, air: MemoryAir, ctl: ModelControl, world: str) -> dict[str, Any]:
    timeline = FaultTimeline(list(opts.faults))
    chaos = air.chaos
    start = asyncio.get_running_loop().time()
    for second in range(1, int(opts.duration) + 1):
        timeline.apply_due(chaos, float(second - 1))
        await asyncio.sleep(1.0)
        _report(air, f"t={second:5.1f}/{opts.duration:g}s")
    await asyncio.sleep(max(0.0, start + opts.duration - asyncio.get_running_loop().time()))
    timeline.apply_due(chaos, float("inf"))  # what is left acts on the swarm phase
    swarm = await organize_and_disperse(ctl, opts) if opts.organize else {}
    summary = await _summary(opts, air, ctl, world)
    summary["faults"] = timeline.applied
    problems = summary["problems"] + swarm.pop("problems", [])
    summary.update(swarm, problems=problems, ok=not problems)
    return summary


async def _drive(
    opts: RunOptions, scenario: Scenario, air: MemoryAir, ctl: ModelControl, world: str, record: RunRecord
) -> dict[str, Any]:
    opts = _scenario_options(opts, scenario)
    user_task = None
    if scenario.user is not None:
        config = UserConfig(
            scenario.user, ENDPOINT, world, scenario.duration_s, opts.seed, beacon=scenario.surround_enabled
        )
        sink = open(record.events_of(scenario.user.node_id), "a")  # noqa: SIM115 (closed below)
        user_task = start_user(config, air, EventLog(sink=sink))
        user_task.add_done_callback(lambda _task: sink.close())
    timeline = FaultTimeline(list(scenario.faults) + list(opts.faults))
    chaos = air.chaos
    loop = asyncio.get_running_loop()
    start = loop.time()
    while (elapsed := loop.time() - start) < scenario.duration_s:
        timeline.apply_due(chaos, elapsed)
        if user_task is not None and user_task.done():
            break
        await asyncio.sleep(min(0.1, scenario.duration_s - elapsed))
        if round(loop.time() - start, 6) % 5 == 0:
            _report(air, f"t={loop.time() - start:5.1f}/{scenario.duration_s:g}s")
    if user_task is not None:
        await user_task
    summary = await _summary(opts, air, ctl, world)
    summary["problems"] = [p for p in summary["problems"] if "heard every other" not in p]  # no ping phase here
    summary.update(scenario=scenario.name, faults=timeline.applied, duration_s=scenario.duration_s)
    summary["ok"] = not summary["problems"]
    return summary


def _scenario_options(opts: RunOptions, scenario: Scenario) -> RunOptions:
    return replace(opts, robots=scenario.robot_count, duration=scenario.duration_s)


async def _summary(opts: RunOptions, air: MemoryAir, ctl: ModelControl, world: str) -> dict[str, Any]:
    stats = {"world": world, **air.env.stats(air.now_us())}
    return summarise(stats, await statuses(ctl, opts.robots), opts, world, ENDPOINT)


def _report(air: MemoryAir, what: str) -> None:
    totals = {"sent": 0, "delivered": 0, "collided": 0, "lost": 0}
    for counters in air.env.medium.node_counters.values():
        for name in totals:
            totals[name] += getattr(counters, name, 0)
    progress(
        f"{what}  sent {totals['sent']}  delivered {totals['delivered']}  "
        f"collided {totals['collided']}  lost {totals['lost']}"
    )
