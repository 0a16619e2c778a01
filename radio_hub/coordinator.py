"""The instant protocol of model and lockstep time: when, and in which order, the environment hears its nodes.

Within one instant of model time everything is in rounds. Nodes run what is due (their timers), and their
messages to the environment are held; the environment's messages to nodes are held too. When every node is
idle, held messages go out first, in the order the environment made them; once nodes are idle again and
nothing is held for them, the held messages from nodes are taken in a fixed order (by node id, then in the
order each node sent them), the environment advances to the instant, and what it answers starts the next
round. When a round brings nothing, time moves on to the earliest due timer or environment event.

Both drivers keep exactly these rules: ``--clock model`` (``petswarm.lab.model_run.MemoryAir``: every node on one
loop, "every node idle" is the loop having nothing ready) and ``--clock lockstep`` (``radio_hub.shell.lockstep``:
node processes report idle over zenoh and are granted the next instant). So a node sees the same messages at
the same instants in the same order in both, and equal seeds give equal digests. Pure: no I/O, no clock.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from pathlib import Path
from typing import Any

from radio_hub.environment import Environment, EnvironmentConfig
from radio_hub.link import wire
from radio_hub.link.values import MODEL_EPOCH_S

MODEL_EPOCH_US = round(MODEL_EPOCH_S * 1e6)


class Coordinator:
    """The environment with its inputs and outputs held per instant (it is the environment's ``Downlink``)."""

    def __init__(
        self,
        config: EnvironmentConfig,
        seed: int,
        *,
        wall_epoch_us: int,
        pcap_path: str | Path | None = None,
        world_log: str | Path | None = None,
        in_memory: bool = False,
    ) -> None:
        """``in_memory``: every node is in this process (model time), so the environment may hand the bulk of
        its messages over as they are (``environment.MessageDownlink``); otherwise every message is bytes."""
        self.takes_messages = in_memory
        self.env = Environment(
            config, seed, self, wall_epoch_us=wall_epoch_us, pcap_path=pcap_path, world_log=world_log
        )
        self.on_world: Callable[[dict[str, Any]], None] | None = None
        """Where world states for viewers go (10 Hz); None: nowhere."""
        self._downs: dict[str, list[bytes | wire.Message]] = {}
        self._ups: list[tuple[str, bool, int, bytes | wire.Message | None, str]] = []
        """Held node messages: (node id, whether it is the node's departure, arrival order, message, instance),
        so that their plain order is the order they are taken in."""
        self._order = itertools.count()

    # -- the environment's Downlink: held until the round ends ----------------------------------------------

    def send(self, node_id: str, data: bytes) -> None:
        """Hold a message for ``node_id``."""
        self._downs.setdefault(node_id, []).append(data)

    def send_message(self, node_id: str, msg: wire.Message) -> None:
        """Hold a message for ``node_id`` as it is (only when ``in_memory``)."""
        self._downs.setdefault(node_id, []).append(msg)

    def forget(self, node_id: str) -> None:
        """Messages still held for a node that left go nowhere."""
        self._downs.pop(node_id, None)

    @property
    def publishes_world(self) -> bool:
        """Whether a viewer callback takes the world's states (else the environment makes none)."""
        return self.on_world is not None

    def publish_world(self, state: dict[str, Any]) -> None:
        """Hand the world's state to the viewer callback, if any."""
        if self.on_world is not None:
            self.on_world(state)

    # -- inputs from the nodes: held until every node is idle --------------------------------------------

    def up(self, node_id: str, data: bytes | wire.Message) -> None:
        """A node's message (bytes, or in memory one handed over as it is), held for the end of the round."""
        self._ups.append((node_id, False, next(self._order), data, ""))

    def leave(self, node_id: str, instance: str) -> None:
        """A node's presence ended (its link closed, its liveliness went): taken in order with its messages."""
        self._ups.append((node_id, True, next(self._order), None, instance))

    # -- the rounds ------------------------------------------------------------------------------------

    def take_downs(self) -> dict[str, list[bytes | wire.Message]]:
        """Every held message for nodes, per node in the order the environment made them (bytes, or with
        ``in_memory`` some as they are)."""
        downs, self._downs = self._downs, {}
        return downs

    def settle(self, now_us: int) -> bool:
        """Hand the held node messages to the environment (by node id, then in sending order) and advance it
        to ``now_us``; False when nothing was held."""
        if not self._ups:
            return False
        # a node's departure comes after everything it sent (its liveliness may overtake its last messages); the
        # arrival order is unique, so the tuples' own order never compares messages (and needs no key function)
        ups, self._ups = sorted(self._ups), []
        for node_id, gone, _, data, instance in ups:
            if gone:
                self.env.node_gone(node_id, instance, now_us)
            else:
                self.env.receive(node_id, data, now_us)
        self.env.advance(now_us)
        return True

    def advance(self, now_us: int) -> None:
        """Carry out the environment's events due by ``now_us`` (what they send is held)."""
        if self.env.next_event_us() <= now_us:
            self.env.advance(now_us)

    def next_event_us(self) -> int:
        """The environment's next event."""
        return self.env.next_event_us()

    def close(self) -> None:
        """Close the environment's files."""
        self.env.close()
