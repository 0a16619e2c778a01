"""802.15.4-2011 clause 9 link security on the emulated air (``radio_hub.air.security``): the PSDU carries the
auxiliary security header and the MIC, a receiver takes only authentic, fresh frames, and counts the rest."""

from __future__ import annotations

import dataclasses

import pytest

from radio_hub.air.mac import MAX_PSDU, Frame, FrameType
from radio_hub.air.security import AUX_LEN, NETWORK_KEY, SWARM_KEY, LinkSecurity, SecurityError, swarm_key
from radio_hub.config import airtime_us

KEY = bytes(range(16))


def _frame(src: int = 1, payload: bytes = b"hello swarm", pan: int = 0x1000) -> Frame:
    return Frame(FrameType.DATA, 7, pan, 0xFFFF, pan, src, payload)


@pytest.mark.parametrize("mic", [4, 8])
def test_a_secured_frame_carries_the_aux_header_and_mic_and_costs_their_airtime(mic: int) -> None:
    sender, receiver = LinkSecurity(KEY, mic), LinkSecurity(KEY, mic)
    plain = _frame()
    secured = sender.protect(plain)
    psdu = secured.encode()
    assert len(psdu) == len(plain.encode()) + AUX_LEN + mic
    fc = int.from_bytes(psdu[:2], "little")
    assert fc & (1 << 3) and (fc >> 12) & 3 == 1  # Security Enabled, frame version 1
    assert psdu[9] == (5 if mic == 4 else 6) | 1 << 3  # security control: level, key identifier mode 1
    assert b"hello swarm" not in psdu  # encrypted
    assert airtime_us(len(psdu)) - airtime_us(len(plain.encode())) == (AUX_LEN + mic) * 32  # 32 us a byte
    assert receiver.unprotect(Frame.decode(psdu)) == plain
    assert receiver.counters.accepted == 1


def test_forged_replayed_unsecured_and_unknown_key_frames_are_refused_and_counted() -> None:
    sender, receiver = LinkSecurity(KEY), LinkSecurity(KEY)
    outsider = LinkSecurity(bytes(16), frame_counter=100)  # ahead of the real sender: only the MIC can tell
    first = Frame.decode(sender.protect(_frame()).encode())
    receiver.unprotect(first)
    cases = [
        (_frame(), "unsecured"),  # the plain frames of a node without the key (a spoofed short address)
        (first, "replayed"),  # the same frame again
        (Frame.decode(outsider.protect(_frame()).encode()), "mic_failed"),  # a forgery under another key
        (dataclasses.replace(first, payload=first.payload[:-1] + b"\x00", seq=8), "replayed"),
        (Frame.decode(sender.protect(_frame(), NETWORK_KEY).encode()), None),
    ]
    tampered = sender.protect(_frame())
    cases.append((dataclasses.replace(tampered, dst=0x0002), "mic_failed"))  # a changed header bit
    for frame, reason in cases:
        if reason is None:
            receiver.unprotect(frame)
            continue
        with pytest.raises(SecurityError) as err:
            receiver.unprotect(frame)
        assert err.value.reason == reason
    sender.set_swarm_key(swarm_key(KEY, 1, 99), 0x4444)
    with pytest.raises(SecurityError):
        receiver.unprotect(sender.protect(_frame(pan=0x4444), sender.key_for(_frame(pan=0x4444))))
    counts = receiver.counters.to_dict()
    assert counts == {**counts, "unsecured": 1, "replayed": 2, "mic_failed": 2, "unknown_key": 1, "accepted": 2}


def test_a_forged_frame_does_not_move_the_counter_and_the_swarm_key_goes_with_the_swarm_pan() -> None:
    sender, receiver = LinkSecurity(KEY), LinkSecurity(KEY)
    forged = dataclasses.replace(sender.protect(_frame()), payload=b"\x05" + b"\xff\xff\xff\x7f" + b"\x01" + b"x" * 8)
    with pytest.raises(SecurityError):
        receiver.unprotect(forged)
    receiver.unprotect(sender.protect(_frame()))  # the real sender's next frame is still taken
    key = swarm_key(KEY, 1, 7)
    sender.set_swarm_key(key, 0x5555)
    receiver.set_swarm_key(key, 0x5555)
    on_swarm = sender.protect_auto(_frame(pan=0x5555))
    assert on_swarm.payload[5] == SWARM_KEY and sender.protect_auto(_frame()).payload[5] == NETWORK_KEY
    assert receiver.unprotect(on_swarm).payload == b"hello swarm"
    assert LinkSecurity(KEY).max_payload() == MAX_PSDU - 2 - 9 - AUX_LEN - 4
