"""``petswarm chaos``: faults in a running hub's air, and robots killed, paused or resumed.

Faults act inside the emulated medium, where a real radio would suffer them (see radio_hub/chaos.py);
the hub logs every change with its model and wall time. Killing, pausing and resuming act on the robot
process itself (it must run on this host): SIGKILL, SIGSTOP and SIGCONT.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
from typing import Any

import msgpack

from cli.hub_session import with_hub
from petswarm import control
from radio_hub.interface import HubUnavailable, Keys, query_hub

SIGNALS = {"kill": signal.SIGKILL, "pause": signal.SIGSTOP, "resume": signal.SIGCONT}


def add_arguments(sub: argparse._SubParsersAction, add_hub: Any, robot_id: Any, bounded: Any) -> None:
    """The ``chaos`` subcommand and its actions."""
    chaos = sub.add_parser("chaos", help="inject faults into a running hub's air; kill, pause or resume a robot")
    actions = chaos.add_subparsers(dest="action", required=True, metavar="ACTION")
    for kind, what in (
        ("loss", "lose receptions"),
        ("corrupt", "spoil receptions' FCS (the MAC drops them)"),
        ("duplicate", "hand deliveries up twice"),
    ):
        p = actions.add_parser(kind, help=f"{what} with probability --p")
        p.add_argument("--p", type=bounded(float, 0, 1), default=1.0, help="probability (default 1)")
        where = p.add_mutually_exclusive_group()
        where.add_argument("--node", help="frames sent or received by this node (e.g. robot-2)")
        where.add_argument("--link", help="frames from one node to another: SENDER,RECEIVER")
        where.add_argument("--pan", type=lambda t: int(t, 0), help="receivers on this PAN ID")
        where.add_argument("--channel", type=bounded(int, 11, 26), help="this channel")
        add_hub(p)
    blind = actions.add_parser("ir-blind", help="an IR module reads full scale on every receiver (a lamp)")
    blind.add_argument("--node", help="the receiving robot (default: every one)")
    add_hub(blind)
    noise = actions.add_parser("ir-noise", help="extra Gaussian noise on an IR module's readings")
    noise.add_argument("--node", help="the receiving robot (default: every one)")
    noise.add_argument("--sigma", type=bounded(float, 0, 1023), default=20.0, help="counts (default 20)")
    add_hub(noise)
    part = actions.add_parser("partition", help="two sets of nodes that cannot hear each other")
    part.add_argument("--group", required=True, help="node ids on one side, comma-separated")
    part.add_argument("--others", help="node ids on the other side (default: everyone else)")
    add_hub(part)
    clear = actions.add_parser("clear", help="end one fault (--id) or all of them (heals partitions)")
    clear.add_argument("--id", type=int, help="the fault to end (default: all)")
    add_hub(clear)
    add_hub(actions.add_parser("list", help="the active faults and the log of changes"))
    for action, sig in SIGNALS.items():
        p = actions.add_parser(action, help=f"send {sig.name} to a robot process on this host")
        p.add_argument("--robot", type=robot_id, required=True, help="the robot's id")
        add_hub(p)


def chaos_command(args: argparse.Namespace) -> int:
    """Carry out one chaos action; 2 when the hub or robot cannot be reached, 1 when refused."""
    return with_hub("chaos", args.hub, lambda session: _act(session, Keys(args.world), args))


def _act(session: Any, keys: Keys, args: argparse.Namespace) -> int:
    if args.action in SIGNALS:
        return _signal_robot(session, keys, args)
    answer = _ask_hub(session, keys, _request(args))
    if "error" in answer:
        print(f"petswarm chaos: the hub refused: {answer['error']}", file=sys.stderr)
        return 1
    print(json.dumps(answer["faults"], indent=2))
    return 0


def _request(args: argparse.Namespace) -> dict[str, Any]:
    if args.action == "list":
        return {"op": "list"}
    if args.action == "clear":
        return {"op": "clear", "id": args.id}
    if args.action == "partition":
        fault: dict[str, Any] = {"kind": "partition", "group": args.group.split(",")}
        if args.others:
            fault["others"] = args.others.split(",")
        return {"op": "add", "fault": fault}
    if args.action in ("ir-blind", "ir-noise"):
        fault = {"kind": args.action.replace("-", "_")}
        fault.update({k: getattr(args, k) for k in ("node", "sigma") if getattr(args, k, None) is not None})
        return {"op": "add", "fault": fault}
    fault = {"kind": args.action, "p": args.p}

    for name in ("node", "pan", "channel"):
        if getattr(args, name) is not None:
            fault[name] = getattr(args, name)
    if args.link:
        fault["link"] = args.link.split(",")
    return {"op": "add", "fault": fault}


def _ask_hub(session: Any, keys: Keys, request: dict[str, Any]) -> dict[str, Any]:
    return query_hub(session, keys.chaos, 5.0, msgpack.packb(request, use_bin_type=True))


def _signal_robot(session: Any, keys: Keys, args: argparse.Namespace) -> int:
    status = control.command(session, keys, args.robot, "status", 5.0) if args.action != "resume" else None
    pid = status["pid"] if status else _remembered_pid(keys, args.robot)
    try:
        os.kill(pid, SIGNALS[args.action])
    except ProcessLookupError:
        print(f"petswarm chaos: robot {args.robot} (pid {pid}) is not a process on this host", file=sys.stderr)
        return 2
    if args.action == "pause":
        _remember_pid(keys, args.robot, pid)
    print(f"robot {args.robot} (pid {pid}): {SIGNALS[args.action].name} sent")
    return 0


def _pid_file(keys: Keys, robot: int) -> str:
    # a paused robot cannot answer its control channel, so its pid is kept for the resume
    return os.path.join(os.environ.get("TMPDIR", "/tmp"), f"petswarm-{keys.world}-robot-{robot}.pid")


def _remember_pid(keys: Keys, robot: int, pid: int) -> None:
    with open(_pid_file(keys, robot), "w") as f:
        f.write(str(pid))


def _remembered_pid(keys: Keys, robot: int) -> int:
    try:
        with open(_pid_file(keys, robot)) as f:
            return int(f.read())
    except (OSError, ValueError):
        raise HubUnavailable(f"robot {robot} was not paused with petswarm chaos pause (no pid kept)") from None
