"""One put per node per pass: the hub's messages to a node travel in batches (``wire.encode_batch``), a node
takes a batch's messages in order, and a malformed batch is counted and dropped whole."""

from __future__ import annotations

import asyncio

import msgpack
import pytest

from radio_hub.air.mac import Frame, FrameType, TxStatus
from radio_hub.link import wire
from radio_hub.link.port import RadioClient, RadioIdentity, RxFrame, TxResult
from radio_hub.link.zenoh_link import DOWN_BATCH_BYTES, UP_BATCH_BYTES, _batches, put_batches
from tests.unit.test_port_transmit import RecordingLink


def _radio() -> tuple[RadioClient, RecordingLink]:
    link = RecordingLink()
    return RadioClient(link, "w", RadioIdentity("n1", 0x1234, 1, 0x1000, 11, (0.0, 0.0))), link


def _numbered(*msgs: wire.Message, first: int = 1) -> list[bytes]:
    for n, msg in enumerate(msgs, first):
        msg.n = n
    return [msg.encode() for msg in msgs]


def test_a_batch_splits_back_into_its_messages_in_order():
    parts = _numbered(wire.TxDone(token=1, status="success"), wire.Error(reason="x"), wire.IrSample(t_us=5))
    data = wire.encode_batch(parts)
    assert wire.is_batch(data) and not wire.is_batch(parts[0])
    assert wire.split_batch(data) == parts
    assert [type(m) for m in wire.decode_all(data)] == [wire.TxDone, wire.Error, wire.IrSample]
    assert [m.n for m in wire.decode_all(parts[1])] == [2]


@pytest.mark.parametrize(
    "junk",
    [
        msgpack.packb([]),
        msgpack.packb([1, 2]),
        msgpack.packb(["a string"]),
        msgpack.packb([b"x"] * (wire.BATCH_MAX_PARTS + 1)),
        b"\x92\xc4\x01",  # an array cut short
        wire.encode_batch([bytes(wire.MAX_MESSAGE_BYTES)]),
    ],
)
def test_a_malformed_batch_raises_wire_error(junk: bytes):
    assert wire.is_batch(junk)
    with pytest.raises(wire.WireError):
        wire.split_batch(junk)


def test_a_node_takes_a_batch_in_order_and_counts_a_malformed_one_once():
    async def scenario() -> None:
        radio, link = _radio()
        results: list[TxResult] = []
        frames: list[RxFrame] = []
        radio.on_frame = frames.append
        token = radio.transmit(radio.data_frame(2, b"a", ack=False), results.append)
        psdu = Frame(FrameType.DATA, 7, 0x1000, 1, 0x1000, 2, b"hi").encode()
        received = wire.Received(psdu=psdu, rssi_dbm=-40.0, lqi=255, start_us=1, end_us=2, submitted_us=0)
        link.on_down(wire.encode_batch(_numbered(wire.TxDone(token=token, status="success", done_us=9), received)))
        assert [r.status for r in results] == [TxStatus.SUCCESS] and [f.end_us for f in frames] == [2]
        assert radio.malformed == 0 and radio.transport_gaps == 0
        link.on_down(msgpack.packb([b"not a message", 3]))
        assert radio.malformed == 1
        # a batch inside a batch is a malformed part; the good part beside it is taken
        inner = wire.encode_batch(_numbered(wire.IrSample(t_us=1), first=3))
        link.on_down(wire.encode_batch([inner, *_numbered(wire.Error(reason="e"), first=3)]))
        assert radio.malformed == 2 and radio.transport_gaps == 0 and radio.faults.total == 0

    asyncio.run(scenario())


def test_a_long_run_of_messages_is_cut_into_batches_within_bounds():
    parts = [bytes(100)] * (wire.BATCH_MAX_PARTS + 10)
    assert [len(b) for b in _batches(parts)] == [wire.BATCH_MAX_PARTS, 10]
    big = [bytes(DOWN_BATCH_BYTES // 2 + 1)] * 3
    assert [len(b) for b in _batches(big)] == [1, 1, 1]
    assert [part for batch in _batches(parts) for part in batch] == parts


def test_a_lockstep_node_batch_stays_within_what_the_hub_takes_from_a_node() -> None:
    """``UP_BATCH_BYTES`` leaves room for msgpack's headers: every batch of parts up to the limit encodes within
    ``wire.MAX_UP_BYTES``; a lone longer part goes alone (and the hub drops it as it always did)."""
    import random

    rng = random.Random(3)
    for _ in range(40):
        parts = [bytes(rng.choice((1, 30, 200, 4000, 30_000))) for _ in range(rng.randrange(1, 600))]
        runs = _batches(parts, UP_BATCH_BYTES)
        assert [part for run in runs for part in run] == parts
        for run in runs:
            assert len(run) <= wire.BATCH_MAX_PARTS
            assert len(run) == 1 or len(wire.encode_batch(run)) <= wire.MAX_UP_BYTES
    assert _batches([bytes(70_000), b"x"], UP_BATCH_BYTES) == [[bytes(70_000)], [b"x"]]


def test_nothing_to_put_is_no_put() -> None:
    """A lockstep link closing with nothing held puts nothing (an empty batch would be malformed)."""
    assert put_batches(None, [], UP_BATCH_BYTES) == 0  # no publisher: any put would raise HubUnavailable


def test_forged_message_numbers_cannot_push_the_gap_counter_out_of_msgpack():
    """Forged down messages once pushed a robot's gap counter to 2^64 - 4: its status answer could not be packed,
    so its status query never answered again."""

    async def scenario() -> None:
        radio, link = _radio()
        for _ in range(8):
            # the hub's attach answer numbers afresh; a forged message far ahead of it adds a gap each time
            link.on_down(wire.Attached(token=0, n=1, instance=radio.instance).encode())
            link.on_down(wire.IrSample(t_us=1, n=2**63 - 1).encode())
            link.on_down(wire.Error(reason="forged", n=2**63 - 1).encode())
        assert 0 < radio.transport_gaps < 2**63
        msgpack.packb({"gaps": radio.transport_gaps})

    asyncio.run(scenario())
