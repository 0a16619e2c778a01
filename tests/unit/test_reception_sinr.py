"""The ``sinr`` reception model: Annex E's bit error rate, the noise floor from the sensitivity, synchronisation,
capture and summed interference, each held against what the formulas say."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from radio_hub.air.error_model import (
    BITS_PER_US,
    bit_error_rate,
    clean_sinr,
    dbm_to_mw,
    noise_floor_dbm,
    piece_success,
)
from radio_hub.air.medium import Medium, RxOutcome
from radio_hub.air.propagation import mean_rssi_dbm
from radio_hub.config import MediumConfig, PathLossConfig, airtime_us

from .helpers import data, medium, place, receptions, run_to_idle

ALOHA = {"mac": {"csma_enabled": False}}
PL = PathLossConfig(shadowing_sigma_db=0.0)


def _mw(dist_m: float) -> float:
    return dbm_to_mw(mean_rssi_dbm(PL, dist_m))


def test_ber_is_half_without_signal_and_falls_monotonically() -> None:
    # the alternating binomial sum is 15 at SINR 0, so BER = (8/15)(1/16) 15 = 1/2
    assert bit_error_rate(0.0) == pytest.approx(0.5)
    values = [bit_error_rate(10 ** (db / 10)) for db in np.arange(-10, 8, 0.25)]
    assert all(a >= b for a, b in itertools.pairwise(values))
    # Annex E, Figure E.2: about 1e-4 near 0 dB and below 1e-8 by 3 dB
    assert 1e-4 < bit_error_rate(1.0) < 1e-3 and bit_error_rate(10**0.3) < 1e-8
    assert 1.0 - bit_error_rate(clean_sinr()) == 1.0 and 1.0 - bit_error_rate(clean_sinr() * 0.99) < 1.0


def test_noise_floor_makes_the_sensitivity_a_one_percent_per_for_20_octets() -> None:
    noise = noise_floor_dbm(-95.0)
    snr = dbm_to_mw(-95.0) / dbm_to_mw(noise)
    assert 1.0 - piece_success(snr, (20 + 6) * 8) == pytest.approx(0.01, rel=1e-6)
    assert -96.0 < noise < -95.0


def test_at_the_sensitivity_a_20_octet_frame_is_lost_one_time_in_a_hundred() -> None:
    """Noise alone: a receiver whose mean RSSI is exactly the sensitivity (-95 dBm: 68.1 m at 40 dB + 30 log d)
    loses 1 % of 20-octet PSDUs, as LOST (no interferer), within four binomial standard deviations."""
    d = 10 ** ((95.0 - 40.0) / 30.0)
    m = Medium(
        MediumConfig.from_dict(
            {
                "range": {"tx_range_m": 100.0, "interference_range_m": 100.0, "success_ratio_rx": 1.0},
                "path_loss": {"shadowing_sigma_db": 0.0},
                "mac": {"csma_enabled": False},
            }
        ),
        np.random.default_rng(3),
        log_size=10,
    )
    a, b = place(m, 1, 0), place(m, 2, d)
    psdu = data(1, payload=bytes(9))
    assert len(psdu) == 20
    n = 4000
    outs = []
    for i in range(n):
        outs += run_to_idle(m, m.submit(a, psdu, i, i * 2000))
    got = len(receptions(outs, b))
    assert abs((n - got) - n * 0.01) < 4 * math.sqrt(n * 0.01 * 0.99)
    assert m.node_counters[b].lost == n - got and m.node_counters[b].collided == 0


def test_a_later_frame_no_stronger_than_the_first_is_not_received() -> None:
    # c is 1 m from both: b's frame starts while c is synchronised to a's equally strong one
    m = medium(ALOHA)
    a, b, c = place(m, 1, 0), place(m, 2, 2), place(m, 3, 1)
    m.submit(a, data(1, payload=bytes(30)), 1, 0)
    outs = run_to_idle(m, m.submit(b, data(2, payload=bytes(30)), 2, 100))
    assert all(r.sender == a for r in receptions(outs, c))
    assert next(tx for tx in m.air_log if tx.sender == b).outcomes[c] == RxOutcome.COLLIDED


def test_a_stronger_later_frame_captures_the_receiver() -> None:
    # c is 1 m from b, 20 m from a: b starts 50 us into a's frame and takes the receiver
    m = medium(ALOHA)
    a, b, c = place(m, 1, 0), place(m, 2, 21), place(m, 3, 20)
    m.submit(a, data(1), 1, 0)
    outs = run_to_idle(m, m.submit(b, data(2), 2, 50))
    assert [r.sender for r in receptions(outs, c)] == [b]
    assert next(tx for tx in m.air_log if tx.sender == a).outcomes[c] == RxOutcome.COLLIDED


def test_survival_under_equal_interference_follows_the_piecewise_error_rate() -> None:
    """a's 41-octet frame at c (1 m) with b's equally strong frame over part of it: per seed, one draw against
    the product over the overlap and the clean part. The rate over 600 seeds matches within 4 sigma."""
    psdu = data(1, payload=bytes(30))
    overlap_us = airtime_us(len(psdu)) - 300
    noise = dbm_to_mw(noise_floor_dbm(PL.sensitivity_dbm))
    expected = piece_success(_mw(1) / (noise + _mw(1)), overlap_us * BITS_PER_US)
    n, got = 600, 0
    for seed in range(n):
        m = medium(ALOHA, seed=seed)
        a, b, c = place(m, 1, 0), place(m, 2, 2), place(m, 3, 1)
        m.submit(a, psdu, 1, 0)
        outs = run_to_idle(m, m.submit(b, data(2, payload=bytes(30)), 2, 300))
        got += any(r.sender == a for r in receptions(outs, c))
    assert 0.5 < expected < 0.99
    assert abs(got - n * expected) < 4 * math.sqrt(n * expected * (1 - expected))


def test_interference_adds_up() -> None:
    """Two later, weaker frames spoil a's frame at c as their summed power says, not as the stronger one alone:
    each alone leaves a SINR of 3 dB, the two together 0 dB. Survival rates over 300 seeds match the piecewise
    error rate of each case within 4 sigma."""
    noise = dbm_to_mw(noise_floor_dbm(PL.sensitivity_dbm))
    signal = _mw(10.0)
    one = signal / 10**0.3 - noise
    d_far = 10 ** ((PL.tx_power_dbm - PL.loss_at_1m_db - 10 * math.log10(one)) / (10 * PL.exponent))
    psdu = data(1, payload=bytes(100))
    start = 40  # the interferers start 40 us into a's frame and outlast it
    bits = (airtime_us(len(psdu)) - start) * BITS_PER_US

    def survival(interferers: int, n: int = 300) -> tuple[int, float]:
        got = 0
        for seed in range(n):
            m = medium(ALOHA, seed=seed)
            a, c = place(m, 1, 0), place(m, 3, 10)
            others = [place(m, 4 + i, 10, d_far if i == 0 else -d_far) for i in range(interferers)]
            outs = m.submit(a, psdu, 1, 0)
            for i, node in enumerate(others):
                outs += m.submit(node, data(4 + i, payload=bytes(100)), 2 + i, start)
            got += any(r.sender == a for r in receptions(run_to_idle(m, outs), c))
        expected = piece_success(signal / (noise + interferers * _mw(d_far)), bits)
        return got, expected

    for interferers in (1, 2):
        got, p = survival(interferers)
        assert abs(got - 300 * p) <= 4 * math.sqrt(300 * p * (1 - p)) + 1e-9, (interferers, got, p)
    assert survival(1)[1] > 0.99 and survival(2)[1] < 0.95
