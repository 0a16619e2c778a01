"""``petswarm bench scale``'s robot counts as the command line gives them."""

from __future__ import annotations

import argparse

import pytest

from cli.main import build_parser
from petswarm.bench.scale import robot_counts


def test_robot_counts_are_sorted_and_unique_and_none_means_no_more() -> None:
    assert robot_counts("50,10,10, 20") == [10, 20, 50]
    assert robot_counts("none") == [] and robot_counts(" None ") == []
    for bad in ("1", "10,5001", "ten", ""):
        with pytest.raises(argparse.ArgumentTypeError):
            robot_counts(bad)


def test_a_small_scale_bench_can_leave_out_the_thousand_robot_run() -> None:
    parser = build_parser()
    assert parser.parse_args(["bench", "scale"]).model_robots == [1000]  # the default, now said in --help
    assert parser.parse_args(["bench", "scale", "--robots", "5", "--model-robots", "none"]).model_robots == []
