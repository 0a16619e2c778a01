"""``petswarm swarm organize|disperse|status``: the user's watch requests to a running robot, and its state.

Every answer prints in words by default; ``--json`` prints the robot's answer as it came."""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass
from typing import Any

from petswarm import control
from petswarm.lab.hub_session import with_hub
from radio_hub.interface import Keys
from radio_hub.values import HubUnavailable

_ORGANIZE_TIMEOUT_S = 60.0
_ROBOT_WAIT_S = 5.0


@dataclass
class SwarmOptions:
    """What ``petswarm swarm organize|disperse|status`` takes (``action``); each action uses its own fields."""

    action: str
    """``organize``, ``disperse`` or ``status``."""
    master: int | None = None
    """organize, disperse: the user-connected (master) robot."""
    robot: int | None = None
    """status: the robot asked."""
    count: int | None = None
    """organize: robots wanted besides the master."""
    protocol: str | None = None
    """organize: the protocol over the robot's own (None: the robot's)."""
    user: int | None = None
    """organize: connect the robot to this user first."""
    hub: str = "tcp/127.0.0.1:7447"
    world: str = "default"
    json: bool = False
    """Print the robot's answer as JSON (else in words)."""


def swarm_command(args: SwarmOptions) -> int:
    """Send the request, print the robot's answer; exit 1 when the robot refused, 2 when unreachable."""
    return with_hub("swarm", args.hub, lambda session: _ask(session, Keys(args.world), args))


def _ask(session: Any, keys: Keys, args: SwarmOptions) -> int:
    _wait_for_robot(session, keys, args.master or args.robot)
    answer = _request(session, keys, args)
    if "error" in answer:
        reason = answer["error"].split(": ", 1)[-1]  # the robot's exception class means nothing to a user
        print(
            f"petswarm swarm {args.action}: robot {args.master or args.robot} refused: {reason}",
            file=sys.stderr,
        )
        return 1
    print(json.dumps(answer, indent=2) if args.json else describe(args.action, answer))
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


def _request(session: Any, keys: Keys, args: SwarmOptions) -> dict[str, Any]:
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
    if action == "status":
        return "\n".join(describe_status(answer))
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


def describe_status(status: dict[str, Any]) -> list[str]:
    """A robot's status (its ``status`` control command) as a person reads it: state, radio, swarm, token
    schedule, the IR fixes of its neighbours, driving and message counters."""
    radio = status["radio"]
    x, y = radio["position"]
    lines = [
        f"robot {status['robot_id']} (pid {status['pid']}, up {status['uptime_s']:.1f} s): {status['state']}"
        + (f", connected to user {status['user']}" if status.get("user") else ""),
        f"radio: {radio['node_id']} short address {radio['short_addr']:#06x}, PAN {radio['pan_id']:#06x}, "
        f"channel {radio['channel']}; attached at ({x:.2f}, {y:.2f}) m heading {radio['heading_deg']:.0f} deg",
    ]
    swarm = status.get("swarm")
    if swarm:
        role = "the master" if swarm["master"] == status["robot_id"] else f"member {swarm['number']}"
        lines.append(
            f"swarm: PAN {swarm['pan_id']:#06x}, master {swarm['master']}, members {_ids(swarm['members'])}; "
            f"this robot is {role}, neighbours {_ids(swarm['neighbours'])}"
        )
    else:
        lines.append("swarm: none")
    ir = status.get("ir") or {}
    if ir:
        chain = " -> ".join(map(str, ir.get("chain") or [])) or "none"
        lines.append(
            f"IR token: round {ir.get('round')}, held {ir.get('rounds_held')} rounds, {ir.get('fixes')} fixes, "
            f"{ir.get('regenerations')} regenerations; module {ir.get('ir_mode')}; chain {chain}"
        )
    fixes = status.get("relative_location") or {}
    if fixes:
        lines.append(f"  {'neighbour':<11}{'bearing':>9}{'distance':>10}{'heading':>9}{'age':>8}{'fixes':>7}")
        for rid, fix in sorted(fixes.items(), key=lambda kv: int(kv[0]) if str(kv[0]).isdigit() else 0):
            heading = fix.get("heading_deg")
            lines.append(
                f"  {'robot ' + str(rid):<11}{fix['bearing_deg']:>8.1f}°{fix['distance_m']:>8.2f} m"
                f"{'-' if heading is None else f'{heading:.1f}°':>9}{fix['age_s']:>6.2f} s{fix.get('fixes', 0):>7}"
            )
    driving = status.get("driving") or {}
    if driving:
        vx, vy, omega = driving.get("command", (0.0, 0.0, 0.0))
        lines.append(
            f"driving: mode {driving.get('mode')}, owner {driving.get('owner') or 'none'}, command vx {vx:.2f} m/s "
            f"vy {vy:.2f} m/s omega {omega:.2f} rad/s"
        )
    surround = status.get("surround")
    if surround:
        lines.append("surround: " + ", ".join(f"{k.replace('_', ' ')} {_value(v)}" for k, v in surround.items()))
    tx = ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in sorted(status.get("tx_results", {}).items())) or "none"
    heard = _ids(sorted(int(k) for k in status.get("heard_from", {})))
    lines.append(
        f"messages: {status.get('messages_received', 0)} received ({status.get('malformed_payloads', 0)} malformed), "
        f"sends: {tx}; step retries {status.get('retries', 0)}, duplicates {status.get('duplicates', 0)}, "
        f"late answers {status.get('late_responses', 0)}; transport gaps {status.get('transport_gaps', 0)}"
    )
    if status.get("pings_sent"):
        lines.append(f"pings: {status['pings_sent']} sent, {status['pings_answered']} answered; heard from {heard}")
    for organization in status.get("organizations", []):
        lines.append("led: " + describe("organize", organization).replace("\n", "; "))
    return lines


def _ids(ids: list[int]) -> str:
    return ", ".join(map(str, ids)) or "none"


def _value(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.3g}"
    if isinstance(value, list):
        return "(" + ", ".join(_value(v) for v in value) + ")"
    return str(value)
