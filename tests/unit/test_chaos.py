"""Faults injected into the medium: loss, corruption, duplication, partitions, and their clearing."""

import pytest

from radio_hub.air.chaos import parse_fault
from radio_hub.air.medium import TxStatus

from .helpers import NO_BACKOFF, data, medium, place, receptions, reports, run_to_idle


def _three():
    m = medium(NO_BACKOFF)
    return m, place(m, 1, 0), place(m, 2, 1), place(m, 3, 2)


def test_link_loss_takes_only_that_link_and_clearing_restores_it():
    m, a, b, c = _three()
    m.chaos.add({"kind": "loss", "link": [a, b]}, 0, 0.0)
    outs = run_to_idle(m, m.submit(a, data(1), 1, 0))
    assert receptions(outs, b) == [] and len(receptions(outs, c)) == 1
    assert m.node_counters[b].chaos_lost == 1 and m.node_counters[b].lost == 1
    m.chaos.clear(None, 10_000, 0.0)
    assert len(receptions(run_to_idle(m, m.submit(a, data(1), 2, 10_000)), b)) == 1


def test_corruption_is_dropped_by_the_mac_and_an_acked_send_gets_no_ack():
    m, a, b, _ = _three()
    m.chaos.add({"kind": "corrupt", "node": b}, 0, 0.0)
    [report] = reports(run_to_idle(m, m.submit(a, data(1, dst=2), 1, 0)))
    assert report.status == TxStatus.NO_ACK and m.node_counters[b].corrupted == 4


def test_duplication_hands_a_frame_up_twice_without_breaking_the_counters():
    m, a, b, _ = _three()
    m.chaos.add({"kind": "duplicate", "pan": 0x1000}, 0, 0.0)
    assert len(receptions(run_to_idle(m, m.submit(a, data(1), 1, 0)), b)) == 2
    counters = m.node_counters[b]
    assert counters.duplicated == 1 and counters.delivered == 1 and counters.heard == 1


def test_a_frame_two_duplication_faults_select_is_duplicated_and_counted_once():
    m, a, b, _ = _three()
    m.chaos.add({"kind": "duplicate", "pan": 0x1000}, 0, 0.0)
    m.chaos.add({"kind": "duplicate", "node": b}, 0, 0.0)
    assert len(receptions(run_to_idle(m, m.submit(a, data(1), 1, 0)), b)) == 2
    counters = m.node_counters[b]
    assert counters.duplicated == 1 and counters.delivered == 1
    assert m.channel_counters[11].duplicated == 2  # b's one and c's one (c is selected by the PAN fault)


def test_a_partition_blocks_reception_interference_and_carrier_sense():
    m, a, b, c = _three()
    m.chaos.add({"kind": "partition", "group": [a]}, 0, 0.0)
    outs = run_to_idle(m, m.submit(a, data(1), 1, 0))
    assert receptions(outs) == []
    # b and c are on the other side: a's long frame does not stop b from sending to c at once
    m.submit(a, data(1, payload=bytes(100)), 2, 10_000)
    outs = run_to_idle(m, m.submit(b, data(2, dst=3), 3, 10_100))
    assert [r.status for r in reports(outs) if r.node_id == b] == [TxStatus.SUCCESS]
    assert m.node_counters[c].collided == 0


@pytest.mark.parametrize(
    "spec, reason",
    [
        ({"kind": "flood"}, "kind must be"),
        ({"kind": "loss", "p": 2}, "probability"),
        ({"kind": "loss", "group": ["a"]}, "unknown key .group."),
        ({"kind": "partition"}, "needs a group"),
        ({"kind": "loss", "link": ["a"]}, "pair"),
    ],
)
def test_bad_fault_specs_are_refused_with_a_reason(spec, reason):
    with pytest.raises(ValueError, match=reason):
        parse_fault(1, spec)


def test_ir_blinding_and_noise_reach_only_the_chosen_receiver():
    import numpy as np

    from radio_hub.air.chaos import Chaos
    from radio_hub.physics.ir_air import IrAir
    from radio_hub.physics.light import IrConfig

    config = IrConfig().noise_free()
    air = IrAir(config, np.random.default_rng(1))
    poses = {"tx": (0.0, 0.0, 0.0), "a": (1.0, 0.0, 0.0), "b": (0.0, 1.0, 0.0)}
    air.set_mode("tx", "transmit", 0)
    air.set_mode("a", "receive", 0)
    air.set_mode("b", "receive", 0)
    chaos = Chaos()
    clean = air.sweep(air.next_event_us(), poses, chaos)
    chaos.add({"kind": "ir_blind", "node": "a"}, 0, 0.0)
    blinded = air.sweep(air.next_event_us(), poses, chaos)
    assert np.all(blinded["a"] == config.saturation_counts)
    np.testing.assert_allclose(blinded["b"], clean["b"])  # noise free: b sees exactly what it saw
    chaos.clear(None, 0, 0.0)
    chaos.add({"kind": "ir_noise", "sigma": 25.0}, 0, 0.0)
    noisy = air.sweep(air.next_event_us(), poses, chaos)
    assert np.std(noisy["b"] - clean["b"]) > 5.0 and not np.allclose(noisy["a"], clean["a"])
