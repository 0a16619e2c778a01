"""``petswarm chaos``: faults in a running hub's air, and robots killed, paused or resumed.

Faults act inside the emulated medium, where a real radio would suffer them (see radio_hub/air/chaos.py);
the hub logs every change with its model and wall time. Killing, pausing and resuming act on the robot
process itself (it must run on this host, as this user): SIGKILL, SIGSTOP and SIGCONT, sent only to a process
registered as that robot of that world in the private runtime directory and still running its command line
(petswarm/lab/runtime.py).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
from typing import Any

import msgpack

from petswarm.lab.arguments import int_auto
from petswarm.lab.hub_session import with_hub
from petswarm.lab.runtime import NotOurRobot, robot_pid
from radio_hub.air.chaos import BURST_DEFAULTS, JITTERS, MAX_DELAY_MS, describe_change, describe_fault, parse_fault
from radio_hub.interface import Keys, query_hub

SIGNALS = {"kill": signal.SIGKILL, "pause": signal.SIGSTOP, "resume": signal.SIGCONT}


EXAMPLES = """examples (every one also takes --hub ENDPOINT --world NAME):
  petswarm chaos loss --p 0.3 --node robot-2          a fade: 30 % of robot-2's frames, both ways, lost
  petswarm chaos corrupt --link robot-1,robot-2       every frame from 1 to 2 fails its FCS (no ACK)
  petswarm chaos duplicate --p 0.5 --pan 0x1000       half the deliveries on PAN 0x1000 handed up twice
  petswarm chaos delay --ms 20 --jitter-ms 5 --node robot-3
                                                      robot-3's stack hands frames up 15-25 ms late
  petswarm chaos burst --p-gb 0.05 --p-bg 0.25 --channel 11
                                                      lossy spells of ~4 frames on every link of channel 11
  petswarm chaos partition --group robot-3,robot-4    robots 3 and 4 hear nobody else, nobody hears them
  petswarm chaos ir-blind --node robot-2              robot-2's IR receivers saturate, as under a lamp
  petswarm chaos ir-noise --sigma 40                  extra noise on every IR receiver
  petswarm chaos list                                 the active faults (with their ids) and the log
  petswarm chaos clear --id 2                         end fault 2 (without --id: all, partitions heal)
  petswarm chaos pause --robot 2; petswarm chaos resume --robot 2; petswarm chaos kill --robot 2

Air faults act in the hub's emulated medium, seeded by the hub's --seed, and are logged there with
model and wall time; a selector (--node, --link, --pan or --channel) narrows them, none means every
reception. The same faults can be timed in an experiment file ([[faults]] with `at` and `kind`).
"""

DELAY_HELP = """Delay acts after the air: the frame's airtime, its outcome, the counters and the MAC's ACK stay
what the air made them (the sender sees no difference); the receiving robot gets the frame --ms later,
as from a slow radio stack. With jitter, frames to one receiver can arrive out of the order they were
sent. A draw below zero is taken as zero. Faults that select the same reception add up."""

BURST_HELP = """Gilbert-Elliott loss: each (sender, receiver) link has a chain that starts good and steps at every
reception: good -> bad with --p-gb, bad -> good with --p-bg; a frame is lost with --loss-good or
--loss-bad in that state. Bad spells last 1/p_bg receptions on average; the long-run loss is
p_gb/(p_gb+p_bg)*loss_bad + p_bg/(p_gb+p_bg)*loss_good. Counted as chaos_lost."""


def add_arguments(sub: argparse._SubParsersAction, add_hub: Any, robot_id: Any, bounded: Any) -> None:
    """The ``chaos`` subcommand and its actions."""
    chaos = sub.add_parser(
        "chaos",
        help="inject faults into a running hub's air; kill, pause or resume a robot",
        description="Faults in a running hub's emulated air, and robots killed, paused or resumed.",
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    actions = chaos.add_subparsers(dest="action", required=True, metavar="ACTION")

    def add_common(p: argparse.ArgumentParser) -> None:
        add_hub(p)
        p.add_argument("--json", action="store_true", help="print the hub's answer as JSON (default: in words)")

    for kind, what in (
        ("loss", "lose receptions"),
        ("corrupt", "spoil receptions' FCS (the MAC drops them)"),
        ("duplicate", "hand deliveries up twice"),
    ):
        p = actions.add_parser(kind, help=f"{what} with probability --p")
        p.add_argument("--p", type=bounded(float, 0, 1), default=1.0, help="probability (default 1)")
        _add_selectors(p, bounded)
        add_common(p)
    _add_delay(actions, add_common, bounded)
    _add_burst(actions, add_common, bounded)
    blind = actions.add_parser("ir-blind", help="an IR module reads full scale on every receiver (a lamp)")
    blind.add_argument("--node", help="the receiving robot (default: every one)")
    add_common(blind)
    noise = actions.add_parser("ir-noise", help="extra Gaussian noise on an IR module's readings")
    noise.add_argument("--node", help="the receiving robot (default: every one)")
    noise.add_argument("--sigma", type=bounded(float, 0, 1023), default=20.0, help="counts (default 20)")
    add_common(noise)
    part = actions.add_parser("partition", help="two sets of nodes that cannot hear each other")
    part.add_argument("--group", required=True, help="node ids on one side, comma-separated")
    part.add_argument("--others", help="node ids on the other side (default: everyone else)")
    add_common(part)
    clear = actions.add_parser("clear", help="end one fault (--id) or all of them (heals partitions)")
    clear.add_argument("--id", type=int, help="the fault to end (default: all)")
    add_common(clear)
    add_common(actions.add_parser("list", help="the active faults and the log of changes"))
    for action, sig in SIGNALS.items():
        p = actions.add_parser(
            action, help=f"send {sig.name} to a robot process of this world on this host (checked to be one)"
        )
        p.add_argument("--robot", type=robot_id, required=True, help="the robot's id")
        add_common(p)


def _add_selectors(p: argparse.ArgumentParser, bounded: Any) -> None:
    where = p.add_mutually_exclusive_group()
    where.add_argument("--node", help="frames sent or received by this node (e.g. robot-2)")
    where.add_argument("--link", type=_link, help="frames from one node to another: SENDER,RECEIVER")
    where.add_argument("--pan", type=bounded(int_auto, 0, 0xFFFF), help="receivers on this PAN ID (e.g. 0x1000)")
    where.add_argument("--channel", type=bounded(int, 11, 26), help="this channel")


def _link(text: str) -> list[str]:
    ends = text.split(",")
    if len(ends) != 2 or not all(ends):
        raise argparse.ArgumentTypeError(f"{text!r} is not SENDER,RECEIVER (two node ids, e.g. robot-1,robot-2)")
    return ends


def _add_delay(actions: argparse._SubParsersAction, add_hub: Any, bounded: Any) -> None:
    p = actions.add_parser(
        "delay",
        help="hand deliveries up --ms later (plus jitter): a slow receiver stack, after the air",
        description=DELAY_HELP,
        epilog="example:\n  petswarm chaos delay --ms 20 --jitter-ms 5 --jitter gaussian --link robot-1,robot-2",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    top = MAX_DELAY_MS
    p.add_argument("--ms", type=bounded(float, 0, top), required=True, help=f"extra delay in ms (0 to {top:g})")
    p.add_argument(
        "--jitter-ms",
        type=bounded(float, 0, top),
        default=0.0,
        help="uniform: the delay varies in [ms - jitter, ms + jitter]; gaussian: its standard deviation (default 0)",
    )
    p.add_argument("--jitter", choices=JITTERS, default="uniform", help="jitter distribution (default uniform)")
    _add_selectors(p, bounded)
    add_hub(p)


def _add_burst(actions: argparse._SubParsersAction, add_hub: Any, bounded: Any) -> None:
    p = actions.add_parser(
        "burst",
        help="Gilbert-Elliott burst loss per link: losses come in runs",
        description=BURST_HELP,
        epilog="example (bad spells of ~10 frames, ~17 % lost):\n"
        "  petswarm chaos burst --p-gb 0.02 --p-bg 0.1 --node robot-2",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    for name, what in (
        ("p_gb", "probability a good link turns bad at a reception"),
        ("p_bg", "probability a bad link turns good at a reception (> 0)"),
        ("loss_good", "loss probability in the good state"),
        ("loss_bad", "loss probability in the bad state"),
    ):
        flag = "--" + name.replace("_", "-")
        p.add_argument(
            flag, type=bounded(float, 0, 1), default=BURST_DEFAULTS[name], help=f"{what} (default %(default)s)"
        )
    _add_selectors(p, bounded)
    add_hub(p)


def chaos_command(args: argparse.Namespace) -> int:
    """Carry out one chaos action; 2 when the hub or robot cannot be reached, 1 when the fault is refused
    (malformed: refused here before the hub is asked; or by the hub)."""
    keys = Keys(args.world)
    if args.action in SIGNALS:
        return _signal_robot(keys, args)
    request = _request(args)
    if request["op"] == "add":
        try:  # the hub checks again; checking here tells a typo apart from an unreachable hub
            parse_fault(0, request["fault"])
        except ValueError as err:
            print(f"petswarm chaos {args.action}: refused: {err}", file=sys.stderr)
            return 1
    return with_hub("chaos", args.hub, lambda session: _act(session, keys, request, args.json))


def _act(session: Any, keys: Keys, request: dict[str, Any], as_json: bool) -> int:
    answer = _ask_hub(session, keys, request)
    if "error" in answer:
        print(f"petswarm chaos: the hub refused: {answer['error']}", file=sys.stderr)
        return 1
    print(json.dumps(answer, indent=2) if as_json else "\n".join(describe_answer(request, answer)))
    return 0


def describe_answer(request: dict[str, Any], answer: dict[str, Any]) -> list[str]:
    """The hub's answer to a chaos request in words: what changed, the active faults, and (list) the log."""
    faults = answer.get("faults", [])
    lines = []
    if request["op"] in ("add", "clear") and answer.get("log"):
        lines.append(describe_change(answer["log"][-1]).split(": ", 1)[1])  # what this request did
    lines.append("active faults:" if faults else "no fault active")
    lines += [f"  {describe_fault(f)}" for f in faults]
    if request["op"] == "list" and answer.get("log"):
        lines.append("log:")
        lines += [f"  {describe_change(entry)}" for entry in answer["log"]]
    return lines


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
    fault = {"kind": args.action, **_fault_parameters(args)}
    for name in ("node", "link", "pan", "channel"):
        if getattr(args, name) is not None:
            fault[name] = getattr(args, name)
    return {"op": "add", "fault": fault}


def _fault_parameters(args: argparse.Namespace) -> dict[str, Any]:
    if args.action == "delay":
        return {"ms": args.ms, "jitter_ms": args.jitter_ms, "jitter": args.jitter}
    if args.action == "burst":
        return {name: getattr(args, name) for name in BURST_DEFAULTS}
    return {"p": args.p}


def _ask_hub(session: Any, keys: Keys, request: dict[str, Any]) -> dict[str, Any]:
    return query_hub(session, keys.chaos, 5.0, msgpack.packb(request, use_bin_type=True))


def _signal_robot(keys: Keys, args: argparse.Namespace) -> int:
    """Signal a robot process of this host, only after checking it is ours (petswarm/lab/runtime.py); the pid never
    comes from the network. 2 with the reason when the target is refused or gone."""
    sig = SIGNALS[args.action]
    try:
        pid = robot_pid(keys.world, args.robot)
        os.kill(pid, sig)
    except NotOurRobot as err:
        print(f"petswarm chaos {args.action}: refused: {err}", file=sys.stderr)
        return 2
    except ProcessLookupError:
        print(f"petswarm chaos {args.action}: robot {args.robot} (pid {pid}) has just ended", file=sys.stderr)
        return 2
    print(
        json.dumps({"robot": args.robot, "pid": pid, "signal": sig.name})
        if args.json
        else f"robot {args.robot} (pid {pid}): {sig.name} sent"
    )
    return 0
