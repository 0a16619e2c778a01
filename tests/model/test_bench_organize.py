"""``petswarm bench organize`` in model time (the default clock): the same figures for the same seed, and no
organization short of its count while enough robots wait, even with the MAC's acknowledgements off."""

from __future__ import annotations

from pathlib import Path

from petswarm.bench.organize import OrganizeOptions, write_no_ack_config
from petswarm.bench.organize_model import measure_count
from petswarm.bench.organize_report import ended_short


def _args(**changes: object) -> OrganizeOptions:
    args = dict(seed=3, runs=4, protocol="paper", step_deadline=None, step_retries=None, profile="ideal")
    return OrganizeOptions(**{**args, **changes})  # type: ignore[arg-type]


def test_the_model_time_bench_repeats_per_seed_and_ends_no_organization_short(tmp_path: Path) -> None:
    config = write_no_ack_config(tmp_path)
    first, again = (measure_count(4, _args(), config)["records"] for _ in range(2))
    assert first == again
    assert all(r["ok"] and r["waiting_before"] == 4 for r in first)
    assert ended_short(first) == [] and all(len(r["members"]) == 4 for r in first)


def test_the_kim2017_profile_reaches_the_robots_and_the_hub(tmp_path: Path) -> None:
    [record] = measure_count(1, _args(runs=1, profile="kim2017"), None)["records"]
    assert record["ok"] and record["members"] == [2]
    assert 0.53 < record["organize_time_s"] < 1.0  # the profile's step deadline and serial link
