"""A hub that carries frames without modelling the air: the floor under any hub's cost.

``petswarm hub --floor`` runs it; ``petswarm bench hub --floor`` measures it beside the real hub. Every frame
an attached robot sends is answered in zenoh's own thread the moment it arrives: a ``Received`` to every other node
on the sender's channel the frame is addressed to (its PAN and short address, or broadcast), then a ``TxDone``
(success) to the sender, both stamped with the arrival time and counted as the medium counts a frame (``sent`` for
the sender, ``heard`` and ``delivered`` for each receiver). No backoff, airtime, range, loss, collision, inbox or
job thread. Everything else (attaching, the world, the sensors, queries) is the hub's, unchanged.

So a bench against it measures what carrying a frame through a hub written in Python costs at the least (zenoh's
callback, decoding the frame, encoding two messages, two puts), and the real hub's figures beside it show what
modelling the air adds. Nothing a node hears from it is emulated: it is a measuring instrument, not a hub to run
experiments on.
"""

from __future__ import annotations

from typing import Any

from radio_hub.air.mac import Frame, FrameError, FrameType
from radio_hub.air.medium import RadioNode, RxOutcome, addressed_to
from radio_hub.link import wire
from radio_hub.shell.hub import RadioHub

FLOOR_RSSI_DBM = -40.0
"""The signal strength every frame it carries is reported with (none is modelled)."""
FLOOR_LQI = 255


class FloorHub(RadioHub):
    """``RadioHub`` whose robots' frames skip the medium: each is answered on arrival (module docstring)."""

    carried = 0
    """Frames answered on arrival (a frame that is not a robot's well-formed data frame goes the hub's way)."""

    def _admit(self, item: tuple[Any, ...]) -> None:
        """Zenoh's threads: a robot's frame is answered here and now; anything else goes to the inbox."""
        if item[0] == "up":
            try:
                if self._carry(self.keys.node_of(item[1]), item[2]):
                    return
            except Exception as err:  # a node that left meanwhile, say: counted, and zenoh's thread goes on
                self.env.faults.record("floor", err)
                return
        super()._admit(item)

    def _carry(self, node_id: str, data: bytes) -> bool:
        """Answer ``data`` if it is a data request of an attached robot, with its own session key; False leaves it
        to the hub (which refuses, counts or models it as it always does)."""
        env = self.env
        sender = env.medium.nodes.get(node_id)
        if sender is None or env.kinds.get(node_id) != "robot":
            return False
        try:
            msg = wire.decode(data, wire.MAX_UP_BYTES)
            frame = Frame.decode(msg.psdu) if type(msg) is wire.Transmit else None
        except (wire.WireError, FrameError):
            return False
        if frame is None or frame.frame_type is FrameType.ACK or msg.s != env.session_key_of(node_id):
            return False
        now = self.now_us()
        env._check_sequence(node_id, msg)
        receivers = [n for n in tuple(env.medium.nodes.values()) if _hears(sender, n, frame)]
        self._answer(sender, receivers, msg, now)
        return True

    def _answer(self, sender: RadioNode, receivers: list[RadioNode], msg: wire.Transmit, now: int) -> None:
        env, down = self.env, self._downlink
        counters = env.medium.node_counters
        with env._down_lock:  # a node's messages are numbered and sent in one order, whichever thread sends
            for node in receivers:
                n = env._next_down_seq(node.node_id)
                down.send(node.node_id, wire.encode_received(n, msg.psdu, FLOOR_RSSI_DBM, FLOOR_LQI, now, now, now))
                counters[node.node_id].count(RxOutcome.DELIVERED)
            n = env._next_down_seq(sender.node_id)
            down.send(sender.node_id, wire.encode_tx_done(n, msg.token, "success", 0, 0, now, now, ""))
            counters[sender.node_id].sent += 1
            self.carried += 1
        down.flush()

    def stats(self) -> dict[str, Any]:
        """The hub's counters, with the frames carried (``hub.carried``)."""
        stats = super().stats()
        stats["hub"]["carried"] = self.carried
        return stats


def _hears(sender: RadioNode, node: RadioNode, frame: Frame) -> bool:
    """Whether ``node`` gets the frame: another node on the sender's channel that the frame is addressed to (the
    medium's own address filter); no range, nothing lost."""
    return node is not sender and node.channel == sender.channel and addressed_to(frame, node)
