"""The control channel of robot processes: how the CLI and tests ask a running robot to do things.

Each robot serves a queryable ``petswarm/<world>/robot/<id>/ctl`` taking a msgpack map ``{"cmd": ...}``
and answering a map; it also listens on ``petswarm/<world>/robots/ctl`` for commands to all robots at
once (no answer), which lets a test make several robots act in the same instant.
"""

from __future__ import annotations

import time
from typing import Any

import msgpack
import zenoh

from radio_hub.interface import HubUnavailable, Keys


def robot_key(keys: Keys, robot_id: int) -> str:
    """The control queryable of one robot."""
    return f"{keys.prefix}/robot/{robot_id}/ctl"


def all_robots_key(keys: Keys) -> str:
    """The control topic every robot listens to."""
    return f"{keys.prefix}/robots/ctl"


def command(
    session: zenoh.Session, keys: Keys, robot_id: int, cmd: str, timeout: float = 5.0, **args: Any
) -> dict[str, Any]:
    """Send one command to one robot and return its answer; HubUnavailable if it does not answer."""
    payload = msgpack.packb({"cmd": cmd, **args}, use_bin_type=True)
    started = time.monotonic()
    for reply in session.get(robot_key(keys, robot_id), payload=payload, timeout=timeout):
        if reply.ok is not None:
            return msgpack.unpackb(reply.ok.payload.to_bytes(), raw=False, strict_map_key=False)
    if time.monotonic() - started < timeout * 0.9:  # zenoh ends a query at once when nobody serves the key
        raise HubUnavailable(f"no robot {robot_id} serves world {keys.world!r} (not running, or not attached yet)")
    raise HubUnavailable(f"robot {robot_id} of world {keys.world!r} did not answer {cmd!r} within {timeout} s")


def broadcast(session: zenoh.Session, keys: Keys, cmd: str, **args: Any) -> None:
    """Send one command to every robot of the world at once."""
    session.put(all_robots_key(keys), msgpack.packb({"cmd": cmd, **args}, use_bin_type=True))
