"""A node's first attach when the hub had not opened its up key yet (``radio_hub.link.up_keys``).

A zenoh link whose node gave up waiting for its key (``wait_for_up_key`` said False) puts its attach into
nothing: the hub hears the node only once its key opens, which may be a moment later (a hub busy with a
rogue's tokens). Such a link says so (``unheard``), and the radio sends its first attach again until answered,
as it does a re-attach; a link that was heard sends it once, as before.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable

import pytest

from radio_hub.link import wire
from radio_hub.link.port import HubUnavailable, RadioClient, RadioIdentity

IDENTITY = RadioIdentity("robot-1", 0x1234, 1, 0x1000, 11, (0.0, 0.0))


class LateKeyLink:
    """A ``HubLink`` whose hub opens the node's key only after ``lost`` messages went into nothing, then answers
    every attach."""

    def __init__(self, unheard: bool, lost: int = 1) -> None:
        self.unheard = unheard
        self.lost = lost
        self.attaches = 0
        self.on_down: Callable[[bytes], None] = lambda data: None

    def open(
        self, node_id: str, instance: str, on_down: Callable[[bytes], None], on_hub: Callable[[bool], None]
    ) -> None:
        self.on_down = on_down

    def put(self, data: bytes) -> None:
        msg = wire.decode(data)
        if self.lost:
            self.lost -= 1
            return
        if isinstance(msg, wire.Attach):
            self.attaches += 1
            answer = wire.Attached(
                token=0, ext_addr=msg.ext_addr, short_addr=msg.short_addr, pan_id=msg.pan_id, channel=msg.channel,
                position=msg.position, heading_deg=msg.heading_deg, instance=msg.instance, n=self.attaches,
            )  # fmt: skip
            asyncio.get_running_loop().call_soon(self.on_down, answer.encode())

    async def close(self) -> None:
        pass


def test_a_first_attach_put_before_the_key_opened_is_sent_again_until_answered() -> None:
    async def scenario() -> None:
        link = LateKeyLink(unheard=True, lost=2)
        radio = await RadioClient.connect(IDENTITY, link=link, timeout=3.0)  # type: ignore[arg-type]
        assert link.attaches == 1 and radio.identity.short_addr == 1
        await radio.close()

    asyncio.run(scenario())


def test_a_link_that_was_heard_sends_the_first_attach_once() -> None:
    async def scenario() -> None:
        link = LateKeyLink(unheard=False, lost=1)
        with pytest.raises(HubUnavailable):
            await RadioClient.connect(IDENTITY, link=link, timeout=1.2)  # type: ignore[arg-type]
        assert link.attaches == 0

    asyncio.run(scenario())
