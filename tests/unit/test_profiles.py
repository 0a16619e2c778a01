"""Testbed profiles (issue 19): the serial link's timing, the profiles' halves on hub and robot, the IR
emitter noise; ``ideal`` changes nothing."""

import dataclasses

import numpy as np
import pytest

from petswarm.draws import Draws
from petswarm.managers.serial_link import LinkTiming, SerialLink
from petswarm.profiles import PROFILES, robot_profile, wearable_profile
from radio_hub.datasheet import IrConfig
from radio_hub.environment import EnvironmentConfig
from radio_hub.physics.light import sense
from radio_hub.profiles import HUB_PROFILES, apply_profile, check_profile

UART = LinkTiming(uart_bps=10_000.0, frame_overhead_bytes=5)
"""5 + payload bytes of 10 bits at 10 kbit/s: 1 ms per byte."""


def test_a_frame_crosses_the_uart_in_its_bytes_time_and_the_second_waits_for_the_first():
    link = SerialLink(UART, Draws(1))
    assert link.tx_ready(1.0, 15) == pytest.approx(1.020)  # 20 bytes
    assert link.tx_ready(1.0, 5) == pytest.approx(1.030)  # handed over at once, sent after the first
    assert link.tx_ready(2.0, 5) == pytest.approx(2.010)  # the line is free again


def test_a_received_frame_waits_for_the_one_before_it_line_and_processing_in_series():
    timing = dataclasses.replace(UART, mcu_min_s=0.004, mcu_max_s=0.004)
    link = SerialLink(timing, Draws(1))
    assert link.rx_ready(0.0, 5) == pytest.approx(0.014)
    assert link.rx_ready(0.005, 5) == pytest.approx(0.028)  # came while the first was processed
    assert link.rx_ready(0.1, 5) == pytest.approx(0.114)


def test_the_mcus_processing_time_is_drawn_from_the_seed():
    timing = LinkTiming(mcu_min_s=0.001, mcu_max_s=0.005)
    runs = [[SerialLink(timing, Draws(seed)).tx_ready(0.0, 10) for _ in range(1)] for seed in (3, 3, 4)]
    assert runs[0] == runs[1] != runs[2]
    assert all(0.001 <= t <= 0.005 for r in runs for t in r)


def test_the_ideal_profile_changes_nothing_on_either_side():
    assert PROFILES == HUB_PROFILES
    assert apply_profile(EnvironmentConfig(), "ideal").to_dict() == EnvironmentConfig().to_dict()
    assert robot_profile("ideal").link.ideal and robot_profile("ideal").step_deadline_s is None
    assert wearable_profile("ideal").recognition_delay_s == 0
    with pytest.raises(ValueError, match="kim2017"):
        check_profile("kim2016")


def test_kim2017_sets_the_hub_tables_and_the_robots_link():
    config = apply_profile(EnvironmentConfig(), "kim2017")
    assert config.ir.emitter_noise > 0 and config.ir.relative_noise != IrConfig().relative_noise
    assert config.ble.interval_ms != EnvironmentConfig().ble.interval_ms
    assert not robot_profile("kim2017").link.ideal and wearable_profile("kim2017").recognition_delay_s > 0


def test_an_ideal_emitter_draws_nothing_more_and_a_noisy_one_moves_all_twelve_readings_together():
    light = np.tile(np.linspace(10, 100, 12), (4000, 1))
    plain = sense(light, IrConfig(), np.random.default_rng(5))
    assert np.array_equal(
        plain, sense(light, dataclasses.replace(IrConfig(), emitter_noise=0.0), np.random.default_rng(5))
    )
    quiet = dataclasses.replace(IrConfig(), relative_noise=0.0, noise_floor_counts=0.0, emitter_noise=0.1)
    ratios = (sense(light, quiet, np.random.default_rng(5)) - quiet.ambient_counts) / light
    assert np.allclose(ratios, ratios[:, :1])  # one factor per sweep
    assert ratios[:, 0].std() == pytest.approx(0.1, rel=0.05)
