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
import contextlib
import contextvars
import dataclasses
import json
import math
import sys
import time
import weakref
from collections.abc import Awaitable, Callable, Collection, Coroutine
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from petswarm.clock import MODEL_EPOCH_S, ModelClockLoop
from petswarm.control import RelayControl
from petswarm.lab.checker import check_record
from petswarm.lab.digest import record_digest
from petswarm.lab.foxglove_live import RunStream, StreamUnavailable, start_stream
from petswarm.lab.hub_tables import hub_environment
from petswarm.lab.metrics import driving_metrics, read_world
from petswarm.lab.processes import Interrupts
from petswarm.lab.records import RunRecord
from petswarm.lab.robot_command import RobotOptions, robot_config
from petswarm.lab.run import (
    HEARING_PROBLEMS,
    FaultTimeline,
    RunFailed,
    RunOptions,
    _print,
    organize_and_disperse,
    organize_shortfall,
    ping_robot_options,
    progress,
    statuses,
    summarise,
)
from petswarm.managers.event_log import EventLog
from petswarm.robot import Robot, RobotConfig
from petswarm.scenario import Scenario, is_action
from petswarm.wearables.user import UserConfig, run_user
from radio_hub.hosting import (
    HANDED_OVER,
    MODEL_EPOCH_US,
    Coordinator,
    EnvironmentConfig,
)
from radio_hub.interface import RadioClient
from radio_hub.values import HubUnavailable, RadioIdentity

if TYPE_CHECKING:
    from radio_hub.values import Message

ENDPOINT = "memory"
"""What a model run records as its hub endpoint: there is no socket."""
CONTROL_IDENTITY = RadioIdentity("run", 0, 0, 0, kind="control")
"""The run's orchestrator as a node of the world: it only relays (commands to robots, questions to the hub)."""


class MemoryAir:
    """The coordinator's environment on the running ``ModelClockLoop``, its nodes linked in memory.

    "Every node is idle" is the loop having nothing ready: then held messages are released, or held node
    messages settled, before model time moves (``radio_hub.coordinator`` gives the rules).
    """

    def __init__(
        self, config: EnvironmentConfig, seed: int, *, pcap_path: Path | None = None, world_log: Path | None = None
    ) -> None:
        """``pcap_path`` and ``world_log``: where the air's frames and the world's ground truth go (a run's
        record); None keeps them in memory only (tests)."""
        self.loop = asyncio.get_running_loop()
        if not isinstance(self.loop, ModelClockLoop):
            raise TypeError("MemoryAir runs on a ModelClockLoop")
        self.coordinator = Coordinator(
            config, seed, wall_epoch_us=MODEL_EPOCH_US, pcap_path=pcap_path, world_log=world_log, in_memory=True
        )
        self.env = self.coordinator.env
        self._nodes: dict[str, tuple[Callable[[bytes | Message], None], Callable[[Message], None] | None]] = {}
        self._settled: list[asyncio.Future[None]] = []
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

    def opened(
        self,
        node_id: str,
        on_down: Callable[[bytes | Message], None],
        on_built: Callable[[Message], None] | None = None,
    ) -> None:
        """A node's link is open: deliver to ``on_down`` from now on, and the environment's ``HANDED_OVER``
        messages to ``on_built`` if given (``RadioClient.on_built``: they are the environment's own)."""
        self._nodes[node_id] = (on_down, on_built)

    def up(self, node_id: str, data: bytes | Message) -> None:
        """A node's message (bytes, or one handed over as it is), held until every node is idle."""
        self.coordinator.up(node_id, data)

    def gone(self, node_id: str, instance: str) -> None:
        """A node's link closed."""
        self._nodes.pop(node_id, None)
        self.coordinator.leave(node_id, instance)

    def chaos(self, request: dict[str, Any]) -> dict[str, Any]:
        """A chaos request (``{"op": "add", "fault": {...}}``, ``{"op": "clear"}``...) now, as the hub's chaos
        queryable takes it (tests; a run's faults go through the relay, held like every node message)."""
        answer = self.env.chaos_request(request, self.now_us(), MODEL_EPOCH_S + self.now_us() / 1e6)
        self._schedule()  # a fault may change what is due next
        return answer

    def quiescent(self) -> bool:
        """Nothing is ready: release what is held for nodes, else settle what nodes sent; True when something
        became ready."""
        delivered = False
        for node_id, messages in self.coordinator.take_downs().items():
            handlers = self._nodes.get(node_id)
            if handlers is None:  # a node that left meanwhile
                continue
            # one callback per node for all its messages, in order: as a callback each, every one of them runs
            # before anything they make ready (that is queued behind every node's delivery either way)
            self.loop.call_soon(self._deliver, *handlers, messages)
            delivered = True
        if delivered:
            return True
        if self.coordinator.settle(self.now_us()):
            self._schedule()
            return self.quiescent()
        waiting, self._settled = self._settled, []
        for future in waiting:
            future.set_result(None)
        return bool(waiting)

    def _deliver(
        self,
        on_down: Callable[[bytes | Message], None],
        on_built: Callable[[Message], None] | None,
        messages: list[bytes | Message],
    ) -> None:
        """A node's messages of this round, one after another; a message whose handling fails is reported as
        a callback's error is, and the next ones still come. Only the environment holds messages for nodes
        (``Coordinator.send_message``), so one of the ``HANDED_OVER`` types is its own: it goes to ``on_built``
        when the node has one."""
        for data in messages:
            try:
                if on_built is not None and type(data) in HANDED_OVER:
                    on_built(data)  # type: ignore[arg-type]
                else:
                    on_down(data)
            except (SystemExit, KeyboardInterrupt):
                raise
            except BaseException as err:
                self.loop.call_exception_handler({"message": f"Exception in callback {on_down!r}", "exception": err})

    async def settled(self) -> None:
        """Until every message of this instant, held both ways, has been handled (no model time passes)."""
        future: asyncio.Future[None] = self.loop.create_future()
        self._settled.append(future)
        await future

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

    takes_messages = True
    """Motor commands and a user's pose go up as they are (``put_message``), without their bytes."""

    def __init__(self, air: MemoryAir) -> None:
        self.air = air
        self.on_built: Callable[[Message], None] | None = None
        """Where the environment's own messages go (``RadioClient.on_built``, set before ``open``)."""
        self.node_id = ""
        self.instance = ""
        self.closed = False

    def open(
        self,
        node_id: str,
        instance: str,
        on_down: Callable[[bytes | Message], None],
        on_hub: Callable[[bool], None],
    ) -> None:
        """Register the node with the air (the hub is always present in memory); the body-sensor and beacon
        messages reach it as they are, without their bytes (``Coordinator(in_memory=True)``)."""
        self.node_id, self.instance = node_id, instance
        self.air.opened(node_id, on_down, self.on_built)

    def put(self, data: bytes) -> None:
        """One message up, held until every node is idle; nothing once closed (a node that has gone sends
        nothing more, whatever its leftover tasks try)."""
        if not self.closed:
            self.air.up(self.node_id, data)

    def put_message(self, msg: Message) -> None:
        """``put`` of a message as it is (the port's ``HANDED_UP`` ones)."""
        if not self.closed:
            self.air.up(self.node_id, msg)

    async def close(self) -> None:
        """The node goes."""
        if not self.closed:
            self.closed = True
            self.air.gone(self.node_id, self.instance)


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
    air: MemoryAir
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
        await self.air.settled()  # the cancelled tasks unwind and the environment forgets the node, now

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
    running = RunningRobot(Robot(config, radio), air)
    token = _OWNER.set(running)
    try:
        running.task = loop.create_task(running.robot.run())
    finally:
        _OWNER.reset(token)
    return running


def start_user(config: UserConfig, air: MemoryAir, log: EventLog) -> asyncio.Task[int]:
    """The user process's coroutine (person, belt and watch) on ``air``; the task ends when the walk is over."""
    return asyncio.get_running_loop().create_task(run_user(config, log, link=air.link()))


async def cancel_leftovers(loop: asyncio.AbstractEventLoop, within_s: float | None = None) -> None:
    """Cancel every task still pending and let them unwind, as ``asyncio.run`` does before it closes its loop
    (a closed loop with pending tasks warns "Task was destroyed but it is pending"); with ``within_s``, for at
    most that long (model seconds on a model-time loop)."""
    current = asyncio.current_task()
    leftovers = [t for t in asyncio.all_tasks(loop) if t is not current]
    for task in leftovers:
        task.cancel()
    if within_s is None:
        await asyncio.gather(*leftovers, return_exceptions=True)
    elif leftovers:
        await asyncio.wait(leftovers, timeout=within_s)


UNWIND_MODEL_S = 10.0
"""Model seconds an interrupted run's leftover tasks have to unwind once cancelled (a robot's last words)."""


def unwind(loop: ModelClockLoop) -> None:
    """Cancel and unwind the tasks an interrupted run left on ``loop`` before it closes: a closed loop reports
    each pending task as destroyed ("Task was destroyed but it is pending!"), 300 kB of them on the terminal for
    a 50-robot run stopped with Ctrl-C. The record is finished after this, as it stands."""
    loop.set_exception_handler(_quiet_about_the_interrupt)
    with contextlib.suppress(Exception):  # stalled: the loop closes all the same
        loop.run_until_complete(cancel_leftovers(loop, UNWIND_MODEL_S))


def _quiet_about_the_interrupt(loop: asyncio.AbstractEventLoop, context: dict[str, Any]) -> None:
    if isinstance(context.get("exception"), KeyboardInterrupt):
        return  # the interrupt itself, in the task it landed in ("exception never retrieved"): the run said so
    loop.default_exception_handler(context)


def run_model(opts: RunOptions, scenario: Scenario | None) -> int:
    """The run in model time, printed as a wall-clock run's is; returns the exit code."""
    try:
        summary = execute(opts, scenario)
    except StreamUnavailable as err:
        print(f"petswarm run: --foxglove {opts.foxglove}: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        progress("interrupted")
        return 130
    progress(
        f"{summary['model_time_s']:.1f} s of model time in {summary['wall_time_s']:.2f} s "
        f"({summary['speedup']:g}x); digest {summary['digest'][:16]}"
    )
    _print(summary, opts.as_json)
    return 0 if summary["ok"] else 1


def scenario_options(scenario: Scenario, seed: int, record_dir: str | Path) -> RunOptions:
    """``petswarm run SCENARIO --clock model --seed SEED --record DIR --json`` without pings: how the exploration
    and the model-time tests run a scenario."""
    return RunOptions(
        robots=scenario.robot_count,
        seed=seed,
        duration=scenario.duration_s,
        ping_interval=0.0,
        record_dir=str(record_dir),
        as_json=True,
        clock="model",
    )


def execute(opts: RunOptions, scenario: Scenario | None) -> dict[str, Any]:
    """Run in model time and leave the record (``summary.json`` too, also when interrupted); the summary."""
    if scenario is not None:
        opts = opts.for_scenario(scenario)
    world = opts.world or f"model-{opts.seed}"
    stream = start_stream(opts.foxglove, world, None)  # before any record: its port may be taken
    record = RunRecord.create(opts, world, ENDPOINT)
    if stream is not None:
        stream.follow(record.path, progress)
    progress(f"world {world}, seed {opts.seed}, model time, record in {record.path}")
    started = time.perf_counter()
    loop = ModelClockLoop()
    summary: dict[str, Any] = {"ok": False, "problems": ["interrupted"], "seed": opts.seed}
    # SIGTERM (timeout, compose, a CI job cancelled) ends the run as Ctrl-C does, with its summary: at its
    # default action it ended the process where it stood and the record had no summary.json at all
    interrupts = Interrupts(at_safe_points=True)
    loop.checkpoint = interrupts.check  # raised between two passes: never lost in a weakref callback (Interrupts)
    finished = False
    try:
        summary = loop.run_until_complete(_run(opts, scenario, world, record, stream))
        finished = True
    except KeyboardInterrupt:
        summary["interrupted"] = True
        raise
    except Exception as err:  # the record says what ended the run, not "interrupted"
        summary["problems"] = [f"failed: {type(err).__name__}: {err}"]
        raise
    finally:
        with interrupts.deferred():  # a second signal waits for the summary (Interrupts)
            model_time_s = loop.time()
            if not finished:
                unwind(loop)
            loop.close()
            if stream is not None:
                stream.close()
            summary["clock"] = "model"
            summary["model_time_s"] = round(model_time_s, 6)
            summary["wall_time_s"] = round(time.perf_counter() - started, 3)
            summary["speedup"] = round(model_time_s / max(summary["wall_time_s"], 1e-9), 1)
            if finished and (interrupts.pending or interrupts.noted):  # after the last pass: the checks are cut
                summary["interrupted"] = True
                summary["ok"] = False
                summary["problems"] = [*summary.get("problems", []), "interrupted"]
            record.finish(summary, {})
            if summary.get("interrupted") and opts.as_json:
                _print(summary, as_json=True)  # --json promises a summary, interrupted too
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


async def _run(
    opts: RunOptions, scenario: Scenario | None, world: str, record: RunRecord, stream: RunStream | None = None
) -> dict[str, Any]:
    world_log = record.path / "world.jsonl" if scenario is not None else None
    air = MemoryAir(
        hub_environment(opts.config, scenario, opts.profile),
        opts.seed,
        pcap_path=record.path / "air.pcap",
        world_log=world_log,
    )
    if stream is not None:  # the world states a hub would publish for viewers (the environment then makes them)
        air.coordinator.on_world = stream.offer
    try:
        # every node starts at model time 0 and attaches in the same round, as lockstep processes do
        robots = run_robots(opts, scenario, world, record)
        cast = Cast(air, robots, record)
        for rid in robots:
            cast.start(rid)
        user = _start_user(opts, scenario, world, record, air)
        radio = await RadioClient.connect(CONTROL_IDENTITY, world=world, link=air.link(), timeout=5.0)
        ctl = RelayControl(radio)
        summary = await orchestrate(opts, scenario, ctl, world, cast.dead, cast.act)
        if user is not None:
            await user
        await asyncio.gather(*cast.tasks)
        await radio.close()
        await cancel_leftovers(asyncio.get_running_loop())
    finally:
        air.coordinator.close()
    return summary


def run_robots(
    opts: RunOptions, scenario: Scenario | None, world: str, record: RunRecord, endpoint: str = ENDPOINT
) -> dict[int, RobotOptions]:
    """The options of the run's robots, by id (a process run starts each with its ``argv()``)."""
    from petswarm.lab.run_scenario import scenario_robot_options

    if scenario is None:
        return {rid: ping_robot_options(opts, rid, endpoint, world, record) for rid in range(1, opts.robots + 1)}
    count = scenario.robot_count
    return {rid: scenario_robot_options(opts, scenario, rid, endpoint, world, record) for rid in range(1, count + 1)}


class Cast:
    """The run's robots by id, and the scenario's actions on them (``petswarm.scenario.ACTIONS``): a robot
    killed as by SIGKILL, restarted as a fresh process of the same id, the wearables' BLE link lost and back.
    Deaths and restarts go to the record's ``supervision.jsonl`` as a wall-clock run's supervisor writes them."""

    def __init__(self, air: MemoryAir, robots: dict[int, RobotOptions], record: RunRecord) -> None:
        self.air, self.robots, self.record = air, robots, record
        self.running: dict[int, RunningRobot] = {}
        self.tasks: list[asyncio.Task[None]] = []
        self._dead: set[int] = set()
        self._ble: Any = None
        self._died_at: dict[int, tuple[float, float, float]] = {}
        """Where a killed robot's body stands (x, y, heading in degrees) until it restarts there."""

    def dead(self) -> frozenset[int]:
        """The robots killed and not restarted (neither asked nor expected to do anything)."""
        return frozenset(self._dead)

    def start(self, rid: int) -> None:
        """Robot ``rid``'s process starts (again: where its body stood when it died, as a robot restarted in place,
        not back at its start pose, into whatever drove there since)."""
        options = self.robots[rid]
        if rid in self._died_at:
            x, y, heading = self._died_at.pop(rid)
            options = dataclasses.replace(options, pos=(x, y), heading=heading)
        config = robot_config(options)
        self.tasks.append(asyncio.get_running_loop().create_task(_run_robot(config, self.air, self.running)))

    async def act(self, action: dict[str, Any]) -> None:
        """Carry out one scenario action now."""
        kind, rid = action["kind"], action.get("robot")
        if kind == "kill" and rid not in self._dead and rid in self.running:
            self._dead.add(rid)
            world = self.air.env.world
            body = world.bodies.get(f"robot-{rid}")
            await self.running[rid].kill()
            if body is not None:
                # the environment forgot the node (its radio is off the air), but a dead robot's body still
                # stands where it stopped: others must drive round it, and it restarts there
                x, y, yaw = (float(v) for v in body.pose)
                self._died_at[rid] = (x, y, math.degrees(yaw))
                if body.body_id not in world.bodies:
                    world.add(body.body_id, body.kind, x, y, yaw)
            self._supervision("died", rid, cause="killed by the scenario")
        elif kind == "restart" and rid in self._dead:
            self._dead.discard(rid)
            self._supervision("restarted", rid)
            self.start(rid)
        elif kind == "wearable_lost" and self._ble is None:
            ble = self.air.env.ble
            self._ble = ble.config
            ble.config = dataclasses.replace(ble.config, range_m=1e-9)  # every message out of range: no link
        elif kind == "wearable_back" and self._ble is not None:
            self.air.env.ble.config, self._ble = self._ble, None

    def _supervision(self, what: str, rid: int, **detail: Any) -> None:
        entry = {"kind": what, "process": f"robot-{rid}", "mono": round(self.air.loop.time(), 6), **detail}
        with open(self.record.path / "supervision.jsonl", "a") as out:
            out.write(json.dumps(entry) + "\n")


async def _run_robot(config: RobotConfig, air: MemoryAir, running_by_id: dict[int, RunningRobot] | None = None) -> None:
    """The robot ``config`` describes, attached through memory, until told to stop (or killed:
    ``RunningRobot.kill``)."""
    running = await start_robot(config, air)
    if running_by_id is not None:
        running_by_id[config.robot_id] = running
    try:
        assert running.task is not None
        await running.task
        await running.robot.close()
    except asyncio.CancelledError:
        if running.gone and running_by_id is not None and running_by_id.get(config.robot_id) is running:
            return  # killed by the scenario: its process is over, the run goes on
        if not running.gone:  # the run was interrupted (a killed robot, gone, leaves no last event)
            # its record ends as a process's does on SIGTERM, not at whatever it did last
            running.robot.log.record("stop", driving=dict(running.robot.driver.counters), interrupted=True)
        raise
    finally:
        running._end()  # as at the end of its process: whatever it left pending ends with it


def _start_user(
    opts: RunOptions, scenario: Scenario | None, world: str, record: RunRecord, air: MemoryAir
) -> asyncio.Task[int] | None:
    if scenario is None or scenario.user is None:
        return None
    config = UserConfig(
        scenario.user,
        ENDPOINT,
        world,
        scenario.duration_s,
        opts.seed,
        beacon=scenario.surround_enabled,
        profile=opts.profile,
    )
    sink = open(record.events_of(scenario.user.node_id), "a")  # noqa: SIM115 (closed when the user is done)
    task = start_user(config, air, EventLog(sink=sink))
    task.add_done_callback(lambda _task: sink.close())
    return task


async def orchestrate(
    opts: RunOptions,
    scenario: Scenario | None,
    ctl: RelayControl,
    world: str,
    dead: Callable[[], Collection[int]] = frozenset,
    act: Callable[[dict[str, Any]], Awaitable[None]] | None = None,
) -> dict[str, Any]:
    """What a model or lockstep run does, on model time, through the relay: wait for the robots, the
    traffic or scenario phase with its faults, the summary, then every robot told to stop. Robots in ``dead()``
    (a lockstep run's robot processes that died, as its supervision saw them; none in model time) are neither
    asked nor expected to do anything; any other robot that does not answer is a problem of the run. ``act``
    carries out the scenario's actions (``petswarm.scenario.ACTIONS``; model time only)."""
    await _wait_attached(ctl, opts.robots)
    faults = FaultTimeline(list(opts.faults) + (list(scenario.faults) if scenario is not None else []))
    faults.act = act
    if scenario is None:
        summary = await ping_and_organize(opts, ctl, faults, world, dead)
    else:
        summary = await _follow_scenario(opts, scenario, ctl, faults, world, dead)
    for rid in sorted(set(range(1, opts.robots + 1)) - set(dead())):
        try:
            await ctl.command(rid, "stop")
        except HubUnavailable as err:  # alive but out of the world (a lockstep node taken as gone): say so
            summary["problems"].append(f"robot {rid} could not be told to stop: {err}")
            summary["ok"] = False
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
        if request["op"] == "add" and is_action(request["fault"]):
            if faults.act is None:
                raise RunFailed(f"fault at {at:g} s: {request['fault']['kind']} runs in model time only")
            await faults.act(request["fault"])
            progress(f"fault at {at:g} s: {request['fault']['kind']} {request['fault'].get('robot', '')}".rstrip())
            faults.applied.append({"at": at, **request})
            continue
        answer = await ctl.hub("chaos", request=request)
        faults.applied_or_refused(at, request, answer)


async def ping_and_organize(
    opts: RunOptions, ctl: RelayControl, faults: FaultTimeline, world: str, dead: Callable[[], Collection[int]]
) -> dict[str, Any]:
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
    swarm = await organize_and_disperse(ctl, opts, dead) if opts.organize else {}
    summary = await _summary(opts, ctl, world, dead)
    summary["faults"] = faults.applied
    summary["notes"] = notes
    problems = summary["problems"] + swarm.pop("problems", [])
    summary.update(swarm, problems=problems, ok=not problems)
    return summary


async def _follow_scenario(
    opts: RunOptions,
    scenario: Scenario,
    ctl: RelayControl,
    faults: FaultTimeline,
    world: str,
    dead: Callable[[], Collection[int]],
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
    summary = await _summary(opts, ctl, world, dead)
    summary["problems"] = [p for p in summary["problems"] if p not in HEARING_PROBLEMS]  # no ping phase here
    summary.update(scenario=scenario.name, faults=faults.applied, duration_s=scenario.duration_s)
    summary["ok"] = not summary["problems"]
    return summary


async def _summary(
    opts: RunOptions, ctl: RelayControl, world: str, dead: Callable[[], Collection[int]]
) -> dict[str, Any]:
    stats = {"world": world, **await ctl.hub("stats")}
    return summarise(stats, await statuses(ctl, opts.robots, dead()), opts, world, ENDPOINT)


def _report(stats: dict[str, Any], what: str) -> None:
    totals = {"sent": 0, "delivered": 0, "collided": 0, "lost": 0}
    for node in stats["nodes"].values():
        for name in totals:
            totals[name] += node.get(name, 0)
    progress(
        f"{what}  sent {totals['sent']}  delivered {totals['delivered']}  "
        f"collided {totals['collided']}  lost {totals['lost']}"
    )
