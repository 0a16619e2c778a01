"""A downlink for tests that drive an ``Environment`` directly: it keeps every message sent, decoded."""

from __future__ import annotations

from typing import Any

import msgpack

from radio_hub.link import wire


class Recorder:
    """A downlink that keeps what the environment sends (and checks it can be decoded back), and checks that
    the world's state can always be published."""

    def __init__(self) -> None:
        self.sent: list[tuple[str, wire.Message]] = []

    def send(self, node_id: str, data: bytes) -> None:
        self.sent.append((node_id, wire.decode(data)))

    def forget(self, node_id: str) -> None:
        pass

    def publish_world(self, state: dict[str, Any]) -> None:
        msgpack.packb(state, use_bin_type=True)
