"""``petswarm swarm organize|disperse``: the user's watch requests, sent to a running robot."""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

from cli.hub_session import with_hub
from petswarm import control
from radio_hub.interface import HubUnavailable, Keys

_ORGANIZE_TIMEOUT_S = 60.0
_ROBOT_WAIT_S = 5.0


def swarm_command(args: argparse.Namespace) -> int:
    """Send the request, print the robot's answer; exit 1 when the robot refused, 2 when unreachable."""
    return with_hub("swarm", args.hub, lambda session: _ask(session, Keys(args.world), args))


def _ask(session: Any, keys: Keys, args: argparse.Namespace) -> int:
    _wait_for_robot(session, keys, getattr(args, "master", None) or args.robot)
    answer = _request(session, keys, args)
    if "error" in answer:
        reason = answer["error"].split(": ", 1)[-1]  # the robot's exception class means nothing to a user
        print(
            f"petswarm swarm {args.action}: robot {getattr(args, 'master', None) or args.robot} refused: {reason}",
            file=sys.stderr,
        )
        return 1
    as_json = args.action == "status" or args.json
    print(json.dumps(answer, indent=2) if as_json else describe(args.action, answer))

    return 0


def _wait_for_robot(session: Any, keys: Keys, robot: int) -> None:
    """A robot started a moment ago is still attaching: give it a few seconds before giving up."""
    deadline = time.monotonic() + _ROBOT_WAIT_S
    while True:
        try:
            control.command(session, keys, robot, "status", 1.0)
            return
        except HubUnavailable:
            if time.monotonic() >= deadline:
                raise
            time.sleep(0.2)


def _request(session: Any, keys: Keys, args: argparse.Namespace) -> dict[str, Any]:
    if args.action == "status":
        return control.command(session, keys, args.robot, "status")
    if args.action == "disperse":
        return control.command(session, keys, args.master, "disperse", _ORGANIZE_TIMEOUT_S)
    if args.user:
        connected = control.command(session, keys, args.master, "connect", user=args.user)
        if "error" in connected:
            return connected
    extra = {"protocol": args.protocol} if args.protocol else {}
    return control.command(session, keys, args.master, "organize", _ORGANIZE_TIMEOUT_S, count=args.count, **extra)


def describe(action: str, answer: dict[str, Any]) -> str:
    """One human line per figure."""
    if action == "disperse":
        return (
            f"dispersed {len(answer['members'])} members in {answer['disperse_time_s'] * 1000:.1f} ms "
            f"({answer['retries']} retries); master back to {answer['restored']}; "
            f"unconfirmed: {answer['unconfirmed'] or 'none'}"
        )
    refused = ", ".join(f"{why.replace('_', ' ')}: {robots}" for why, robots in answer["refused"].items()) or "none"
    steps = ", ".join(f"{step} {n}" for step, n in answer["step_retries"].items())
    return (
        f"swarm on PAN {answer['pan_id']:#06x}: members {answer['members'] or 'none'} (closest first) of "
        f"{answer['requested']} requested; {len(answer['available'])} available; refused: {refused}\n"
        f"organized in {answer['organize_time_s'] * 1000:.1f} ms with {answer['retries']} retries ({steps}) "
        f"[{answer['protocol']} protocol]"
    )
