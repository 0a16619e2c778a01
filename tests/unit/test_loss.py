"""Loss statistics under fixed seeds, RSSI/LQI, and reproducibility."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from radio_hub.air.propagation import GilbertElliott, lqi_from_rssi, mean_rssi_dbm, reception_probability
from radio_hub.config import GilbertElliottConfig, MediumConfig, PathLossConfig, RangeConfig

from .helpers import data, medium, place, receptions, run_to_idle

ALOHA_NOACK = {"mac": {"csma_enabled": False, "ack_enabled": False}}
FRAMES = 3000
GAP_US = 5000  # well apart: no frame overlaps another


def _delivered_fraction(settings: dict, seed: int = 7, dist: float = 1.0) -> tuple[float, list[bool]]:
    m = medium({**ALOHA_NOACK, **settings}, seed=seed)
    a, b = place(m, 1, 0), place(m, 2, dist)
    got = []
    for i in range(FRAMES):
        outs = run_to_idle(m, m.submit(a, data(1, seq=i & 0xFF), i, i * GAP_US))
        got.append(bool(receptions(outs, b)))
    return sum(got) / FRAMES, got


def _within_3_sigma(observed: float, p: float) -> bool:
    return abs(observed - p) <= 3 * np.sqrt(p * (1 - p) / FRAMES) + 1e-9


def test_base_loss_rate_matches_its_probability():
    fraction, _ = _delivered_fraction({"loss": {"base": 0.3}})
    assert _within_3_sigma(fraction, 0.7)


def test_reception_ratio_falls_with_distance_to_the_edge_ratio():
    cfg = RangeConfig(tx_range_m=30, success_ratio_rx=0.5)
    assert reception_probability(cfg, 0) == 1.0
    assert reception_probability(cfg, 15) == pytest.approx(0.875)
    assert reception_probability(cfg, 30) == pytest.approx(0.5)
    assert reception_probability(cfg, 30.01) == 0.0
    fraction, _ = _delivered_fraction({"range": {"success_ratio_rx": 0.5}}, dist=30.0)
    assert _within_3_sigma(fraction, 0.5)


def test_gilbert_elliott_loses_in_bursts_at_its_stationary_rate():
    ge = {"p_good_to_bad": 0.02, "p_bad_to_good": 0.2, "loss_good": 0.0, "loss_bad": 1.0}
    fraction, got = _delivered_fraction({"loss": {"gilbert_elliott": ge}}, seed=11)
    expected_loss = GilbertElliott(GilbertElliottConfig(**ge)).mean_loss()
    assert expected_loss == pytest.approx(0.02 / 0.22)
    assert abs((1 - fraction) - expected_loss) < 0.04
    bursts = [len(run) for run in "".join("x" if not g else " " for g in got).split()]
    assert np.mean(bursts) == pytest.approx(1 / 0.2, rel=0.3)  # geometric bursts, mean 1 / p_bad_to_good


def test_independent_loss_has_short_bursts():
    _, got = _delivered_fraction({"loss": {"base": 0.1}}, seed=11)
    bursts = [len(run) for run in "".join("x" if not g else " " for g in got).split()]
    assert np.mean(bursts) < 1.3


def test_rssi_and_lqi_follow_the_path_loss_model():
    cfg = PathLossConfig()
    assert mean_rssi_dbm(cfg, 1.0) == pytest.approx(-40.0)
    assert mean_rssi_dbm(cfg, 10.0) == pytest.approx(-70.0)
    assert lqi_from_rssi(cfg, -95.0) == 0 and lqi_from_rssi(cfg, -20.0) == 255 and lqi_from_rssi(cfg, 0) == 255
    m = medium(ALOHA_NOACK)
    a, b = place(m, 1, 0), place(m, 2, 10)
    [rx] = receptions(run_to_idle(m, m.submit(a, data(1), 1, 0)), b)
    assert rx.rssi_dbm == pytest.approx(-70.0) and rx.lqi == lqi_from_rssi(cfg, -70.0)


def _trace(seed: int) -> list[tuple]:
    m = medium({"loss": {"base": 0.2}, "path_loss": {"shadowing_sigma_db": 2.0}}, seed=seed)
    nodes = [place(m, i, i * 2.0) for i in range(1, 5)]
    outs = []
    for k in range(40):
        outs += m.submit(nodes[k % 4], data(k % 4 + 1, dst=(k + 1) % 4 + 1), k, k * 700)
    return [tuple(vars(o).values()) if hasattr(o, "__dict__") else o for o in run_to_idle(m, outs)]


def test_same_seed_same_outcomes_other_seed_other_outcomes():
    assert _trace(5) == _trace(5)
    assert _trace(5) != _trace(6)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    sends=st.lists(st.tuples(st.integers(1, 4), st.integers(0, 5), st.integers(0, 3000)), min_size=1, max_size=25),
)
def test_counters_add_up_at_every_receiver(seed, sends):
    m = medium({"loss": {"base": 0.1}}, seed=seed)
    nodes = [place(m, i, i * 3.0, pan=0x1000 if i < 4 else 0x2000) for i in range(1, 5)]
    outs, now = [], 0
    for src, dst, gap in sends:
        now += gap
        outs += m.submit(nodes[src - 1], data(src, dst=dst or 0xFFFF), len(outs), now)
    outs = run_to_idle(m, outs)
    for name in nodes:
        c = m.node_counters[name]
        assert c.heard == c.delivered + c.collided + c.lost + c.filtered
        assert c.delivered == len(receptions(outs, name))
    total = m.channel_counters[11]
    assert total.sent == sum(m.node_counters[n].sent for n in nodes)


def test_config_rejects_unknown_keys_and_bad_values():
    with pytest.raises(ValueError, match="unknown key "):
        MediumConfig.from_dict({"mac": {"min_bee": 3}})
    with pytest.raises(ValueError, match="probability"):
        MediumConfig.from_dict({"loss": {"base": 1.5}})
    with pytest.raises(ValueError, match="min_be"):
        MediumConfig.from_dict({"mac": {"min_be": 6, "max_be": 5}})
    with pytest.raises(ValueError, match="true or false"):
        MediumConfig.from_dict({"mac": {"ack_enabled": "yes"}})
    assert MediumConfig.from_dict(MediumConfig().to_dict()) == MediumConfig()
