"""Overlap, capture, half duplex, range and the PAN/address/channel filters.

The overlap tests run the ``overlap`` reception model (the unit-disk rule, a named option); the default ``sinr``
model's reception rule has its own tests in test_reception_sinr.py."""

import pytest

from radio_hub.air.mac import BROADCAST
from radio_hub.air.medium import Medium, RxOutcome, TxStatus
from radio_hub.config import airtime_us

from .helpers import PAN, data, medium, place, receptions, reports, run_to_idle

ALOHA = {"mac": {"csma_enabled": False}}
OVERLAP = {**ALOHA, "reception": {"model": "overlap"}}
TURNAROUND = 192


def _outcome(m: Medium, sender: str, receiver: str) -> RxOutcome:
    return next(tx.outcomes[receiver] for tx in m.air_log if tx.sender == sender and receiver in tx.outcomes)


def test_overlapping_frames_collide_at_a_receiver_that_hears_both():
    m = medium(OVERLAP)
    a, b, c = place(m, 1, 0), place(m, 2, 2), place(m, 3, 1)
    m.submit(a, data(1, payload=bytes(30)), 1, 0)
    outs = run_to_idle(m, m.submit(b, data(2, payload=bytes(30)), 2, 100))
    assert receptions(outs, c) == []
    assert m.node_counters[c].collided == 2
    # each sender was transmitting during part of the other's frame: half duplex, nothing received
    assert _outcome(m, a, b) == RxOutcome.COLLIDED and _outcome(m, b, a) == RxOutcome.COLLIDED


def test_back_to_back_frames_do_not_collide():
    m = medium(ALOHA)
    a, b, c = place(m, 1, 0), place(m, 2, 2), place(m, 3, 1)
    psdu = data(1, payload=bytes(30))
    m.submit(a, psdu, 1, 0)
    # b starts exactly when a ends: intervals are half-open, so they do not overlap
    outs = run_to_idle(m, m.submit(b, data(2), 2, airtime_us(len(psdu))))
    assert len(receptions(outs, c)) == 2


def test_capture_keeps_the_much_stronger_frame():
    m = medium({**OVERLAP, "capture": {"enabled": True, "margin_db": 6.0}})
    a, b, c = place(m, 1, 0), place(m, 2, 21), place(m, 3, 1)  # c is 1 m from a, 20 m from b
    m.submit(a, data(1), 1, 0)
    outs = run_to_idle(m, m.submit(b, data(2), 2, 50))
    assert [r.sender for r in receptions(outs, c)] == [a]
    assert _outcome(m, b, c) == RxOutcome.COLLIDED


def test_without_capture_the_stronger_frame_is_lost_too():
    m = medium(OVERLAP)
    a, b, c = place(m, 1, 0), place(m, 2, 21), place(m, 3, 1)
    m.submit(a, data(1), 1, 0)
    assert receptions(run_to_idle(m, m.submit(b, data(2), 2, 50)), c) == []


def test_a_far_node_is_not_heard_but_interferes_and_is_sensed():
    m = medium(OVERLAP)  # tx range 30 m, interference range 50 m
    a, c, far = place(m, 1, 0), place(m, 3, 10), place(m, 9, 50)
    m.submit(far, data(9, payload=bytes(60)), 1, 0)
    outs = run_to_idle(m, m.submit(a, data(1), 2, 300))
    assert receptions(outs, c) == []  # 40 m from far: interference only, and it garbles a's frame
    assert m.node_counters[c].heard == 1 and m.node_counters[c].collided == 1
    m2 = medium({"mac": {"min_be": 0, "max_be": 0}, "reception": {"model": "overlap"}})
    a2, far2 = place(m2, 1, 0), place(m2, 9, 45)
    m2.submit(far2, data(9, payload=bytes(100)), 1, 0)
    failure = reports(run_to_idle(m2, m2.submit(a2, data(1), 2, 500)))
    assert next(r for r in failure if r.node_id == a2).status == TxStatus.CHANNEL_ACCESS_FAILURE


@pytest.mark.parametrize(
    "dst_pan, dst, delivered",
    [
        (PAN, BROADCAST, True),
        (PAN, 2, True),
        (BROADCAST, BROADCAST, True),
        (BROADCAST, 2, True),
        (PAN, 3, False),
        (0x2000, BROADCAST, False),
        (0x2000, 2, False),
    ],
)
def test_pan_and_address_filter(dst_pan, dst, delivered):
    m = medium({"mac": {"min_be": 0, "max_be": 0, "ack_enabled": False}})
    a, b = place(m, 1, 0), place(m, 2, 1)
    outs = run_to_idle(m, m.submit(a, data(1, dst=dst, pan=dst_pan), 1, 0))
    assert bool(receptions(outs, b)) is delivered
    assert m.node_counters[b].filtered == (0 if delivered else 1)


def test_other_channels_are_not_heard_at_all():
    m = medium(ALOHA)
    a, b = place(m, 1, 0, channel=11), place(m, 2, 1, channel=12)
    run_to_idle(m, m.submit(a, data(1), 1, 0))
    assert m.node_counters[b].heard == 0


def test_pan_switch_takes_effect_for_the_next_frame():
    m = medium(ALOHA)
    a, b = place(m, 1, 0, pan=0x2000), place(m, 2, 1)
    assert receptions(run_to_idle(m, m.submit(a, data(1, pan=0x2000), 1, 0)), b) == []
    m.update(b, pan_id=0x2000)
    assert len(receptions(run_to_idle(m, m.submit(a, data(1, pan=0x2000), 2, 10_000)), b)) == 1


def test_update_rejects_a_bad_channel_and_keeps_the_node_as_it_was():
    m = medium()
    a = place(m, 1, 0)
    with pytest.raises(ValueError, match="11-26"):
        m.update(a, channel=27)
    assert m.nodes[a].channel == 11


def test_refusals_name_the_problem():
    m = medium()
    a = place(m, 1, 0)
    [oversize] = m.submit(a, bytes(130), 1, 0)
    assert oversize.status == TxStatus.REFUSED and "127" in oversize.reason
    [garbage] = m.submit(a, b"\x01\x02\x03\x04\x05\x06", 2, 0)
    assert garbage.status == TxStatus.REFUSED and "FCS" in garbage.reason
    [stranger] = m.submit("nobody", data(1), 3, 0)
    assert "not attached" in stranger.reason
    assert m.node_counters[a].refused == 2


def test_detached_node_gets_nothing_and_its_queue_is_dropped():
    m = medium(ALOHA)
    a, b = place(m, 1, 0), place(m, 2, 1)
    m.submit(a, data(1), 1, 0)
    m.detach(a)
    outs = run_to_idle(m)
    assert reports(outs) == [] and receptions(outs) == []
    assert m.next_event_us() is None
    assert b in m.nodes


def test_transmission_start_is_cca_plus_turnaround_without_csma_it_is_turnaround_only():
    m = medium(ALOHA)
    a, b = place(m, 1, 0), place(m, 2, 1)
    [rx] = receptions(run_to_idle(m, m.submit(a, data(1), 1, 0)), b)
    assert rx.start_us == TURNAROUND


def test_channel_counters_add_up_to_the_node_counters():
    m = medium({"mac": {"min_be": 0, "max_be": 0}})
    a, b = place(m, 1, 0), place(m, 2, 1)
    m.submit(a, data(1, dst=9), 1, 0)  # nobody answers: retries, then no_ack
    m.submit(b, data(2, payload=bytes(100)), 2, 0)
    m.submit(a, bytes(3), 3, 0)  # refused
    run_to_idle(m)
    channel = m.channel_counters[11].to_dict()
    for name, value in channel.items():
        assert value == m.node_counters[a].to_dict()[name] + m.node_counters[b].to_dict()[name], name
    assert channel["no_ack"] + channel["channel_access_failures"] >= 1 and channel["refused"] == 1
