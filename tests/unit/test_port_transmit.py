"""RadioClient's lean path for high-rate nodes: ``transmit`` with a callback and ``on_frame``, no future per frame."""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Coroutine
from typing import Any

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


SWARM_PAN, HOME_PAN = 0xE74B, 0x1000


def _attached(pan: int, token: int = 0) -> wire.Attached:
    return wire.Attached(token=token, ext_addr=0x1234, short_addr=1, pan_id=pan)


async def _settle() -> None:
    for _ in range(5):  # an answer wakes the waiting request, which wakes the re-attach
        await asyncio.sleep(0)


async def _reattaching() -> tuple[RadioClient, RecordingLink]:
    """A radio on the swarm's PAN whose hub has just restarted: its attach to the new hub is on the way."""
    link = RecordingLink()
    identity = RadioIdentity("n1", 0x1234, 1, SWARM_PAN, 11, (0.0, 0.0))
    connecting = asyncio.ensure_future(RadioClient.connect(identity, link=link))
    await asyncio.sleep(0)
    link.down(_attached(SWARM_PAN))
    radio = await connecting
    link.on_hub(True)
    await asyncio.sleep(0)
    assert isinstance(link.sent[-1], wire.Attach) and link.sent[-1].pan_id == SWARM_PAN
    return radio, link


async def _refused_before_the_attach(
    link: RecordingLink, request: Coroutine[Any, Any, Any]
) -> tuple[asyncio.Future[Any], wire.Message, wire.Message]:
    """Start ``request`` while re-attaching; the new hub refuses it as not attached, then answers the attach:
    the request's future, what the radio sent first and what it sent then."""
    pending = asyncio.ensure_future(request)
    await asyncio.sleep(0)
    refused = link.sent[-1]
    link.down(wire.Error(token=refused.token, reason=wire.NOT_ATTACHED))  # type: ignore[attr-defined]
    link.down(_attached(SWARM_PAN))
    await _settle()
    return pending, refused, link.sent[-1]


def test_a_configure_refused_while_reattaching_is_made_once_attached():
    """A robot whose swarm timed out as the hub restarted: its configure (home PAN) reached the new hub before
    its attach (swarm PAN) and was refused as "not attached"; the hub must end with the home PAN, configured
    (another attach would start the node afresh there)."""

    async def scenario() -> None:
        radio, link = await _reattaching()
        configuring, refused, again = await _refused_before_the_attach(link, radio.configure(pan_id=HOME_PAN))
        assert isinstance(refused, wire.Configure)
        assert isinstance(again, wire.Configure) and again.pan_id == HOME_PAN and again.token != refused.token
        assert again.short_addr is None and again.channel is None and again.position is None  # only what differs
        link.down(_attached(HOME_PAN, again.token))
        assert (await asyncio.wait_for(configuring, 1.0)).pan_id == HOME_PAN
        assert radio.identity.pan_id == HOME_PAN and radio.reattaches == 1 and radio.faults.total == 0

    asyncio.run(scenario())


def test_a_not_attached_answer_to_a_tokenless_message_does_not_fail_the_attach():
    """The new hub answers a message without a token (a drive sent before the attach) "not attached" with token
    0, which is the attach's: the re-attach must go on, and the configure made after it (seen in
    test_chaos's hub restart: a robot back to waiting kept the swarm's PAN while the hub had it home)."""

    async def scenario() -> None:
        radio, link = await _reattaching()
        configuring = asyncio.ensure_future(radio.configure(pan_id=HOME_PAN))
        await asyncio.sleep(0)
        link.down(wire.Error(token=link.sent[-1].token, reason=wire.NOT_ATTACHED))  # type: ignore[attr-defined]
        link.down(wire.Error(token=0, reason=wire.NOT_ATTACHED))  # the answer to the drive
        link.down(_attached(SWARM_PAN))
        await _settle()
        again = link.sent[-1]
        assert isinstance(again, wire.Configure) and again.pan_id == HOME_PAN
        link.down(_attached(HOME_PAN, again.token))
        assert (await asyncio.wait_for(configuring, 1.0)).pan_id == HOME_PAN
        assert radio.identity.pan_id == HOME_PAN and radio.reattaches == 1 and radio.faults.total == 0

    asyncio.run(scenario())


def test_a_late_answer_to_an_earlier_attach_copy_does_not_undo_a_configure():
    """The attach goes again every 0.5 s until answered: a slow new hub may answer two copies, and the second
    answer (swarm PAN) must not settle the configure that the robot still wants made."""

    async def scenario() -> None:
        radio, link = await _reattaching()
        configuring, _, configure = await _refused_before_the_attach(link, radio.configure(pan_id=HOME_PAN))
        link.down(_attached(SWARM_PAN))  # the late answer to the attach's earlier copy
        await _settle()
        assert not configuring.done()
        link.down(_attached(HOME_PAN, configure.token))
        assert (await asyncio.wait_for(configuring, 1.0)).pan_id == HOME_PAN
        assert radio.identity.pan_id == HOME_PAN

    asyncio.run(scenario())


def test_an_ir_switch_refused_while_reattaching_is_made_once_attached():
    """The IR module switched as the hub restarted: the new hub refuses it before our attach; the switch waits
    for the attach and goes again, rather than failing the token schedule's step."""

    async def scenario() -> None:
        radio, link = await _reattaching()
        switching, refused, again = await _refused_before_the_attach(link, radio.set_ir_mode("transmit"))
        assert isinstance(refused, wire.SetIrMode)
        assert isinstance(again, wire.SetIrMode) and again.mode == "transmit" and again.token != refused.token
        link.down(_attached(SWARM_PAN, again.token))
        await asyncio.wait_for(switching, 1.0)
        assert radio.reattaches == 1 and radio.faults.total == 0

    asyncio.run(scenario())


def test_a_refused_ir_switch_is_not_retried_once_a_later_one_took_its_place():
    """Switches overlap (the token schedule runs them in tasks of their own): "transmit" refused before the
    attach, then "receive" accepted after it; a retried "transmit" would leave the module shining."""

    async def scenario() -> None:
        radio, link = await _reattaching()
        first = asyncio.ensure_future(radio.set_ir_mode("transmit"))
        await asyncio.sleep(0)
        link.down(wire.Error(token=link.sent[-1].token, reason=wire.NOT_ATTACHED))
        second = asyncio.ensure_future(radio.set_ir_mode("receive"))
        await asyncio.sleep(0)
        receive = link.sent[-1]
        link.down(_attached(SWARM_PAN))
        link.down(_attached(SWARM_PAN, receive.token))
        await asyncio.wait_for(asyncio.gather(first, second), 1.0)
        modes = [m.mode for m in link.sent if isinstance(m, wire.SetIrMode)]
        assert modes == ["transmit", "receive"]

    asyncio.run(scenario())


def test_a_move_refused_while_reattaching_is_made_once_attached():
    """A robot placed elsewhere (``configure(position=...)``) as the hub restarted: the attach said where it was
    before, so the move goes as a configure of the position alone."""

    async def scenario() -> None:
        radio, link = await _reattaching()
        moving, _, again = await _refused_before_the_attach(link, radio.configure(position=(2.0, -1.5)))
        assert isinstance(again, wire.Configure) and again.position == [2.0, -1.5] and again.pan_id is None
        link.down(
            wire.Attached(token=again.token, ext_addr=0x1234, short_addr=1, pan_id=SWARM_PAN, position=[2.0, -1.5])
        )
        assert (await asyncio.wait_for(moving, 1.0)).position == (2.0, -1.5)

    asyncio.run(scenario())
