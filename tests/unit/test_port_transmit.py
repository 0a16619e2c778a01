"""RadioClient's lean path for high-rate nodes: ``transmit`` with a callback and ``on_frame``, no future per frame."""

from __future__ import annotations

import asyncio
from collections.abc import Callable

from radio_hub.air.mac import Frame, FrameType, TxStatus
from radio_hub.link import wire
from radio_hub.link.port import RadioClient, RadioIdentity, RxFrame, TxResult


class RecordingLink:
    """A ``HubLink`` that keeps what the node sends and lets the test speak for the hub."""

    def __init__(self) -> None:
        self.sent: list[wire.Message] = []
        self.on_down: Callable[[bytes], None] = lambda data: None
        self.on_hub: Callable[[bool], None] = lambda present: None
        self.n = 0

    def open(
        self, node_id: str, instance: str, on_down: Callable[[bytes], None], on_hub: Callable[[bool], None]
    ) -> None:
        self.on_down, self.on_hub = on_down, on_hub

    def put(self, data: bytes) -> None:
        self.sent.append(wire.decode(data))

    async def close(self) -> None:
        pass

    def down(self, msg: wire.Message) -> None:
        self.n += 1
        msg.n = self.n
        self.on_down(msg.encode())


def _radio() -> tuple[RadioClient, RecordingLink]:
    link = RecordingLink()
    identity = RadioIdentity("n1", 0x1234, 1, 0x1000, 11, (0.0, 0.0))
    return RadioClient(link, "w", identity), link


def test_transmit_sends_at_once_and_calls_back_with_the_tx_done_of_its_token():
    async def scenario() -> None:
        radio, link = _radio()
        results: list[tuple[str, TxResult]] = []
        first = radio.transmit(radio.data_frame(2, b"a", ack=False), lambda r: results.append(("a", r)))
        second = radio.transmit(radio.data_frame(2, b"b", ack=False), lambda r: results.append(("b", r)))
        assert [type(m) for m in link.sent] == [wire.Transmit, wire.Transmit]
        assert [m.token for m in link.sent] == [first, second]
        assert Frame.decode(link.sent[1].psdu).payload == b"b"
        link.down(wire.TxDone(token=second, status="success", submitted_us=10, done_us=900))
        link.down(wire.Error(token=first, reason="MAC queue full"))
        link.down(wire.TxDone(token=second, status="success"))  # a repeat of an answered token: nobody to call
        assert results == [
            ("b", TxResult(TxStatus.SUCCESS, 0, 0, 10, 900, "")),
            ("a", TxResult(TxStatus.REFUSED, 0, 0, 0, 0, "MAC queue full")),
        ]
        assert radio.faults.total == 0 and radio.malformed == 0

    asyncio.run(scenario())


def test_on_frame_takes_received_frames_instead_of_the_queue():
    async def scenario() -> None:
        radio, link = _radio()
        psdu = Frame(FrameType.DATA, 7, 0x1000, 1, 0x1000, 2, b"hi").encode()
        link.down(wire.Received(psdu=psdu, rssi_dbm=-40.0, lqi=255, start_us=1, end_us=2, submitted_us=0))
        queued = await asyncio.wait_for(radio.receive(), 1.0)
        frames: list[RxFrame] = []
        radio.on_frame = frames.append
        link.down(wire.Received(psdu=psdu, rssi_dbm=-41.0, lqi=250, start_us=3, end_us=4, submitted_us=1))
        assert queued.frame.payload == b"hi"
        assert [(f.frame.payload, f.rssi_dbm, f.end_us) for f in frames] == [(b"hi", -41.0, 4)]
        assert radio._rx.empty()

    asyncio.run(scenario())


def test_a_configure_refused_while_reattaching_is_carried_by_a_second_attach():
    """A robot whose swarm timed out as the hub restarted: its configure (home PAN) reached the new hub before
    its attach (swarm PAN) and was refused as "not attached"; the hub must end with the home PAN."""

    async def scenario() -> None:
        link = RecordingLink()
        identity = RadioIdentity("n1", 0x1234, 1, 0xE74B, 11, (0.0, 0.0))
        connecting = asyncio.ensure_future(RadioClient.connect(identity, link=link))
        await asyncio.sleep(0)
        link.down(wire.Attached(token=0, ext_addr=0x1234, short_addr=1, pan_id=0xE74B))
        radio = await connecting
        link.on_hub(True)  # the hub came back: attach again, on the swarm PAN
        await asyncio.sleep(0)
        assert isinstance(link.sent[-1], wire.Attach) and link.sent[-1].pan_id == 0xE74B
        configuring = asyncio.ensure_future(radio.configure(pan_id=0x1000))
        await asyncio.sleep(0)
        configure = link.sent[-1]
        assert isinstance(configure, wire.Configure)
        link.down(wire.Error(token=configure.token, reason=wire.NOT_ATTACHED))
        link.down(wire.Attached(token=0, ext_addr=0x1234, short_addr=1, pan_id=0xE74B))
        for _ in range(5):  # the attach's answer wakes the re-attach, which looks at what is wanted now
            await asyncio.sleep(0)
        again = link.sent[-1]
        assert isinstance(again, wire.Attach) and again.pan_id == 0x1000
        link.down(wire.Attached(token=0, ext_addr=0x1234, short_addr=1, pan_id=0x1000))
        assert (await asyncio.wait_for(configuring, 1.0)).pan_id == 0x1000
        assert radio.identity.pan_id == 0x1000 and radio.reattaches == 1 and radio.faults.total == 0

    asyncio.run(scenario())


def test_an_ir_switch_refused_while_reattaching_is_made_once_attached():
    """The IR module switched as the hub restarted: the new hub refuses it before our attach; the switch waits
    for the attach and goes again, rather than failing the token schedule's step."""

    async def scenario() -> None:
        link = RecordingLink()
        identity = RadioIdentity("n1", 0x1234, 1, 0xE74B, 11, (0.0, 0.0))
        connecting = asyncio.ensure_future(RadioClient.connect(identity, link=link))
        await asyncio.sleep(0)
        link.down(wire.Attached(token=0, ext_addr=0x1234, short_addr=1, pan_id=0xE74B))
        radio = await connecting
        link.on_hub(True)
        await asyncio.sleep(0)
        switching = asyncio.ensure_future(radio.set_ir_mode("transmit"))
        await asyncio.sleep(0)
        refused = link.sent[-1]
        assert isinstance(refused, wire.SetIrMode)
        link.down(wire.Error(token=refused.token, reason=wire.NOT_ATTACHED))
        link.down(wire.Attached(token=0, ext_addr=0x1234, short_addr=1, pan_id=0xE74B))
        for _ in range(5):
            await asyncio.sleep(0)
        again = link.sent[-1]
        assert isinstance(again, wire.SetIrMode) and again.mode == "transmit" and again.token != refused.token
        link.down(wire.Attached(token=again.token, ext_addr=0x1234, short_addr=1, pan_id=0xE74B))
        await asyncio.wait_for(switching, 1.0)
        assert radio.reattaches == 1 and radio.faults.total == 0

    asyncio.run(scenario())
