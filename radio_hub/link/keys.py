"""Zenoh key expressions shared by the hub and its nodes (plain strings: this module imports no zenoh).

Every run lives under its own prefix ``petswarm/<world>`` so parallel runs on one router never meet.
"""

from __future__ import annotations

import re

ROOT = "petswarm"
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
DEFAULT_WORLD = "default"
WORLD_THREAD = "hub-world"
"""The name of the hub's world thread, as the OS sees it too (``/proc/<pid>/task/*/comm``): a bench reads its CPU."""
_WORLD_RE = re.compile(r"[A-Za-z0-9_.-]{1,64}")


def check_name(kind: str, name: str) -> str:
    """World and node names become key chunks: no '/', '*', '$' or spaces."""
    if not _WORLD_RE.fullmatch(name):  # not match with "$": that lets a trailing newline through
        raise ValueError(f"{kind} {name!r} must be 1-64 letters, digits, '_', '.' or '-'")
    return name


class Keys:
    """The key expressions of one world."""

    def __init__(self, world: str = DEFAULT_WORLD) -> None:
        self.world = check_name("world", world)
        self.prefix = f"{ROOT}/{world}"

    def up(self, node_id: str) -> str:
        """Node -> hub messages of one node."""
        return f"{self.prefix}/up/{node_id}"

    def down(self, node_id: str) -> str:
        """Hub -> node messages of one node."""
        return f"{self.prefix}/down/{node_id}"

    def alive(self, node_id: str, instance: str) -> str:
        """A node's liveliness token; ``instance`` tells a restarted node from its earlier self."""
        return f"{self.prefix}/alive/{node_id}/{instance}"

    @property
    def alive_all(self) -> str:
        """What the hub watches for arrivals and departures."""
        return f"{self.prefix}/alive/*/*"

    def alive_of(self, key: str) -> tuple[str, str]:
        """(node id, instance) of a liveliness key."""
        node_id, instance = str(key).rsplit("/", 2)[-2:]
        return node_id, instance

    @property
    def stats(self) -> str:
        """The hub's counters (queryable)."""
        return f"{self.prefix}/hub/stats"

    @property
    def hub_alive(self) -> str:
        """The hub's liveliness token: nodes re-attach when a (restarted) hub appears."""
        return f"{self.prefix}/hub/alive"

    @property
    def chaos(self) -> str:
        """The hub's fault injection (queryable: add, clear, list)."""
        return f"{self.prefix}/hub/chaos"

    @property
    def world_state(self) -> str:
        """The hub's ground truth, published about 10 times a second for viewers (msgpack)."""
        return f"{self.prefix}/hub/world"

    @property
    def world_query(self) -> str:
        """The hub's ground truth now (queryable)."""
        return f"{self.prefix}/hub/world/now"

    @property
    def air(self) -> str:
        """The hub's recent frame log (queryable)."""
        return f"{self.prefix}/hub/air"

    def node_of(self, key: str) -> str:
        """The node id at the end of an up key."""
        return str(key).rsplit("/", 1)[-1]
