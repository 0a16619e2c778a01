"""MAC frame encoding: sizes, FCS and round trips."""

import contextlib

import pytest
from hypothesis import given
from hypothesis import strategies as st

from radio_hub.air.mac import ACK_PSDU_LEN, BROADCAST, MAX_PSDU, Frame, FrameError, FrameType, fcs, max_payload
from radio_hub.config import airtime_us


def test_fcs_is_crc16_kermit():
    # the standard check value of CRC-16/KERMIT, the 802.15.4 FCS
    assert fcs(b"123456789") == 0x2189


def _kermit_bitwise(data: bytes) -> int:
    """CRC-16/KERMIT by its definition: reflected polynomial 0x8408, one bit at a time, initial value 0."""
    crc = 0
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0x8408 if crc & 1 else crc >> 1
    return crc


@given(st.binary(max_size=MAX_PSDU + 8))
def test_fcs_matches_the_bitwise_definition(data):
    assert fcs(data) == _kermit_bitwise(data)
    assert fcs(bytearray(data)) == fcs(memoryview(data)) == fcs(data)


def test_intra_pan_data_frame_has_an_11_byte_overhead():
    frame = Frame(FrameType.DATA, 7, 0x1000, 2, 0x1000, 1, b"hello")
    assert len(frame.encode()) == 11 + 5


def test_inter_pan_frame_carries_the_source_pan():
    frame = Frame(FrameType.DATA, 7, 0x2000, 2, 0x1000, 1, b"x")
    assert len(frame.encode()) == 13 + 1
    assert Frame.decode(frame.encode()).src_pan == 0x1000


def test_ack_frame_is_five_bytes():
    assert len(Frame(FrameType.ACK, 9).encode()) == ACK_PSDU_LEN
    assert Frame.decode(Frame(FrameType.ACK, 9).encode()) == Frame(FrameType.ACK, 9)


def test_largest_payload_fits_and_one_more_byte_is_refused():
    Frame(FrameType.DATA, 1, payload=bytes(max_payload())).encode()
    assert len(Frame(FrameType.DATA, 1, payload=bytes(max_payload())).encode()) == MAX_PSDU
    with pytest.raises(FrameError, match=r"exceeds the 802\.15\.4 limit of 127"):
        Frame(FrameType.DATA, 1, payload=bytes(max_payload() + 1)).encode()


@pytest.mark.parametrize(
    "psdu, reason",
    [
        (b"\x41\x88", "shorter"),
        (bytes(128), "limit of 127"),
        (Frame(FrameType.DATA, 1, payload=b"abc").encode()[:-1] + b"\x00", "bad FCS"),
    ],
)
def test_bad_psdus_are_rejected_with_a_reason(psdu, reason):
    with pytest.raises(FrameError, match=reason):
        Frame.decode(psdu)


def test_airtime_counts_phy_header_and_psdu():
    assert airtime_us(127) == (6 + 127) * 32 == 4256
    assert airtime_us(ACK_PSDU_LEN) == 352


@given(
    seq=st.integers(0, 255),
    dst_pan=st.integers(0, 0xFFFF),
    src_pan=st.integers(0, 0xFFFF),
    dst=st.integers(0, 0xFFFF),
    src=st.integers(0, 0xFFFF),
    payload=st.binary(max_size=max_payload(False)),
    ack=st.booleans(),
)
def test_data_frames_round_trip(seq, dst_pan, src_pan, dst, src, payload, ack):
    frame = Frame(FrameType.DATA, seq, dst_pan, dst, src_pan, src, payload, ack)
    assert Frame.decode(frame.encode()) == frame


@given(st.binary(max_size=140))
def test_garbage_raises_only_frame_error(data):
    with contextlib.suppress(FrameError):
        Frame.decode(data)


def test_broadcast_flag():
    assert Frame(FrameType.DATA, 0, dst=BROADCAST).is_broadcast
    assert not Frame(FrameType.DATA, 0, dst=3).is_broadcast
