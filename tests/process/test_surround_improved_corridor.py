"""The improved surround law past the corridor as 20 robot processes and the human's in lockstep, seeds 1-5: issue
17's four bounds and the model-time twin's digest (tests/process/surround_improved_runs.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.process.surround_improved_runs import SEEDS, TIMEOUT_S, check_improved_surround_run

pytestmark = [pytest.mark.process, pytest.mark.long]


@pytest.mark.timeout(TIMEOUT_S)
@pytest.mark.parametrize("seed", SEEDS)
def test_improved_surround_robot_processes_keep_their_human_inside_through_the_corridor(
    seed: int, tmp_path: Path
) -> None:
    """Seed ``seed`` of scenarios/surround-corridor-improved.toml as processes: see ``check_improved_surround_run``."""
    check_improved_surround_run("corridor", seed, tmp_path)
