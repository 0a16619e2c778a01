"""Chaos delay and burst faults in the medium: timing, statistics, counters and seeded reproducibility."""

from __future__ import annotations

import numpy as np
import pytest

from radio_hub.air.chaos import parse_fault
from radio_hub.air.medium import Medium, Output, Reception, TxStatus

from .helpers import NO_BACKOFF, data, medium, place, receptions, reports, run_to_idle

GAP_US = 5_000  # between two frames of a series: longer than a frame and its ACK exchange


def _three(seed: int = 0) -> tuple[Medium, str, str, str]:
    m = medium(NO_BACKOFF, seed)
    return m, place(m, 1, 0), place(m, 2, 1), place(m, 3, 2)


def _series(m: Medium, sender: str, count: int) -> list[Output]:
    """``count`` broadcasts from ``sender``, GAP_US apart, each carrying its index; every output."""
    outs: list[Output] = []
    short, start = m.nodes[sender].short_addr, m.now_us
    for i in range(count):
        t = start + i * GAP_US
        outs += m.advance(t)
        outs += m.submit(sender, data(short, payload=i.to_bytes(2, "big"), seq=i % 256), i, t)
    return run_to_idle(m, outs)


def _index(rx: Reception) -> int:
    return int.from_bytes(rx.frame.payload, "big")


def _balanced(m: Medium) -> None:
    for node_id, c in m.node_counters.items():
        assert c.heard == c.delivered + c.collided + c.lost + c.filtered, node_id


def test_a_delayed_frame_is_handed_up_later_and_only_at_the_selected_receiver():
    m, a, b, c = _three()
    m.chaos.add({"kind": "delay", "ms": 5, "link": [a, b]}, 0, 0.0)
    outs = m.submit(a, data(1), 1, 0)
    while not receptions(outs):
        outs += m.advance(m.next_event_us())
    [at_c] = receptions(outs)
    air_end = at_c.end_us
    assert (at_c.node_id, at_c.handed_up_us) == (c, air_end)  # b's copy is not due yet
    assert m.node_counters[b].delivered == 1  # counted when it left the air
    assert m.next_event_us() == air_end + 5_000
    [late] = receptions(m.advance(air_end + 5_000))
    assert (late.node_id, late.end_us, late.handed_up_us) == (b, air_end, air_end + 5_000)
    _balanced(m)


def test_the_ack_and_the_senders_result_keep_the_airs_timing():
    outcomes = []
    for delayed in (False, True):
        m, a, b, _ = _three(seed=4)
        if delayed:
            m.chaos.add({"kind": "delay", "ms": 20, "node": b}, 0, 0.0)
        outs = run_to_idle(m, m.submit(a, data(1, dst=2), 1, 0))
        [report] = reports(outs)
        [rx] = receptions(outs, b)
        outcomes.append((report.status, report.done_us, rx.end_us, rx.handed_up_us - rx.end_us))
    assert outcomes[0][:3] == outcomes[1][:3] and outcomes[0][0] == TxStatus.SUCCESS
    assert (outcomes[0][3], outcomes[1][3]) == (0, 20_000)


@pytest.mark.parametrize("jitter, std_factor", [("uniform", 1 / np.sqrt(3)), ("gaussian", 1.0)])
def test_jitter_spreads_the_delay_around_its_mean_and_reorders_frames(jitter, std_factor):
    m, a, b, _ = _three(seed=2)
    m.chaos.add({"kind": "delay", "ms": 10, "jitter_ms": 4, "jitter": jitter, "node": b}, 0, 0.0)
    at_b = receptions(_series(m, a, 600), b)
    extra_ms = np.array([r.handed_up_us - r.end_us for r in at_b]) / 1000
    assert len(at_b) == 600
    assert extra_ms.mean() == pytest.approx(10.0, abs=0.3)
    assert extra_ms.std() == pytest.approx(4 * std_factor, rel=0.1)
    if jitter == "uniform":
        assert extra_ms.min() >= 6.0 and extra_ms.max() <= 14.0
    # frames 5 ms apart with +-4 ms of jitter overtake each other: out of air order at the receiver
    sent_order = [_index(r) for r in at_b]
    assert sent_order != sorted(sent_order)
    assert [r.handed_up_us for r in at_b] == sorted(r.handed_up_us for r in at_b)  # handed up in time order
    _balanced(m)


def test_delays_of_two_faults_add_up_and_a_negative_draw_is_clipped():
    m, a, b, _ = _three(seed=3)
    m.chaos.add({"kind": "delay", "ms": 2, "node": b}, 0, 0.0)
    m.chaos.add({"kind": "delay", "ms": 3, "link": [a, b]}, 0, 0.0)
    [rx] = receptions(run_to_idle(m, m.submit(a, data(1), 1, 0)), b)
    assert rx.handed_up_us - rx.end_us == 5_000
    m.chaos.clear(None, 0, 0.0)
    m.chaos.add({"kind": "delay", "ms": 0, "jitter_ms": 5, "jitter": "gaussian", "node": b}, 0, 0.0)
    extra = [r.handed_up_us - r.end_us for r in receptions(_series(m, a, 200), b)]
    assert min(extra) == 0 and 0.3 < np.mean([e == 0 for e in extra]) < 0.7  # about half the draws clip


def test_a_node_that_leaves_during_the_delay_gets_nothing_and_counters_still_add_up():
    m, a, b, _ = _three()
    m.chaos.add({"kind": "delay", "ms": 50, "node": b}, 0, 0.0)
    loss = m.chaos.add({"kind": "loss", "p": 0.3, "node": b}, 0, 0.0)
    outs = _series(m, a, 40)
    at_b = receptions(outs, b)
    assert len(at_b) == m.node_counters[b].delivered and m.node_counters[b].chaos_lost > 0
    _balanced(m)
    m.chaos.clear(loss.fault_id, 300_000, 0.0)
    delivered = m.node_counters[b].delivered
    m.submit(a, data(1), 99, 300_000)
    m.advance(310_000)  # the frame has left the air; b's hand-up is 50 ms away
    assert m.node_counters[b].delivered == delivered + 1
    m.detach(b)
    m.attach(type(m.nodes[a])(b, 0xAB02, 2, 0x1000, 11, (1.0, 0.0)))  # b re-attaches as a new radio
    assert receptions(run_to_idle(m), b) == []


def _delays(seed: int) -> list[int]:
    m, a, b, _ = _three(seed)
    m.chaos.add({"kind": "delay", "ms": 3, "jitter_ms": 2, "node": b}, 0, 0.0)
    return [r.handed_up_us for r in receptions(_series(m, a, 50), b)]


def test_delay_draws_are_seeded():
    assert _delays(9) == _delays(9)
    assert _delays(9) != _delays(10)


def _burst_losses(seed: int, count: int, **params: float) -> tuple[list[bool], Medium]:
    m, a, b, c = _three(seed)
    m.chaos.add({"kind": "burst", "link": [a, b], **params}, 0, 0.0)
    outs = _series(m, a, count)
    got = {_index(r) for r in receptions(outs, b)}
    assert len(receptions(outs, c)) == count  # the link selector spares the others
    return [i not in got for i in range(count)], m


def _runs(lost: list[bool]) -> list[int]:
    runs, length = [], 0
    for x in [*lost, False]:
        if x:
            length += 1
        elif length:
            runs.append(length)
            length = 0
    return runs


def test_burst_losses_come_in_runs_with_the_chains_statistics():
    lost, m = _burst_losses(5, 3000, p_gb=0.1, p_bg=0.25)
    rate = np.mean(lost)
    assert rate == pytest.approx(0.1 / 0.35, abs=0.04)  # stationary share of the bad state
    runs = _runs(lost)
    assert np.mean(runs) == pytest.approx(1 / 0.25, rel=0.2)  # a bad spell lasts 1/p_bg frames
    assert np.mean(runs) > 2 * (1 / (1 - rate))  # independent loss at that rate gives runs of ~1.4
    b = m.node_counters["n2"]
    assert b.chaos_lost == b.lost == sum(lost)
    _balanced(m)


def test_burst_is_seeded():
    assert _burst_losses(3, 200)[0] == _burst_losses(3, 200)[0]
    assert _burst_losses(3, 200)[0] != _burst_losses(4, 200)[0]


def test_each_link_has_its_own_chain_and_clearing_ends_the_bursts():
    # p_gb = p_bg = 1: every chain flips at each reception, so its first frame is lost, the next one not
    m, a, b, c = _three()
    m.chaos.add({"kind": "burst", "node": b, "p_gb": 1, "p_bg": 1}, 0, 0.0)
    outs = run_to_idle(m, m.submit(a, data(1), 1, 0))
    outs += run_to_idle(m, m.submit(c, data(3), 2, 10_000))  # c -> b starts good too, so it is lost
    assert receptions(outs, b) == []
    outs = run_to_idle(m, m.submit(a, data(1), 3, 20_000))  # a -> b is bad now, flips back to good
    assert len(receptions(outs, b)) == 1
    m.chaos.clear(None, 30_000, 0.0)
    assert len(receptions(run_to_idle(m, m.submit(c, data(3), 4, 30_000)), b)) == 1
    assert m.chaos._chains == {}


def test_burst_and_delay_are_logged_with_their_parameters():
    m = _three()[0]
    m.chaos.add({"kind": "delay", "ms": 7.5, "jitter_ms": 1, "jitter": "gaussian", "pan": 0x1000}, 100, 1.5)
    m.chaos.add({"kind": "burst", "channel": 11, "p_gb": 0.02}, 200, 2.5)
    first, second = m.chaos.log
    assert first["model_us"] == 100 and (first["ms"], first["jitter_ms"], first["jitter"]) == (7.5, 1.0, "gaussian")
    assert second["wall"] == 2.5 and (second["p_gb"], second["p_bg"], second["loss_bad"]) == (0.02, 0.25, 1.0)


@pytest.mark.parametrize(
    "spec, reason",
    [
        ({"kind": "delay"}, "needs ms"),
        ({"kind": "delay", "ms": -1}, "ms must be in"),
        ({"kind": "delay", "ms": 20_000}, "ms must be in"),
        ({"kind": "delay", "ms": "soon"}, "ms must be a number"),
        ({"kind": "delay", "ms": 1, "jitter_ms": float("nan")}, "jitter_ms must be in"),
        ({"kind": "delay", "ms": 1, "jitter": "pink"}, "jitter must be one of"),
        ({"kind": "delay", "ms": 0}, "delays nothing"),
        ({"kind": "delay", "ms": 1, "p": 0.5}, "unknown key .p."),
        ({"kind": "burst", "p_gb": 1.5}, "p_gb must be a probability"),
        ({"kind": "burst", "p_bg": 0}, "first burst never ends"),
        ({"kind": "burst", "p_gb": 0}, "never loses"),
        ({"kind": "burst", "loss_bad": 0}, "never loses"),
        ({"kind": "burst", "sigma": 1}, "unknown key .sigma."),
    ],
)
def test_absurd_delay_and_burst_specs_are_refused_with_a_reason(spec, reason):
    with pytest.raises(ValueError, match=reason):
        parse_fault(1, spec)
