"""``petswarm run``: a hub and N robot processes, exercised, summarised and stopped cleanly."""

from __future__ import annotations

import asyncio
import json
import math
import os
import sys
import time
from collections.abc import Awaitable, Callable, Collection
from dataclasses import dataclass, replace
from typing import Any, Protocol

import msgpack
import zenoh

from petswarm import control
from petswarm.lab.checker import check_record
from petswarm.lab.foxglove_live import StreamUnavailable, start_stream
from petswarm.lab.metrics import describe_driving
from petswarm.lab.processes import Interrupts, Supervisor, free_tcp_port
from petswarm.lab.records import RunRecord
from petswarm.lab.robot_command import RobotOptions
from petswarm.lab.supervision import RunAborted, Supervision, verdict
from petswarm.lab.swarm import describe
from petswarm.managers.decisions import WAITING_PAN as DEFAULT_PAN
from radio_hub.interface import Keys, open_session, query_hub
from radio_hub.values import HubUnavailable, describe_fault


@dataclass(frozen=True)
class RunOptions:
    """What ``petswarm run`` was asked to do; the defaults are the command line's (but for ``seed``, which the
    command line draws when none is given: a run from here is a function of the seed it is given)."""

    robots: int = 5
    seed: int = 0
    duration: float = 5.0
    ping_interval: float = math.nan
    """Seconds between a robot's pings; left out (NaN), ``default_ping_interval(robots)``."""
    world: str | None = None
    config: str | None = None
    pcap: str | None = None
    """The hub writes every frame on the air to this pcap file."""
    as_json: bool = False
    startup_timeout: float = 30.0
    organize: int = 0
    """Robot 1 organizes a swarm of this many after the ping phase (0: no swarm)."""
    protocol: str = "paper"
    record_dir: str | None = None
    """Where the run record goes (default ``runs/<UTC time>-<seed>``)."""
    scenario: str | None = None
    """A scenario file: run its world, robots and user end to end instead of the ping phase."""
    faults: tuple[dict[str, Any], ...] = ()
    """Chaos requests with ``at`` (seconds into the traffic phase); those later than the phase act just
    before the swarm is organized. ``{"at": 1, "kind": "loss", "p": 0.3}``, ``{"at": 2, "clear": true}``."""
    clock: str = "wall"
    """``wall``: processes over zenoh in real time; ``model``: one process on model time (``petswarm.lab.model_run``);
    ``lockstep``: processes on model time the hub owns (``petswarm.lab.lockstep_run``)."""
    fail_fast: bool = False
    """End the run at a robot's unexpected death instead of recording it and going on without the robot."""
    profile: str = "ideal"
    """The testbed profile (``petswarm.profiles``, ``radio_hub.profiles``) of the hub, the robots and the user."""
    link_key: str | None = None
    """A file with the 802.15.4 network key: every robot secures its frames (docs/SECURITY.md); None: off."""
    link_mic: int = 4
    """Bytes of a secured frame's MIC (4 or 8)."""
    dead_after_s: float | None = None
    """``lockstep``: wall seconds the hub waits for a granted process's idle before it takes the process as gone
    (None: the hub's own default)."""
    foxglove: int | None = None
    """Port of a Foxglove WebSocket server that streams the run live (0: any free port; None: no server)."""

    def __post_init__(self) -> None:
        if math.isnan(self.ping_interval):  # frozen: set once, here, as the command line would have
            object.__setattr__(self, "ping_interval", default_ping_interval(self.robots))

    def for_scenario(self, scenario: Any) -> RunOptions:
        """These options with the scenario's robot count and duration (what its record's manifest shows)."""
        return replace(self, robots=scenario.robot_count, duration=scenario.duration_s)


def progress(text: str) -> None:
    """Progress goes to stderr so that ``--json`` output stays clean."""
    print(f"[run] {text}", file=sys.stderr, flush=True)


ALL_PAIRS_UP_TO = 10
"""Up to this many robots a run passes only if every robot heard every other one (a pong from each). Beyond it
the N(N-1) acked pongs a ping round asks for outgrow the 250 kbit/s channel: every robot answers a broadcast
ping at once, and at 100 robots most pongs collide (collisions and channel-access failures are the model
working, not a fault). So a larger run asks that every robot's radio received frames from other robots (a
pong, or any frame the hub delivered to it), and reports the fraction of pairs whose pongs got through
(``pairs_heard_fraction``)."""
HEARING_PROBLEMS = ("not every robot heard every other robot", "a robot received no frame from another robot")
"""What the ping phase can find wrong; a scenario run has no ping phase and leaves them out."""
STATS_TIMEOUT_S = 10.0
"""How long supervision waits for the hub's stats: a hub busy with 50 robots answers late, not never."""


def default_ping_interval(robots: int) -> float:
    """0.5 s, and 0.05 s more per robot beyond 10: the pong load of a ping round grows with the robots."""
    return 0.5 + 0.05 * max(0, robots - 10)


class RunFailed(RuntimeError):
    """A process of the run died or never came up."""


@dataclass
class RunContext:
    """What a run's phase works with: its options, world, hub endpoint, record and processes."""

    opts: RunOptions
    world: str
    endpoint: str
    keys: Keys
    record: RunRecord
    sup: Supervisor
    session: zenoh.Session
    watch: Supervision


def roster_argv(robots: int, *others: str) -> list[str]:
    """The hub's ``--roster`` for a run of ``robots`` robots and the other nodes it starts (a user, its orchestrator):
    the hub keeps room for these ids whatever other sessions attach (docs/SECURITY.md)."""
    return ["--roster", ",".join([*(f"robot-{rid}" for rid in range(1, robots + 1)), *others])]


def supervise(
    opts: RunOptions,
    prefix: str,
    hub_extra: Callable[[RunRecord], list[str]],
    phase: Callable[[RunContext], dict[str, Any]],
    after_stop: Callable[[dict[str, Any], RunRecord], None] | None = None,
) -> int:
    """The skeleton of every run: a record, a hub on a free port (``hub_extra``: more hub arguments),
    ``phase`` (which starts the other processes and returns the summary), a clean stop of every process
    on success, failure, Ctrl-C or SIGTERM, then ``after_stop``, the checker and the printed summary."""
    world = opts.world or f"{prefix}-{os.getpid()}-{opts.seed}"
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    keys = Keys(world)
    try:
        stream = start_stream(opts.foxglove, world, endpoint)
    except StreamUnavailable as err:
        print(f"petswarm run: --foxglove {opts.foxglove}: {err}", file=sys.stderr)
        return 2
    record = RunRecord.create(opts, world, endpoint)
    if stream is not None:
        stream.follow(record.path, progress)
    sup = Supervisor(record.path / "logs")
    watch = Supervision(sup, record, opts.fail_fast, progress)
    watch.write_progress(force=True)  # from the first moment a kill leaves a summary
    interrupts = Interrupts()  # SIGTERM stops the run as Ctrl-C does, and only the first signal acts
    watch.checkpoint = interrupts.check  # the run's loops raise again a first signal whose raise was lost
    session: zenoh.Session | None = None
    summary: dict[str, Any] = {"ok": False, "problems": ["the run did not finish"], "seed": opts.seed}
    try:
        progress(f"world {world}, seed {opts.seed}, hub on {endpoint}, record in {record.path}")
        hub_args = ["hub", "--listen", endpoint, "--world", world, "--seed", str(opts.seed)]
        # the air's frame log belongs to the record unless the user wants the capture elsewhere
        hub_args += ["--pcap", opts.pcap or str(record.path / "air.pcap"), *hub_extra(record)]
        hub_args += ["--profile", opts.profile] if opts.profile != "ideal" else []
        sup.spawn("hub", hub_args + (["--config", opts.config] if opts.config else []))
        session = _wait_for_hub(watch, endpoint, keys, opts.startup_timeout)
        summary = phase(RunContext(opts, world, endpoint, keys, record, sup, session, watch))
        watch.check()  # a death in the last moments counts too
    except (RunFailed, RunAborted, HubUnavailable) as err:
        progress(f"failed: {err}")
        summary["problems"] = [f"failed: {err}"]
        return 1
    except KeyboardInterrupt:
        progress("interrupted; stopping every process")
        # what the run had learnt by then (the phase, its traffic totals), as its running summary showed it
        summary = {**watch.progress, **summary, "ok": False, "problems": ["interrupted"], "interrupted": True}
        return 130
    finally:
        # a second Ctrl-C or SIGTERM waits until every process is stopped and the record says how (Interrupts)
        with interrupts.deferred():
            if session is not None:
                session.close()
            codes = sup.stop_all()
            if stream is not None:
                stream.close()  # after the processes: their last events and frames are streamed too
            summary["deaths"] = watch.deaths
            summary["elapsed_s"] = round(time.monotonic() - watch.started, 2)
            record.finish(summary, codes)
            progress(f"stopped {len(codes)} processes; record in {record.path}")
            if summary.get("interrupted") and opts.as_json:
                _print({**summary, "exit_codes": codes}, as_json=True)  # --json promises a summary
    if after_stop is not None:
        after_stop(summary, record)
    violations = check_record(record.path)
    summary["invariants"] = violations or "all hold"
    summary["problems"] += [f"invariant violated: {v}" for v in violations]
    summary["ok"] = not summary["problems"]
    record.finish(summary, codes)
    _print(summary, opts.as_json)
    return watch.exit_status(summary["ok"])


def ping_and_organize(ctx: RunContext) -> dict[str, Any]:
    """The default run: robots ping each other for ``duration``, then robot 1 may organize a swarm."""
    opts, session, keys = ctx.opts, ctx.session, ctx.keys
    notes = organize_shortfall(opts)
    for note in notes:
        progress(f"warning: {note}")
    for rid in range(1, opts.robots + 1):
        ctx.sup.spawn(f"robot-{rid}", ping_robot_options(opts, rid, ctx.endpoint, ctx.world, ctx.record).argv())
    _wait_for_robots(ctx.watch, session, keys, opts.robots, opts.startup_timeout)
    timeline = FaultTimeline(list(opts.faults))
    _exercise(ctx.watch, session, keys, opts.duration, timeline)
    timeline.apply_due(hub_chaos(session, keys), float("inf"))  # what is left acts on the swarm phase
    ctx.watch.check()
    dead = ctx.watch.dead_robots
    swarm = asyncio.run(organize_and_disperse(ZenohControl(session, keys), opts, dead)) if opts.organize else {}
    ctx.watch.check()
    summary = _summarise(session, keys, opts, ctx.world, ctx.endpoint, dead())
    summary["faults"] = timeline.applied
    summary["notes"] = notes
    problems = summary["problems"] + swarm.pop("problems", [])
    summary.update(swarm, problems=problems, ok=not problems)
    return summary


def ping_robot_options(opts: RunOptions, rid: int, endpoint: str, world: str, record: RunRecord) -> RobotOptions:
    """The options of robot ``rid`` in the default run (robot 1 serves user 1 when the run organizes a swarm)."""
    serves = rid == 1 and opts.organize
    return RobotOptions(
        id=rid,
        hub=endpoint,
        world=world,
        record=str(record.events_of(f"robot-{rid}")),
        user=1 if serves else 0,
        protocol=opts.protocol if serves else "paper",
        profile=opts.profile,
        link_key=opts.link_key,
        link_mic=opts.link_mic if opts.link_key else RobotOptions.link_mic,
        ping_interval=opts.ping_interval,
        seed=opts.seed,
    )


def organize_shortfall(opts: RunOptions) -> list[str]:
    """Why the swarm will have fewer members than ``--organize`` asks, when the run itself makes it so.

    Not a failure: the protocol takes every available robot when fewer are available than asked (Table 2),
    so the run checks that all of them joined; the note tells the user why the swarm is smaller."""
    others = opts.robots - 1
    if opts.organize <= others:
        return []
    return [
        f"--organize {opts.organize} asks for more robots than the {others} this run has besides the master "
        f"(--robots {opts.robots}): at most {others} can join"
    ]


def _wait_for_hub(watch: Supervision, endpoint: str, keys: Keys, timeout: float) -> zenoh.Session:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        watch.check()
        try:
            session = open_session("client", endpoint)
        except HubUnavailable:
            time.sleep(0.1)
            continue
        try:
            query_hub(session, keys.stats, timeout=1.0)
            progress("hub is up")
            return session
        except HubUnavailable:
            session.close()
    raise RunFailed(f"hub did not come up within {timeout} s:\n{watch.sup.log_tail('hub')}")


def _attached(session: zenoh.Session, keys: Keys) -> int:
    stats = query_hub(session, keys.stats, timeout=STATS_TIMEOUT_S)
    return sum(1 for n in stats["nodes"].values() if n["attached"])


def _wait_for_robots(watch: Supervision, session: zenoh.Session, keys: Keys, count: int, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    seen = -1
    while time.monotonic() < deadline:
        watch.check()
        attached = _attached(session, keys)
        if attached != seen:
            progress(f"{attached}/{count} robots attached")
            seen = attached
        if attached >= count - len(watch.dead_robots()):
            return
        time.sleep(0.2)
    raise RunFailed(f"only {seen}/{count} robots attached within {timeout} s")


def _exercise(watch: Supervision, session: zenoh.Session, keys: Keys, duration: float, timeline: FaultTimeline) -> None:
    start = time.monotonic()
    next_report = start
    while (elapsed := time.monotonic() - start) < duration:
        watch.check()
        timeline.apply_due(hub_chaos(session, keys), elapsed)
        if time.monotonic() >= next_report:
            try:
                totals = _totals(query_hub(session, keys.stats, timeout=STATS_TIMEOUT_S))
            except HubUnavailable:  # a busy hub: progress can wait, the run goes on
                totals = None
            if totals is not None:
                watch.progress = {"phase": "ping", "phase_elapsed_s": round(elapsed, 1), "totals": totals}
                progress(
                    f"t={elapsed:5.1f}/{duration:g}s  sent {totals['sent']}  delivered {totals['delivered']}  "
                    f"collided {totals['collided']}  lost {totals['lost']}"
                )
            next_report = time.monotonic() + 1.0
        time.sleep(min(0.1, max(duration - elapsed, 0)))


class FaultTimeline:
    """Faults of a run, applied through the hub's chaos queryable when their time comes."""

    def __init__(self, faults: list[dict[str, Any]]) -> None:
        self.pending = sorted(faults, key=lambda f: float(f.get("at", 0.0)))
        self.applied: list[dict[str, Any]] = []
        self.act: Callable[[dict[str, Any]], Awaitable[None]] | None = None
        """Carries out a scenario's actions (``petswarm.scenario.ACTIONS``) where the run can: model time."""

    def apply_due(self, chaos: Callable[[dict[str, Any]], dict[str, Any]], elapsed: float) -> None:
        """Send every fault whose time has come to ``chaos`` (the hub's chaos request); a refused one fails
        the run with the hub's reason."""
        for at, request in self.take_due(elapsed):
            self.applied_or_refused(at, request, chaos(request))

    def take_due(self, elapsed: float) -> list[tuple[float, dict[str, Any]]]:
        """The chaos requests whose time has come, with their times, in order."""
        due = []
        while self.pending and float(self.pending[0].get("at", 0.0)) <= elapsed:
            fault = dict(self.pending.pop(0))
            at = float(fault.pop("at", 0.0))
            clear = fault.pop("clear", False)
            due.append((at, {"op": "clear", "id": fault.get("id")} if clear else {"op": "add", "fault": fault}))
        return due

    def applied_or_refused(self, at: float, request: dict[str, Any], answer: dict[str, Any]) -> None:
        """Record a fault the hub took; RunFailed with the hub's reason when it refused it."""
        if "error" in answer:
            raise RunFailed(f"fault at {at:g} s refused by the hub: {answer['error']}")
        what = describe_fault(request["fault"]) if request["op"] == "add" else _cleared(request.get("id"))
        progress(f"fault at {at:g} s: {what}")
        self.applied.append({"at": at, **request})


def hub_chaos(session: zenoh.Session, keys: Keys) -> Callable[[dict[str, Any]], dict[str, Any]]:
    """The hub's chaos queryable as a call."""
    return lambda request: query_hub(session, keys.chaos, payload=msgpack.packb(request, use_bin_type=True))


def _cleared(fault_id: int | None) -> str:
    return "clear every fault" if fault_id is None else f"clear fault {fault_id}"


_NOT_COUNTERS = ("pan_id", "short_addr", "channel")
"""Integers of a node's stats that name its radio rather than count anything: no total."""


def _totals(stats: dict[str, Any]) -> dict[str, int]:
    """The hub's per-node counters summed over the nodes (the progress line's and running summary's)."""
    totals: dict[str, int] = {}
    for node in stats["nodes"].values():
        for name, value in node.items():
            if isinstance(value, int) and not isinstance(value, bool) and name not in _NOT_COUNTERS:
                totals[name] = totals.get(name, 0) + value
    return totals


class RunControl(Protocol):
    """How a run's orchestration reaches its robots: zenoh queries to processes, or calls in model time."""

    async def command(self, robot: int, cmd: str, timeout: float = 5.0, **args: Any) -> dict[str, Any]:
        """One control command (``status``, ``organize``...) to one robot; HubUnavailable if it cannot answer."""

    async def sleep(self, seconds: float) -> None:
        """Let the run go on for ``seconds`` (wall or model time)."""


class ZenohControl:
    """``RunControl`` over the robots' control queryables."""

    def __init__(self, session: zenoh.Session, keys: Keys) -> None:
        self.session, self.keys = session, keys

    async def command(self, robot: int, cmd: str, timeout: float = 5.0, **args: Any) -> dict[str, Any]:
        return await asyncio.to_thread(control.command, self.session, self.keys, robot, cmd, timeout, **args)

    async def sleep(self, seconds: float) -> None:
        await asyncio.sleep(seconds)


async def organize_and_disperse(
    ctl: RunControl, opts: RunOptions, dead: Callable[[], Collection[int]] = frozenset
) -> dict[str, Any]:
    """Robot 1 (connected to user 1) organizes, the swarm holds a second, then disperses; states are checked.
    Robots in ``dead()`` (died during the run) are neither asked nor expected to join."""
    progress(f"robot 1 organizes a swarm of {opts.organize} ({opts.protocol} protocol)")
    organized = await ctl.command(1, "organize", 60.0, count=opts.organize)
    if "error" in organized:
        return {"organization": organized, "problems": [f"organize failed: {organized['error']}"]}
    progress(
        f"members {organized['members']} on PAN {organized['pan_id']:#06x} in "
        f"{organized['organize_time_s'] * 1000:.1f} ms, {organized['retries']} retries"
    )
    await ctl.sleep(1.0)
    problems = swarm_problems(opts.robots, await statuses(ctl, opts.robots, dead()), organized)
    expected = min(opts.organize, opts.robots - 1 - len(set(dead()) - {1}))
    if len(organized["members"]) < expected:
        found = len(organized.get("available", []))  # the master's count: the robots that answered available
        problems.append(
            f"only {len(organized['members'])} of the {expected} robots it could take joined the swarm "
            f"(the master found {found} available)"
        )
    if not organized["members"]:
        return {"organization": organized, "problems": problems}
    dispersed = await ctl.command(1, "disperse", 60.0)

    progress(f"dispersed in {dispersed.get('disperse_time_s', 0) * 1000:.1f} ms")
    await ctl.sleep(0.3)
    problems += swarm_problems(opts.robots, await statuses(ctl, opts.robots, dead()), None)
    return {"organization": organized, "dispersal": dispersed, "problems": problems}


DIED = {"died": True}
"""The status of a robot that died during the run: it is not asked, and no check expects anything of it."""


async def statuses(ctl: RunControl, robots: int, dead: Collection[int] = ()) -> dict[int, dict[str, Any] | str]:
    """Every robot's status, or the reason it gave none; DIED for the robots in ``dead``."""
    answers: dict[int, dict[str, Any] | str] = {}
    for rid in range(1, robots + 1):
        if rid in dead:
            answers[rid] = DIED
            continue
        try:
            answers[rid] = await ctl.command(rid, "status")
        except HubUnavailable as err:
            answers[rid] = str(err)
    return answers


def swarm_problems(robots: int, status: dict[int, dict[str, Any] | str], organized: dict[str, Any] | None) -> list[str]:
    """Every robot's own belief against the master's: the master and its members on the swarm's PAN in
    their swarm states, everyone else waiting on the waiting PAN (and the master following, after)."""
    members = set(organized["members"]) if organized else set()
    pan = organized["pan_id"] if members else DEFAULT_PAN
    when = "after organizing" if organized else "after dispersing"
    problems = []
    for rid in range(1, robots + 1):
        if rid == 1:
            want = ("master-driving", pan) if members else ("following", DEFAULT_PAN)
        else:
            want = ("slave-driving", pan) if rid in members else ("waiting", DEFAULT_PAN)
        answer = status[rid]
        if isinstance(answer, str):
            problems.append(f"{answer} {when}")
            continue
        if answer is DIED:
            continue
        got = (answer["state"], answer["radio"]["pan_id"])
        if got != want:
            problems.append(
                f"robot {rid} is {got[0]} on PAN {got[1]:#06x} {when}; the master says {want[0]} on {want[1]:#06x}"
            )
    return problems


def _summarise(
    session: zenoh.Session, keys: Keys, opts: RunOptions, world: str, endpoint: str, dead: Collection[int] = ()
) -> dict[str, Any]:
    ctl = ZenohControl(session, keys)
    stats = query_hub(session, keys.stats, timeout=STATS_TIMEOUT_S)
    return summarise(stats, asyncio.run(statuses(ctl, opts.robots, dead)), opts, world, endpoint)


def summarise(
    stats: dict[str, Any], status: dict[int, dict[str, Any] | str], opts: RunOptions, world: str, endpoint: str
) -> dict[str, Any]:
    """The run's summary from the hub's stats and every robot's status; a robot that died during the run
    (DIED) keeps its hub counters and is left out of the hearing checks."""
    nodes: dict[str, Any] = {}
    problems: list[str] = [answer for answer in status.values() if isinstance(answer, str)]
    for rid in range(1, opts.robots + 1):
        name = f"robot-{rid}"
        answer = status[rid]
        robot = answer if isinstance(answer, dict) else {}
        counters = stats["nodes"].get(name, {})
        nodes[name] = {
            **{
                k: counters.get(k, 0)
                for k in (
                    "sent",
                    "heard",
                    "delivered",
                    "collided",
                    "lost",
                    "filtered",
                    "mac_retries",
                    "channel_access_failures",
                    "no_ack",
                    "acks_sent",
                    "chaos_lost",
                )
            },
            "heard_from": sorted(robot.get("heard_from", {})),
            "transport_gaps": robot.get("transport_gaps", 0),
            "pings_sent": robot.get("pings_sent", 0),
            "pings_answered": robot.get("pings_answered", 0),
            "peak_rss_mb": robot.get("peak_rss_mb"),
        }
        if answer is DIED:
            nodes[name]["died"] = True
    alive = {rid: n for rid, n in enumerate(nodes.values(), 1) if not n.get("died")}
    everyone = set(alive)
    all_pairs = all(set(n["heard_from"]) >= everyone - {rid} for rid, n in alive.items())
    pairs = sum(len(set(n["heard_from"]) - {rid}) for rid, n in alive.items())
    if len(alive) > 1 and not all_pairs and opts.robots <= ALL_PAIRS_UP_TO:
        problems.append(HEARING_PROBLEMS[0])
    elif opts.robots > ALL_PAIRS_UP_TO and any(not (n["heard_from"] or n["delivered"]) for n in alive.values()):
        problems.append(HEARING_PROBLEMS[1])
    gaps = stats["hub"]["transport_gaps"] + sum(n["transport_gaps"] for n in nodes.values())
    if gaps:
        problems.append(f"the transport lost {gaps} messages (robots to hub and hub to robots)")
    return {
        "ok": not problems,
        "problems": problems,
        "seed": opts.seed,
        "world": world,
        "endpoint": endpoint,
        "robots": opts.robots,
        "duration_s": opts.duration,
        "all_pairs_heard": all_pairs,
        "pairs_heard_fraction": round(pairs / max(len(alive) * (len(alive) - 1), 1), 3),
        "nodes": nodes,
        "channels": stats["channels"],
        "hub": stats["hub"],
        "hub_process": stats.get("process"),
        "ir": stats["ir"],
        "medium": stats["config"],
    }


def _print(summary: dict[str, Any], as_json: bool) -> None:
    if as_json:
        print(json.dumps(summary, indent=2))
        return
    print(f"seed {summary['seed']}  world {summary['world']}  {summary['robots']} robots  {summary['duration_s']:g} s")
    pinged = "scenario" not in summary  # a scenario run has no ping phase: nobody is 'heard from'
    nodes = summary["nodes"]
    if not pinged and not any(n["sent"] or n["delivered"] for n in nodes.values()):
        nodes = {}  # a surround swarm exchanges no messages: a table of zeros says nothing
        print(f"radio: silent (none of the {len(summary['nodes'])} nodes sent or received a frame)")
    else:
        header = f"{'node':<10}{'sent':>7}{'delivered':>11}{'collided':>10}{'lost':>7}{'retries':>9}{'cca fail':>10}"
        print(header + ("  heard from" if pinged else ""))
    for name, n in nodes.items():
        heard = "  " + (", ".join(map(str, n["heard_from"])) or "nobody") if pinged else ""
        print(
            f"{name:<10}{n['sent']:>7}{n['delivered']:>11}{n['collided']:>10}{n['lost']:>7}"
            f"{n['mac_retries']:>9}{n['channel_access_failures']:>10}{heard}"
        )
    hub = summary["hub"]
    print(
        f"hub: delivery lag p50 {hub['lag_p50_us']:.0f} us, p99 {hub['lag_p99_us']:.0f} us; "
        f"malformed {hub['malformed']}, transport gaps {hub['transport_gaps']}"
    )
    organized = summary.get("organization")
    if organized and "error" not in organized:
        print(describe("organize", organized))
        if "disperse_time_s" in summary.get("dispersal", {}):
            print(describe("disperse", summary["dispersal"]))
    if "driving" in summary:
        print(describe_driving(summary["driving"]))
    for note in summary.get("notes", []):
        print(f"note: {note}")
    for death in summary.get("deaths", []):
        when = f"{death['cause']}, {death['elapsed_s']:g} s in"
        print(f"died during the run: {death['process']} ({when}); the run went on without it")
    print(verdict(summary))
