"""``petswarm``: emulate swarms of human-accompanying robots over an emulated IEEE 802.15.4 air."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import signal
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cli.bench import add_bench, bench
from cli.common import CommandParser, add_link_security, add_profile
from cli.common import add_hub as _add_hub
from cli.common import add_node_clock as _add_node_clock
from cli.common import add_tls as _add_tls
from cli.common import add_world as _add_world
from cli.explore import add_explore, explore
from cli.options import options_of
from cli.robot import add_robot_arguments, robot_options
from cli.text import plain
from petswarm.lab.arguments import CLOCKS, bounded, node_ids, robot_id, seed, world_name

if TYPE_CHECKING:
    from petswarm.robot import RobotConfig

MAX_PROCESS_ROBOTS = 200
"""Robot processes one ``petswarm run`` starts (wall or lockstep clock): each is some 60 MB and a zenoh session."""
MAX_MODEL_ROBOTS = 2000
"""Robots of one ``--clock model`` run, all in one process."""

EPILOG = """examples:
  petswarm run --robots 5 --duration 5          a hub and 5 robots pinging each other; prints a summary
  petswarm hub --listen tcp/127.0.0.1:7447      serve the emulated air (Ctrl-C stops it)
  petswarm robot --id 3 --pos 1.5,0             one robot attached to that hub
  petswarm swarm organize --master 1 --count 3 --user 1    the user asks robot 1 for a swarm of 3
  petswarm swarm status --robot 2               one robot's state, swarm and IR fixes of its neighbours
  petswarm stats                                the hub's counters per node and per channel
  petswarm report runs/<time>-<seed>            a recorded run's summary and plots
  petswarm export runs/<time>-<seed> --mcap run.mcap   the record as MCAP, for Foxglove
  petswarm watch --world lab                    a web page drawing the world live (--replay RUN: a record)
  petswarm bench hub|organize|ir|reaction|surround|scale|start   the benchmarks (figures, JSON, plots)

start the hub before its robots (they wait up to 15 s for it); every process of one swarm uses the
same --world and --hub endpoint.

  petswarm bench organize --slaves 1-5          swarm organizing time vs slaves, paper vs slotted protocol
  petswarm bench reaction --profile kim2017     the paper's testbed (docs/PROFILES.md): its figures beside ours

--profile ideal|kim2017 (hub, robot, user, run, bench organize|reaction|ir): the testbed's properties;
ideal (default) is the ideal air and instant processing, kim2017 the swarm paper's testbed.
"""


RUN_EXIT_STATUS = """exit status:
  0    the run finished and every check held (criteria and invariants)
  1    a check failed; or the hub (or a user) died; or a robot died under --fail-fast
  2    bad arguments or scenario file
  3    the run carried on past robots that died unexpectedly (killed, crashed), every other check held;
       each death is in the record (supervision.jsonl, summary.json "deaths")
  130  interrupted (Ctrl-C or SIGTERM): every process is stopped and the summary written

summary.json is rewritten every second while the run goes, so a run killed outright leaves one
("running": true); its children die with it, paused ones too."""


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("petswarm")
    except PackageNotFoundError:  # run from a checkout that was never installed
        return "(not installed)"


class _VersionAction(argparse.Action):
    """``--version``: the installed version, looked up only when asked. ``importlib.metadata`` costs a process
    about 25 ms of CPU to import, and every ``petswarm`` process (each hub, user and run, the tests' hundreds)
    builds this parser."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS, **kwargs: Any) -> None:
        super().__init__(option_strings, dest, default=argparse.SUPPRESS, nargs=0, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, *_: Any) -> None:
        print(f"petswarm {_version()}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    """The whole command line."""
    parser = CommandParser(
        prog="petswarm",
        description=plain(__doc__ or ""),
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action=_VersionAction, help="show the installed version and exit")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    _add_hub_command(sub)
    _add_user_command(sub)
    _add_robot_command(sub)
    _add_swarm_command(sub)
    _add_run_command(sub)
    from cli.chaos import add_arguments as add_chaos_arguments

    add_chaos_arguments(sub, _add_hub, robot_id, bounded)
    from cli.certs import add_certs

    add_certs(sub)
    _add_watch_command(sub)
    _add_experiment_command(sub)
    _add_export_command(sub)
    _add_report_command(sub)
    add_explore(sub)
    _add_stats_command(sub)
    add_bench(sub)
    return parser


def _add_hub_command(sub: Any) -> None:
    """``petswarm hub``."""
    hub = sub.add_parser("hub", help="run the radio hub (zenoh router + emulated air)")
    hub.add_argument("--listen", default="tcp/127.0.0.1:7447", help="zenoh endpoint to listen on (default %(default)s)")
    _add_world(hub)
    hub.add_argument("--seed", type=seed, default=0, help="seed of every random radio outcome (default %(default)s)")
    hub.add_argument(
        "--config", help="TOML or JSON file with [mac], [range], [loss], [path_loss], [capture] and [ir] tables"
    )
    add_profile(hub, "the radio's MAC settings, the wearables' BLE link, the IR module's noise")
    hub.add_argument(
        "--pcap",
        metavar="FILE",
        help="write every 802.15.4 frame on the air (data and ACK, with FCS) to this pcap file for Wireshark",
    )

    hub.add_argument(
        "--scenario",
        metavar="FILE",
        help="take the world from a scenario file: its obstacles and [hub] tables (see scenarios/)",
    )
    hub.add_argument(
        "--world-log",
        metavar="FILE",
        help="write the ground truth (every body's pose, every world tick) to this JSON-lines file",
    )
    hub.add_argument(
        "--clock",
        choices=("wall", "lockstep"),
        default="wall",
        help="wall (default): model time is the wall clock; lockstep: the hub owns model time and grants it to "
        "nodes started with --clock lockstep, so a run is exact and repeatable under any load",
    )
    hub.add_argument(
        "--expect",
        type=bounded(int, 1, 100000),
        default=1,
        help="lockstep: model time starts once this many nodes are there (default %(default)s)",
    )
    _add_dead_after(hub, 10.0, "lockstep: wall seconds a granted node may stay silent before it is taken as gone")
    hub.add_argument(
        "--floor",
        action="store_true",
        help="wall clock: answer every frame the moment it arrives, without modelling the air (no backoff, "
        "airtime, range, loss or collision): the floor under a hub's cost, for 'petswarm bench hub --floor'; "
        "not an emulation",
    )
    hub.add_argument(
        "--start-within",
        type=bounded(float, 1, 86400),
        default=None,
        help="lockstep: wall seconds to wait for the --expect nodes; then model time starts without the missing "
        "ones, recorded as gone (default 60 + 1 per expected node)",
    )
    hub.add_argument(
        "--roster",
        type=node_ids,
        default=(),
        metavar="IDS",
        help="comma-separated node ids the run starts (robot-1,robot-2,user-1): their up keys open outside the cap of "
        "1,024 node ids and room is kept for their first messages and tokens, so no other session's nodes can keep "
        "them from attaching (petswarm run gives its own; docs/SECURITY.md)",
    )
    _add_tls(hub, "hub")


def _add_user_command(sub: Any) -> None:
    """``petswarm user``."""
    user = sub.add_parser(
        "user",
        help="run the user process: a person walking a scenario's path with belt and watch",
        description="The person walks the scenario's path; the belt answers its robot's LF bursts and reports "
        "distances and activity over BLE; the watch sends the scenario's requests at their times.",
    )
    user.add_argument("--scenario", metavar="FILE", required=True, help="scenario file with a [user] table")
    _add_hub(user)
    user.add_argument("--seed", type=seed, default=0, help="seed of the belt's IMU noise (default 0)")
    user.add_argument(
        "--duration", type=bounded(float, 0.1, 86400), default=None, help="seconds (default: the scenario's)"
    )
    user.add_argument("--record", metavar="FILE", help="append every event to this JSON-lines file as it happens")
    _add_node_clock(user)
    add_profile(user, "the belt's recognition delay")


def _add_robot_command(sub: Any) -> None:
    """``petswarm robot``."""
    robot = sub.add_parser("robot", help="run one robot process attached to a hub")
    add_robot_arguments(robot)


def _add_swarm_command(sub: Any) -> None:
    """``petswarm swarm organize|disperse|status``."""
    swarm = sub.add_parser("swarm", help="ask a running robot to organize or disperse a swarm (the watch's requests)")
    swarm_sub = swarm.add_subparsers(dest="action", required=True, metavar="ACTION")
    org = swarm_sub.add_parser("organize", help="the user asks the robot connected to them for a swarm of N")
    org.add_argument("--master", type=robot_id, required=True, help="id of the user-connected robot")
    org.add_argument(
        "--count",
        type=bounded(int, 1, 32),
        required=True,
        help="robots wanted besides the master, 1-32 (a roster lists them in one frame)",
    )

    org.add_argument("--protocol", choices=("paper", "slotted"), help="override the robot's organizing protocol")
    org.add_argument(
        "--user", type=bounded(int, 1, 65535), help="connect the robot to this user first (until the wearables exist)"
    )
    _add_hub(org)
    dis = swarm_sub.add_parser("disperse", help="the user ends the swarm")
    dis.add_argument("--master", type=robot_id, required=True, help="id of the master robot")
    _add_hub(dis)
    sts = swarm_sub.add_parser("status", help="one robot's state, radio, swarm, token schedule and IR fixes")
    sts.add_argument("--robot", type=robot_id, required=True, help="id of the robot")
    _add_hub(sts)
    for p in (org, dis, sts):
        p.add_argument("--json", action="store_true", help="print the robot's answer as JSON (default: in words)")


def _add_run_command(sub: Any) -> None:
    """``petswarm run``."""
    run = sub.add_parser(
        "run",
        help="run a hub and N robots on this machine and summarise the radio traffic",
        epilog=RUN_EXIT_STATUS,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    run.add_argument(
        "scenario",
        nargs="?",
        help="a scenario file (scenarios/*.toml): hub, robots and user end to end, with driving metrics",
    )
    run.add_argument(
        "--robots",
        type=bounded(int, 1, MAX_MODEL_ROBOTS),
        default=None,
        help=f"number of robots (default 5; up to {MAX_PROCESS_ROBOTS} as processes, {MAX_MODEL_ROBOTS} in model time)",
    )
    run.add_argument("--seed", type=seed, default=None, help="seed (default: random, and reported)")
    run.add_argument("--duration", type=bounded(float, 0.1, 86400), default=None, help="seconds of traffic (default 5)")
    run.add_argument(
        "--ping-interval",
        type=bounded(float, 0.01, 60),
        default=None,
        help="seconds between each robot's broadcast pings (default 0.5, and 0.05 s per robot beyond 10, so the "
        "pongs of a large run stay within what the 250 kbit/s channel carries)",
    )
    run.add_argument("--world", type=world_name, help="key prefix of the run (default: derived from pid and seed)")
    run.add_argument("--config", help="hub medium config file (see petswarm hub --help)")
    run.add_argument("--pcap", metavar="FILE", help="the hub writes the run's 802.15.4 frames to this pcap file")
    run.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    run.add_argument(
        "--record",
        metavar="DIR",
        help="directory of the run record (default runs/<UTC time>-<seed>, or under $PETSWARM_RUNS): manifest, "
        "events, logs, summary",
    )
    run.add_argument(
        "--organize",
        type=bounded(int, 0, 199),
        default=None,
        help="robot 1 is connected to user 1 and organizes a swarm of this many (default 0: none)",
    )
    run.add_argument(
        "--protocol", choices=("paper", "slotted"), default="paper", help="organizing protocol (default paper)"
    )
    run.add_argument(
        "--clock",
        choices=CLOCKS,
        default="wall",
        help="wall (default): a hub process and robot processes over zenoh, in real time; model: the hub's "
        "environment and every robot in this one process on a virtual clock, as fast as the CPU allows, "
        "the same run (digest) for the same seed on any machine; lockstep: hub and robot processes over zenoh "
        "on model time the hub owns, exact under any load, the same digest as model",
    )

    _add_dead_after(
        run,
        None,
        "--clock lockstep: wall seconds the hub waits for a granted process before it takes it as gone and "
        "model time goes on without it (longer to hold a robot in a debugger)",
    )
    add_profile(run, "hub, robots and user alike (MAC, BLE, IR noise; MCU and UART per frame; recognition)")
    add_link_security(run)
    _add_foxglove(run, "stream the run live to Foxglove while it goes, in any clock")
    run.add_argument(
        "--fail-fast",
        action="store_true",
        help="end the run when a robot dies unexpectedly (default: record the death and go on without it)",
    )


def _add_watch_command(sub: Any) -> None:
    """``petswarm watch``."""
    watch = sub.add_parser("watch", help="a local web page drawing the world live from a hub, or replaying a run")
    _add_hub(watch)
    watch.add_argument("--replay", metavar="RUN", help="replay a run record (its directory, or its world.jsonl)")
    watch.add_argument(
        "--port", type=bounded(int, 0, 65535), default=8047, help="port of the page (default %(default)s; 0: any)"
    )
    watch.add_argument("--bind", default="127.0.0.1", help="address to serve on (default %(default)s; 0.0.0.0: all)")
    _add_foxglove(watch, "also serve the hub's world live to Foxglove")
    watch.add_argument(
        "--record",
        metavar="RUN",
        help="with --foxglove: also stream this run record's events and radio frames as its processes write them",
    )


def _add_experiment_command(sub: Any) -> None:
    """``petswarm experiment``."""
    exp = sub.add_parser("experiment", help="run an experiment file: a run, a fault timeline, repetitions, seeds")
    exp.add_argument("file", help="a TOML experiment file (see examples/experiment-loss.toml)")
    exp.add_argument(
        "--out", help="directory for the records and results (default runs/experiment-<time>, or under $PETSWARM_RUNS)"
    )
    exp.add_argument("--json", action="store_true", help="print the results as JSON on stdout (the table on stderr)")
    exp.add_argument(
        "--clock",
        choices=CLOCKS,
        default=None,
        help="every run's clock, over the file's [run] clock (default: the file's, else wall): model repeats a run "
        "exactly from its seed (each run's digest is in the results), wall runs real processes over zenoh",
    )


def _add_export_command(sub: Any) -> None:
    """``petswarm export``."""
    export = sub.add_parser(
        "export",
        help="write a run record as an MCAP file for Foxglove (docs/FOXGLOVE.md)",
        description="A run record (any clock) as one MCAP file: the world as Foxglove scenes and transforms, IR "
        "modes and fixes, every radio frame on a channel per node, each node's events as logs, counters; the "
        "manifest and summary as metadata; every message at the run's model time. Needs the foxglove extra.",
    )
    export.add_argument("run", help="a run record directory (runs/<time>-<seed>)")
    export.add_argument("--mcap", metavar="FILE", required=True, help="the MCAP file to write")
    export.add_argument("--force", action="store_true", help="replace FILE when it exists")
    export.add_argument("--json", action="store_true", help="print the messages per topic, size and time as JSON")


def _add_report_command(sub: Any) -> None:
    """``petswarm report``."""
    rep = sub.add_parser("report", help="print a run record's summary and render its plots to PNG")
    rep.add_argument("run", help="a run record directory (runs/<time>-<seed>)")
    rep.add_argument("--out", help="directory for report.png (default: the run directory)")
    rep.add_argument("--json", action="store_true", help="print the record's figures and the plots' paths as JSON")


def _add_stats_command(sub: Any) -> None:
    """``petswarm stats``."""
    stats = sub.add_parser("stats", help="print a running hub's counters")
    _add_hub(stats)
    stats.add_argument("--json", action="store_true", help="print the raw counters as JSON")


def _use_security(args: argparse.Namespace) -> str | None:
    """Make the command line's TLS options the process's transport security; the reason when they do not fit."""
    files = {name: getattr(args, name, None) for name in ("tls_ca", "tls_cert", "tls_key", "zenoh_config")}
    if not any(files.values()):
        return None
    if bool(files["tls_cert"]) != bool(files["tls_key"]):
        return "--tls-cert and --tls-key go together"
    if args.command == "hub" and files["tls_ca"] and not files["tls_cert"]:
        return "--tls-ca asks clients for certificates: the hub needs its own (--tls-cert and --tls-key)"
    if args.command == "hub" and files["tls_cert"] and not args.listen.startswith("tls/"):
        return f"--tls-cert needs a tls/ endpoint to listen on, not {args.listen!r} (e.g. tls/0.0.0.0:7447)"
    from radio_hub.link.trust import TransportSecurity
    from radio_hub.link.zenoh_link import use_security

    use_security(
        TransportSecurity(
            ca=files["tls_ca"],
            cert=files["tls_cert"],
            key=files["tls_key"],
            zenoh_config=files["zenoh_config"],
            acl_ids=getattr(args, "acl_ids", 64),
        )
    )
    return None


def main(argv: list[str] | None = None, parser: argparse.ArgumentParser | None = None) -> int:
    """Entry point of the ``petswarm`` console script; ``parser``: ``build_parser()``'s, made already (the fork
    server makes it once for all its robots)."""
    args = (parser or build_parser()).parse_args(argv)
    commands = {"hub": _hub, "user": _user, "robot": _robot, "run": _run, "stats": _stats, "bench": bench}
    commands.update(swarm=_swarm, watch=_watch)
    commands.update(report=_report, chaos=_chaos, experiment=_experiment, certs=_certs, explore=explore)
    commands.update(export=_export)
    handler = commands[args.command]
    unfit = _use_security(args)
    if unfit:
        print(f"petswarm {args.command}: {unfit}", file=sys.stderr)
        return 2
    try:
        code = handler(args)
    except KeyboardInterrupt:
        code = 130
    except BrokenPipeError:  # `petswarm stats | head`: the reader left; not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    if code == 130:
        # interrupted, and all written: a second Ctrl-C during the interpreter's exit (which puts Python's own
        # handlers back to the default action, 50 ms and more) killed it as -2 instead of this 130; ignored
        # signals stay ignored through that exit
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, signal.SIG_IGN)
    return code


def _wall_hub_class(floor: bool) -> type[Any]:
    """The wall-clock hub, or with ``floor`` the one that answers frames without modelling them."""
    if floor:
        from radio_hub.shell.floor import FloorHub

        return FloorHub
    from radio_hub.shell.hub import RadioHub

    return RadioHub


FOXGLOVE_PORT = 8765
"""Foxglove's default port for a WebSocket connection (``--foxglove`` without a port)."""


def _add_foxglove(parser: argparse.ArgumentParser, what: str) -> None:
    """``--foxglove [PORT]``: a Foxglove WebSocket server with the run's channels (docs/FOXGLOVE.md)."""
    parser.add_argument(
        "--foxglove",
        nargs="?",
        const=FOXGLOVE_PORT,
        type=bounded(int, 0, 65535),
        metavar="PORT",
        help=f"{what}: a Foxglove WebSocket server on PORT (default {FOXGLOVE_PORT}; 0: any free port); needs the "
        "foxglove extra",
    )


def _foxglove_missing(command: str, args: argparse.Namespace) -> bool:
    """With --foxglove and no Foxglove SDK: say which extra to install (True)."""
    if getattr(args, "foxglove", None) is None:
        return False
    from petswarm.lab.foxglove_channels import MissingExtra, require_sdk

    try:
        require_sdk()
    except MissingExtra as err:
        print(f"petswarm {command}: --foxglove: {err}", file=sys.stderr)
        return True
    return False


def _add_dead_after(parser: argparse.ArgumentParser, default: float | None, what: str) -> None:
    """The lockstep hub's patience for a silent node (``LockstepHub.dead_after_s``), on the hub or a run."""
    parser.add_argument("--dead-after", type=bounded(float, 0.5, 3600), default=default, help=f"{what} (default 10)")


def _hub(args: argparse.Namespace) -> int:
    from petswarm.lab.hub_tables import hub_environment
    from petswarm.scenario import ScenarioError, load
    from radio_hub.shell.hub import ready_line
    from radio_hub.shell.stopping import end_closed, stop_on_signals

    if args.floor and args.clock != "wall":
        print("petswarm hub: --floor models nothing and keeps no lockstep time: use --clock wall", file=sys.stderr)
        return 2
    try:
        scenario = load(args.scenario) if args.scenario else None
    except (ScenarioError, ValueError) as err:
        print(f"petswarm hub: bad --scenario: {err}", file=sys.stderr)
        return 2
    try:
        environment = hub_environment(args.config, scenario, args.profile)
    except ValueError as err:
        print(f"petswarm hub: {err}", file=sys.stderr)
        return 2
    try:
        hub: Any
        if args.clock == "lockstep":
            from radio_hub.shell.lockstep import LockstepHub

            hub = LockstepHub(
                args.listen,
                args.world,
                environment,
                args.seed,
                expect=args.expect,
                dead_after_s=args.dead_after,
                start_within_s=args.start_within,
                roster=args.roster,
                pcap_path=args.pcap,
                world_log=args.world_log,
            )
        else:
            hub = _wall_hub_class(args.floor)(
                args.listen,
                args.world,
                seed=args.seed,
                pcap_path=args.pcap,
                environment=environment,
                world_log=args.world_log,
                roster=args.roster,
            )
    except OSError as err:
        print(f"petswarm hub: cannot open --pcap file or --world-log file: {err}", file=sys.stderr)
        return 2
    try:
        hub.open()
    except Exception as err:  # zenoh reports a busy port or bad endpoint as a generic error
        hub.close()
        print(f"petswarm hub: cannot listen on {args.listen}: {err}", file=sys.stderr)
        return 2
    stop_on_signals(hub)
    print(ready_line(hub), flush=True)
    print(
        f"hub: serving world {args.world!r} on {args.listen}, seed {args.seed}, {args.clock} clock",
        file=sys.stderr,
        flush=True,
    )
    if args.pcap:
        print(f"hub: writing the air's frames to {args.pcap}", file=sys.stderr, flush=True)
    try:
        hub.serve()
    finally:
        hub.close()
    print("hub: closed", file=sys.stderr)
    end_closed(0)
    return 0  # not reached


def _user(args: argparse.Namespace) -> int:
    from petswarm.managers.event_log import EventLog
    from petswarm.scenario import ScenarioError, load
    from petswarm.wearables.user import UserConfig, run_user

    try:
        scenario = load(args.scenario)
    except ScenarioError as err:
        print(f"petswarm user: {err}", file=sys.stderr)
        return 2
    if scenario.user is None:
        print(f"petswarm user: {args.scenario} has no [user] table", file=sys.stderr)
        return 2
    duration = args.duration or scenario.duration_s
    config = UserConfig(
        scenario.user, args.hub, args.world, duration, args.seed, beacon=scenario.surround_enabled, profile=args.profile
    )
    sink = open(args.record, "a") if args.record else None  # noqa: SIM115 (closed below)
    try:
        if args.clock == "lockstep":
            from petswarm.lab.lockstep_node import run_node

            return run_node("user", args.hub, args.world, lambda link: run_user(config, EventLog(sink=sink), link=link))
        return asyncio.run(run_user(config, EventLog(sink=sink)))
    finally:
        if sink is not None:
            sink.close()


def _robot(args: argparse.Namespace) -> int:
    from petswarm.lab.robot_command import robot_config
    from petswarm.lab.runtime import NotOurRobot, register, unregister

    config = robot_config(robot_options(args))
    try:  # so that petswarm chaos kill|pause|resume can tell this process is ours (petswarm/lab/runtime.py)
        entry = register(config.world, config.robot_id) if config.robot_id else None
    except (OSError, NotOurRobot) as err:
        print(f"petswarm robot: not registered for petswarm chaos: {err}", file=sys.stderr)
        entry = None
    try:
        return _run_robot(args, config)
    finally:
        unregister(entry)


def _run_robot(args: argparse.Namespace, config: RobotConfig) -> int:
    from petswarm.robot import run_robot

    if args.clock == "lockstep":
        from petswarm.lab.lockstep_node import run_node

        if config.robot_id == 0:
            print(
                "petswarm robot: --clock lockstep needs an explicit --id (ids are claimed in wall time)",
                file=sys.stderr,
            )
            return 2
        return run_node(f"robot {config.robot_id}", config.endpoint, config.world, lambda link: run_robot(config, link))
    return asyncio.run(run_robot(config))


SCENARIO_SETS = {
    "robots": "[robots] count",
    "duration": "duration_s",
    "organize": "its robots' roles",
    "ping_interval": "no ping phase",
}
"""Options of ``petswarm run`` that a scenario decides for itself, with where (given with one, they were ignored)."""


def _unwritable_record(record: str | None) -> str | None:
    """Why the run's record cannot be written where it goes (``--record``, else the runs directory), or None."""
    from petswarm.lab.records import runs_dir

    where = Path(record) if record else runs_dir()
    missing = [d for d in (where, *where.parents) if not d.exists()]  # deepest first; made for the probe only
    try:
        where.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=where):
            pass
    except OSError as err:
        return f"cannot write the run record in {where}: {err.strerror or err}"
    finally:
        for made in missing:  # nothing is left behind by a run refused later, before it starts
            with contextlib.suppress(OSError):
                made.rmdir()
    return None


def _run(args: argparse.Namespace) -> int:
    from petswarm.lab.launch import run
    from petswarm.lab.run import RunOptions, default_ping_interval

    given = [name for name in SCENARIO_SETS if getattr(args, name) is not None]
    if args.scenario and given:
        why = "; ".join(f"--{n.replace('_', '-')}: {SCENARIO_SETS[n]}" for n in given)
        print(f"petswarm run: the scenario sets these itself ({why}); leave them out or edit the file", file=sys.stderr)
        return 2
    args.robots = 5 if args.robots is None else args.robots
    args.duration = 5.0 if args.duration is None else args.duration
    args.organize = 0 if args.organize is None else args.organize
    if args.clock != "model" and args.robots > MAX_PROCESS_ROBOTS:
        print(
            f"petswarm run: --robots {args.robots} is more robot processes than one run starts "
            f"({MAX_PROCESS_ROBOTS}); use --clock model for up to {MAX_MODEL_ROBOTS} robots in one process",
            file=sys.stderr,
        )
        return 2

    if _foxglove_missing("run", args):
        return 2
    if args.dead_after is not None and args.clock != "lockstep":
        print("petswarm run: --dead-after is the lockstep hub's patience; it needs --clock lockstep", file=sys.stderr)
        return 2
    unwritable = _unwritable_record(args.record)
    if unwritable:
        print(f"petswarm run: {unwritable}", file=sys.stderr)
        return 2
    chosen_seed = args.seed if args.seed is not None else int.from_bytes(os.urandom(4), "big")
    opts = RunOptions(
        robots=args.robots,
        seed=chosen_seed,
        duration=args.duration,
        ping_interval=args.ping_interval or default_ping_interval(args.robots),
        world=args.world,
        config=args.config,
        pcap=args.pcap,
        as_json=args.json,
        organize=args.organize,
        protocol=args.protocol,
        record_dir=args.record,
        scenario=args.scenario,
        clock=args.clock,
        fail_fast=args.fail_fast,
        profile=args.profile,
        dead_after_s=args.dead_after,
        link_key=args.link_key,
        link_mic=args.link_mic,
        foxglove=args.foxglove,
    )
    return run(opts)


def _experiment(args: argparse.Namespace) -> int:
    from petswarm.lab.experiment import ExperimentOptions, experiment_command

    return experiment_command(options_of(ExperimentOptions, args))


def _watch(args: argparse.Namespace) -> int:
    from petswarm.lab.watch import WatchOptions

    options = options_of(WatchOptions, args)
    if options.foxglove is not None:
        from petswarm.lab.foxglove_live import watch_command as watch_with_foxglove

        return watch_with_foxglove(options)
    from petswarm.lab.watch import watch_command

    return watch_command(options)


def _certs(args: argparse.Namespace) -> int:
    from petswarm.lab.certs import CertsOptions, certs_command

    return certs_command(options_of(CertsOptions, args))


def _chaos(args: argparse.Namespace) -> int:

    from cli.chaos import chaos_command

    return chaos_command(args)


def _export(args: argparse.Namespace) -> int:
    from petswarm.lab.mcap_export import ExportOptions, export_command

    return export_command(options_of(ExportOptions, args))


def _report(args: argparse.Namespace) -> int:
    from petswarm.lab.report import ReportOptions, report_command

    return report_command(options_of(ReportOptions, args))


def _swarm(args: argparse.Namespace) -> int:
    from petswarm.lab.swarm import SwarmOptions, swarm_command

    return swarm_command(options_of(SwarmOptions, args))


def _stats(args: argparse.Namespace) -> int:
    from petswarm.lab.hub_session import with_hub
    from radio_hub.interface import Keys, query_hub

    def show(session: Any) -> int:
        stats = query_hub(session, Keys(args.world).stats)
        if args.json:
            print(json.dumps(stats, indent=2))
        else:
            _print_stats(stats)
        return 0

    return with_hub("stats", args.hub, show)


def _print_stats(stats: dict[str, Any]) -> None:
    cols = ("sent", "delivered", "collided", "lost", "filtered", "mac_retries", "channel_access_failures", "no_ack")
    labels = ("sent", "delivered", "collided", "lost", "filtered", "retries", "cca fail", "no ack")
    print(f"world {stats['world']}  seed {stats['seed']}  model time {stats['now_us'] / 1e6:.3f} s")
    print(f"{'node':<14}{'PAN':>7}{'ch':>4}" + "".join(f"{c:>10}" for c in labels))
    for name, n in sorted(stats["nodes"].items()):
        pan = f"{n['pan_id']:#06x}" if n["attached"] else "gone"
        print(f"{name:<14}{pan:>7}{n.get('channel', ''):>4}" + "".join(f"{n[c]:>10}" for c in cols))
    for ch, c in sorted(stats["channels"].items()):
        print(f"{'channel ' + ch:<25}" + "".join(f"{c[k]:>10}" for k in cols))
    print(hub_line(stats["hub"]))


def hub_line(hub: dict[str, Any]) -> str:
    """The hub's own counters in one line: whole numbers, lags in microseconds rounded to 1 us."""
    parts = []
    for key, value in hub.items():
        name = key.removesuffix("_us").replace("_", " ")
        number = f"{value:.0f}" if isinstance(value, float) else str(value)
        parts.append(f"{name} {number}" + (" us" if key.endswith("_us") else ""))
    return "hub: " + ", ".join(parts)


if __name__ == "__main__":
    raise SystemExit(main())
