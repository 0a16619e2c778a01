"""A node whose up key the hub opens only after the node stopped waiting for it still attaches.

``wait_for_up_key`` waits 5 s; a hub busy with a rogue's tokens may open a node's key later than that (a robot
waited 10 s in vain behind 4,000 of them while its key opened). Here a hub in this process opens every key 1 s
after the token shows, and the node waits 0.3 s: its first attach goes out before its key is open.
"""

from __future__ import annotations

import asyncio
import threading
import time
import uuid
from typing import Any

import pytest

from petswarm.lab.processes import free_tcp_port
from radio_hub.link import up_keys, zenoh_link
from radio_hub.link.port import RadioClient, RadioIdentity
from radio_hub.shell.hub import RadioHub

KEY_LATE_S = 1.0


def test_an_attach_put_before_the_hub_opened_the_key_gets_through(monkeypatch: pytest.MonkeyPatch) -> None:
    token_came = up_keys.UpKeys._token_came

    def late(self: up_keys.UpKeys, node_id: str, instance: str) -> None:
        time.sleep(KEY_LATE_S)
        token_came(self, node_id, instance)

    monkeypatch.setattr(up_keys.UpKeys, "_token_came", late)
    monkeypatch.setattr(zenoh_link, "wait_for_up_key", lambda pub: up_keys.wait_for_up_key(pub, within_s=0.3))
    endpoint, world = f"tcp/127.0.0.1:{free_tcp_port()}", f"t{uuid.uuid4().hex[:10]}"
    hub = RadioHub(endpoint, world)
    hub.open()
    serving = threading.Thread(target=hub.serve, daemon=True)
    serving.start()

    async def attach() -> Any:
        identity = RadioIdentity("robot-7", 0x7, 7, 0x1000, 11, (1.0, 0.0))
        radio = await RadioClient.connect(identity, endpoint, world, timeout=5.0)
        unheard = radio.link.unheard  # type: ignore[attr-defined]
        await radio.close()
        return unheard

    try:
        assert asyncio.run(attach()) is True  # the node stopped waiting before its key opened, and attached
    finally:
        hub.stop()
        serving.join(10)
        hub.close()
