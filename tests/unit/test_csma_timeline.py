"""Unslotted CSMA-CA and acknowledged unicast against timelines computed by hand.

Constants (IEEE 802.15.4-2006, 2.4 GHz): unit backoff 320 us, CCA 128 us, turnaround 192 us,
ACK wait 864 us, airtime (6 + PSDU) x 32 us; an ACK PSDU is 5 bytes (352 us on air).
"""

import numpy as np

from radio_hub.air.medium import RxOutcome, TxStatus
from radio_hub.config import airtime_us

from .helpers import NO_BACKOFF, data, medium, place, receptions, reports, run_to_idle

CCA, TURNAROUND, UNIT, ACK_WAIT, ACK_AIR, SIFS = 128, 192, 320, 864, 352, 192


def test_broadcast_with_no_backoff_goes_out_after_cca_and_turnaround():
    m = medium(NO_BACKOFF)
    a, b = place(m, 1, 0), place(m, 2, 1)
    psdu = data(1, payload=bytes(20))
    outs = run_to_idle(m, m.submit(a, psdu, token=5, now_us=1000))
    start = 1000 + CCA + TURNAROUND
    end = start + airtime_us(len(psdu))
    [rx] = receptions(outs, b)
    assert (rx.start_us, rx.end_us, rx.submitted_us) == (start, end, 1000)
    [report] = reports(outs)
    assert (report.token, report.status, report.done_us) == (5, TxStatus.SUCCESS, end)


def test_backoff_slots_are_drawn_from_0_to_2_pow_min_be_minus_1():
    seed = 42
    m = medium(None, seed=seed)
    a, _ = place(m, 1, 0), place(m, 2, 1)
    psdu = data(1)
    [report] = reports(run_to_idle(m, m.submit(a, psdu, 1, 0)))
    slots = int(np.random.default_rng(seed).integers(0, 1 << 3))  # macMinBE = 3
    assert report.done_us == slots * UNIT + CCA + TURNAROUND + airtime_us(len(psdu))


def test_acknowledged_unicast_completes_when_the_ack_ends():
    m = medium(NO_BACKOFF)
    a, b = place(m, 1, 0), place(m, 2, 1)
    psdu = data(1, dst=2, payload=b"hi")
    outs = run_to_idle(m, m.submit(a, psdu, 1, 0))
    data_end = CCA + TURNAROUND + airtime_us(len(psdu))
    assert receptions(outs, b)[0].end_us == data_end
    [report] = reports(outs)
    assert report.status == TxStatus.SUCCESS
    assert report.done_us == data_end + TURNAROUND + ACK_AIR
    assert m.node_counters[b].acks_sent == 1


def test_an_ack_is_not_heard_by_a_sender_that_left_the_channel_meanwhile():
    m = medium(NO_BACKOFF)
    a, b = place(m, 1, 0), place(m, 2, 1)
    psdu = data(1, dst=2)
    m.submit(a, psdu, 1, 0)
    data_end = CCA + TURNAROUND + airtime_us(len(psdu))
    m.advance(data_end)  # b has the frame and turns around to send its ACK on channel 11
    m.update(a, channel=12)
    outs = run_to_idle(m)
    [ack] = [tx for tx in m.air_log if tx.sender == b and tx.frame.frame_type.name == "ACK"]
    assert ack.channel == 11 and ack.outcomes == {a: RxOutcome.LOST}
    assert m.node_counters[a].acks_lost == 1
    # a retries on channel 12, where b is not: no ACK at all
    [report] = reports(outs)
    assert report.status == TxStatus.NO_ACK and report.retries == 3


def test_unicast_to_nobody_is_retried_three_times_then_no_ack():
    m = medium(NO_BACKOFF)
    a = place(m, 1, 0)
    psdu = data(1, dst=9)
    [report] = reports(run_to_idle(m, m.submit(a, psdu, 1, 0)))
    attempt = CCA + TURNAROUND + airtime_us(len(psdu)) + ACK_WAIT
    assert report.status == TxStatus.NO_ACK
    assert report.retries == 3
    assert report.done_us == 4 * attempt
    assert m.node_counters[a].sent == 4
    assert m.node_counters[a].mac_retries == 3


def test_busy_channel_exhausts_backoffs_into_channel_access_failure():
    m = medium(NO_BACKOFF)
    a, b = place(m, 1, 0), place(m, 2, 1)
    long = data(1, payload=bytes(100))
    m.submit(a, long, 1, 0)  # on air from 320 to 320 + airtime
    assert airtime_us(len(long)) > 2000
    outs = run_to_idle(m, m.submit(b, data(2), 2, 1000))
    failure = next(r for r in reports(outs) if r.node_id == b)
    # BE stays 0 (macMaxBE 0): five CCAs back to back, each busy; NB 5 > macMaxCSMABackoffs 4
    assert failure.status == TxStatus.CHANNEL_ACCESS_FAILURE
    assert failure.done_us == 1000 + 5 * CCA
    assert failure.backoffs == 5
    assert m.node_counters[b].channel_access_failures == 1


def test_a_sender_that_senses_the_channel_busy_waits_and_goes_after():
    m = medium({"mac": {"min_be": 0, "max_be": 5}}, seed=3)
    a, b, c = place(m, 1, 0), place(m, 2, 1), place(m, 3, 2)
    first = data(1, payload=bytes(40))
    m.submit(a, first, 1, 0)
    outs = run_to_idle(m, m.submit(b, data(2), 2, 400))  # a is on air from 320
    at_c = sorted(receptions(outs, c), key=lambda r: r.start_us)
    assert [r.sender for r in at_c] == [a, b]
    assert at_c[1].start_us >= at_c[0].end_us  # no overlap, so no collision
    assert m.node_counters[c].collided == 0


def test_frames_queue_in_the_mac_one_at_a_time():
    m = medium(NO_BACKOFF)
    a, b = place(m, 1, 0), place(m, 2, 1)
    m.submit(a, data(1, seq=1), 1, 0)
    outs = run_to_idle(m, m.submit(a, data(1, seq=2), 2, 0))
    first, second = reports(outs)
    assert (first.token, second.token) == (1, 2)
    assert [r.frame.seq for r in receptions(outs, b)] == [1, 2]
    # the second waits for the interframe spacing after the first (a 12-octet MPDU: SIFS, 192 us), then CCA
    assert len(data(1)) <= 18
    assert receptions(outs, b)[1].start_us == first.done_us + SIFS + CCA + TURNAROUND


def test_mac_queue_limit_refuses_with_a_reason():
    m = medium({"mac": {"min_be": 0, "max_be": 0, "queue_limit": 2}})
    a = place(m, 1, 0)
    m.submit(a, data(1), 1, 0)
    m.submit(a, data(1), 2, 0)
    [refused] = reports(m.submit(a, data(1), 3, 0))
    assert refused.status == TxStatus.REFUSED and "queue full" in refused.reason
