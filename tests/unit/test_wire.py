"""Node/hub and robot/robot message schemas: round trips, and garbage only ever raises the schema's error."""

import contextlib

import msgpack
import pytest
from hypothesis import given
from hypothesis import strategies as st

from petswarm.managers import messages
from radio_hub.link import wire


@pytest.mark.parametrize(
    "msg",
    [
        wire.Attach(ext_addr=2**63, short_addr=5, pan_id=0x1000, channel=26, position=[1.5, -2.0], n=1),
        wire.Configure(token=3, pan_id=0x2000, n=2),
        wire.Transmit(token=9, psdu=b"\x01\x02", n=3),
        wire.TxDone(token=9, status="no_ack", retries=3, n=4),
        wire.Received(psdu=b"x", rssi_dbm=-61.5, lqi=120, n=5),
        wire.Error(reason="nope", n=6),
        wire.Error(reason="node id robot-2 is taken", instance="9f3a", n=7),
        wire.Attached(token=0, short_addr=2, instance="9f3a", n=1),
        wire.IrBeacons(sources=["robot-2", "user"], readings=b"\0" * 96, t_us=40_000, gains=[1.0, 0.125]),
    ],
)
def test_wire_messages_round_trip(msg):
    assert wire.decode(msg.encode()) == msg


@pytest.mark.parametrize(
    "body, reason",
    [
        ({"v": 2, "t": "transmit"}, "version"),
        ({"v": 1, "t": "launch"}, "unknown message type"),
        ({"v": 1, "t": "transmit", "token": "1"}, "wrong type"),
        ({"v": 1, "t": "transmit", "token": True}, "wrong type"),
        ({"v": 1, "t": "attach", "position": [1.0]}, "wrong type"),
        ({"v": 1, "t": "ir_beacons", "gains": ["1"]}, "wrong type"),
        ({"v": 1, "t": "transmit", "colour": 1}, "bad transmit fields"),
    ],
)
def test_wire_rejects_bad_messages_with_a_reason(body, reason):
    with pytest.raises(wire.WireError, match=reason):
        wire.decode(msgpack.packb(body))


@given(st.binary(max_size=200))
def test_wire_garbage_raises_only_wire_error(data):
    with contextlib.suppress(wire.WireError):
        wire.decode(data)


@given(
    st.recursive(
        st.none() | st.integers(-(2**63), 2**64 - 1) | st.text() | st.binary(),
        lambda c: st.lists(c) | st.dictionaries(st.text(), c),
    )
)
def test_message_garbage_raises_only_message_error(value):
    with contextlib.suppress(messages.MessageError):
        messages.decode(msgpack.packb(value))


def test_swarm_messages_are_small_and_round_trip():
    ping = messages.Ping(nonce=2**31)
    assert messages.decode(ping.encode()) == ping
    assert len(ping.encode()) <= 8
    assert messages.decode(messages.Blob(1, b"abc").encode()) == messages.Blob(1, b"abc")
    with pytest.raises(messages.MessageError, match="unknown message type"):
        messages.decode(msgpack.packb([1, 99]))
