"""Zenoh key expressions and session settings shared by the hub and its nodes.

Every run lives under its own prefix ``petswarm/<world>`` so parallel runs on one router never meet.
"""

from __future__ import annotations

import re

import zenoh

ROOT = "petswarm"
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
DEFAULT_WORLD = "default"
_WORLD_RE = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")


def check_name(kind: str, name: str) -> str:
    """World and node names become key chunks: no '/', '*', '$' or spaces."""
    if not _WORLD_RE.match(name):
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

    @property
    def up_all(self) -> str:
        """What the hub subscribes to."""
        return f"{self.prefix}/up/*"

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


def session_config(mode: str, endpoint: str) -> zenoh.Config:
    """A zenoh config: ``router`` listens on ``endpoint``, ``client`` connects to it; no multicast."""
    if mode not in ("router", "client"):
        raise ValueError("mode must be router or client")
    config = zenoh.Config()
    config.insert_json5("mode", f'"{mode}"')
    where = "listen/endpoints" if mode == "router" else "connect/endpoints"
    config.insert_json5(where, f'["{endpoint}"]')
    config.insert_json5("scouting/multicast/enabled", "false")
    if mode == "client":
        # A restarted hub must get its nodes back at once. Zenoh's default backoff retries 1 s, then 2, then
        # 4 s after the router went away: a client unlucky with a hub down 1.5 s came back 5 s late, missed
        # the re-organize that followed, and failed test_the_hub_restarts about 1 run in 15 on a busy machine.
        # A constant 0.2-0.5 s costs a connect attempt per node twice a second while the hub is away.
        retry = "{ period_init_ms: 200, period_max_ms: 500, period_increase_factor: 1.5 }"
        config.insert_json5("connect/retry", retry)
    return config


def reliable_publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    """Emulated frames must never vanish in the transport: reliable, and block rather than drop."""
    return session.declare_publisher(
        key, congestion_control=zenoh.CongestionControl.BLOCK, reliability=zenoh.Reliability.RELIABLE
    )
