"""A radio is half duplex: while it sends (its ACK or a data frame) it starts nothing else and receives nothing.

Constants as in test_csma_timeline: CCA 128 us, turnaround 192 us, an ACK is 352 us on air, and the SIFS
(192 us) a radio keeps after its ACK before it senses or sends again (IEEE 802.15.4-2011 5.1.1.3).
"""

from itertools import pairwise

from hypothesis import given, settings
from hypothesis import strategies as st

from radio_hub.air.medium import Medium, RxOutcome, TxStatus
from radio_hub.config import airtime_us

from .helpers import NO_BACKOFF, data, medium, place, receptions, reports, run_to_idle

CCA, TURNAROUND, ACK_AIR, SIFS = 128, 192, 352, 192


def _on_air(m: Medium, sender: str) -> list[tuple[int, int, str]]:
    return sorted((tx.start_us, tx.end_us, tx.frame.frame_type.name) for tx in m.air_log if tx.sender == sender)


def _no_overlap(spans: list[tuple[int, int, str]]) -> bool:
    return all(prev[1] <= nxt[0] for prev, nxt in pairwise(spans))


def test_a_radio_sending_an_ack_defers_its_own_data_until_the_ack_has_left():
    m = medium(NO_BACKOFF)
    a, b = place(m, 1, 0), place(m, 2, 1)
    unicast = data(1, dst=2, payload=bytes(16))
    m.submit(a, unicast, 1, 0)
    data_end = CCA + TURNAROUND + airtime_us(len(unicast))
    ack_end = data_end + TURNAROUND + ACK_AIR
    # b's CCA would fall in the turnaround before its ACK: its radio is already committed to sending the ACK,
    # and to the SIFS after it
    reply = data(2, payload=bytes(30))
    outs = run_to_idle(m, m.submit(b, reply, 2, data_end + 10))
    reply_start = ack_end + SIFS + CCA + TURNAROUND
    assert _on_air(m, b) == [
        (data_end + TURNAROUND, ack_end, "ACK"),
        (reply_start, reply_start + airtime_us(len(reply)), "DATA"),
    ]
    by_token = {r.token: r for r in reports(outs)}
    assert by_token[1].status == TxStatus.SUCCESS and by_token[1].done_us == ack_end
    # the deferral is the radio's, not a busy channel: no backoff is counted
    assert by_token[2].status == TxStatus.SUCCESS and by_token[2].backoffs == 0
    assert [r.sender for r in receptions(outs, a)] == [b]


def test_without_csma_a_radio_sending_an_ack_still_sends_its_data_after_it():
    m = medium({**NO_BACKOFF, "mac": {"csma_enabled": False}})
    a, b = place(m, 1, 0), place(m, 2, 1)
    unicast = data(1, dst=2, payload=bytes(16))
    m.submit(a, unicast, 1, 0)
    data_end = TURNAROUND + airtime_us(len(unicast))
    ack_end = data_end + TURNAROUND + ACK_AIR
    # b's data would start 10 us into its own ACK: it goes once the ACK and its SIFS are over
    outs = run_to_idle(m, m.submit(b, data(2), 2, data_end + 10))
    assert [span[0] for span in _on_air(m, b)] == [data_end + TURNAROUND, ack_end + SIFS + TURNAROUND]
    assert all(r.status == TxStatus.SUCCESS for r in reports(outs))


def test_a_radio_receives_nothing_that_overlaps_its_own_ack():
    m = medium({**NO_BACKOFF, "mac": {"csma_enabled": False}})
    # c is out of a's interference range (50 m), so only b's own ACK can spoil c's frame at b
    a, b, c = place(m, 1, 0), place(m, 2, 30), place(m, 3, 60)
    unicast = data(1, dst=2, payload=bytes(16))
    m.submit(a, unicast, 1, 0)
    data_end = TURNAROUND + airtime_us(len(unicast))
    # c's broadcast starts while b is sending its ACK to a
    outs = run_to_idle(m, m.submit(c, data(3), 2, data_end + 100))
    frame_from_c = next(tx for tx in m.air_log if tx.sender == c)
    assert frame_from_c.outcomes[b] == RxOutcome.COLLIDED
    assert [r.sender for r in receptions(outs, b)] == [a]


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    csma=st.booleans(),
    sends=st.lists(st.tuples(st.integers(1, 3), st.integers(0, 3), st.integers(0, 1500)), min_size=2, max_size=20),
)
def test_no_radio_ever_has_two_transmissions_on_the_air_at_once(seed, csma, sends):
    m = medium({"mac": {"csma_enabled": csma, "min_be": 0, "max_be": 2}}, seed=seed)
    nodes = [place(m, i, float(i)) for i in range(1, 4)]
    outs, now = [], 0
    for src, dst, gap in sends:
        now += gap
        outs += m.submit(nodes[src - 1], data(src, dst=dst or 0xFFFF, payload=bytes(10)), len(outs), now)
    run_to_idle(m, outs)
    for name in nodes:
        assert _no_overlap(_on_air(m, name)), _on_air(m, name)
