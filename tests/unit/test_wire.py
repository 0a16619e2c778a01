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


_u64 = st.integers(min_value=0, max_value=2**63 - 1)


@given(
    n=_u64,
    psdu=st.binary(max_size=127),
    rssi=st.floats(-100, 0),
    lqi=st.integers(0, 255),
    times=st.tuples(_u64, _u64, _u64),
)
def test_the_hubs_received_encoding_is_the_messages(n, psdu, rssi, lqi, times):
    start, end, submitted = times
    msg = wire.Received(psdu=psdu, rssi_dbm=rssi, lqi=lqi, start_us=start, end_us=end, submitted_us=submitted, n=n)
    assert wire.encode_received(n, psdu, rssi, lqi, start, end, submitted) == msg.encode()


@given(
    n=_u64,
    token=_u64,
    status=st.sampled_from(["success", "no_ack", "channel_access_failure", "refused"]),
    counts=st.tuples(st.integers(0, 7), st.integers(0, 7)),
    times=st.tuples(_u64, _u64),
    reason=st.text(max_size=40),
)
def test_the_hubs_tx_done_encoding_is_the_messages(n, token, status, counts, times, reason):
    (retries, backoffs), (submitted, done) = counts, times
    msg = wire.TxDone(
        token=token,
        status=status,
        retries=retries,
        backoffs=backoffs,
        submitted_us=submitted,
        done_us=done,
        reason=reason,
        n=n,
    )
    assert wire.encode_tx_done(n, token, status, retries, backoffs, submitted, done, reason) == msg.encode()
