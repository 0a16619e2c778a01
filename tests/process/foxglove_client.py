"""A Foxglove WebSocket client of the tests' own (over ``websockets``): it subscribes to every channel the server
advertises, as they come, and counts the messages it receives.

The protocol is Foxglove's WebSocket protocol, first named ``foxglove.websocket.v1``; foxglove-sdk servers of the
version petswarm pins answer only to its new name, ``foxglove.sdk.v1`` (the same messages). The client offers both,
as Foxglove's app does, and says which the server took."""

from __future__ import annotations

import asyncio
import json
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

SUBPROTOCOLS = ("foxglove.websocket.v1", "foxglove.sdk.v1")
MESSAGE_DATA = 0x01
"""Opcode of a binary message: subscription id (u32), log time (u64), then the message's bytes."""
TIME = 0x02
"""Opcode of the server's time (u64 nanoseconds)."""
_DATA_HEADER = struct.Struct("<BIQ")


@dataclass
class Received:
    """What a client saw: the server's info, the advertised topics, the messages per topic and their log times."""

    subprotocol: str = ""
    server_info: dict[str, object] = field(default_factory=dict)
    topics: dict[int, str] = field(default_factory=dict)
    """Channel id -> topic, of every advertisement."""
    schemas: dict[str, str] = field(default_factory=dict)
    """Topic -> schema name."""
    counts: dict[str, int] = field(default_factory=dict)
    log_times: dict[str, list[int]] = field(default_factory=dict)
    server_times: list[int] = field(default_factory=list)
    first: dict[str, bytes] = field(default_factory=dict)
    """The first message's bytes on each topic."""


async def listen(url: str, seconds: float, until: Callable[[], bool] | None = None) -> Received:
    """Connect to ``url``, subscribe to every advertised channel and collect for ``seconds`` (wall), or until the
    server closes, or until ``until()`` holds (looked at twice a second)."""
    got = Received()
    subscriptions: dict[int, str] = {}
    deadline = time.monotonic() + seconds
    offered: list[Any] = list(SUBPROTOCOLS)
    async with connect(url, subprotocols=offered, max_size=None, open_timeout=10) as ws:
        got.subprotocol = str(ws.subprotocol)
        while time.monotonic() < deadline and not (until is not None and until()):
            try:
                raw = await asyncio.wait_for(ws.recv(), 0.5)
            except TimeoutError:
                continue
            except ConnectionClosed:
                break
            if isinstance(raw, str):
                message = json.loads(raw)
                if message.get("op") == "serverInfo":
                    got.server_info = message
                elif message.get("op") == "advertise":
                    wanted = []
                    for channel in message["channels"]:
                        got.topics[channel["id"]] = channel["topic"]
                        got.schemas[channel["topic"]] = channel.get("schemaName", "")
                        sub = len(subscriptions) + 1
                        subscriptions[sub] = channel["topic"]
                        wanted.append({"id": sub, "channelId": channel["id"]})
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": wanted}))
                continue
            if raw[0] == TIME:
                got.server_times.append(struct.unpack_from("<Q", raw, 1)[0])
                continue
            if raw[0] != MESSAGE_DATA:
                continue
            _, sub, log_time = _DATA_HEADER.unpack_from(raw)
            topic = subscriptions[sub]
            got.counts[topic] = got.counts.get(topic, 0) + 1
            got.log_times.setdefault(topic, []).append(log_time)
            got.first.setdefault(topic, bytes(raw[_DATA_HEADER.size :]))
    return got
