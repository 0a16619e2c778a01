"""Where run records go: ``--record``, else ``$PETSWARM_RUNS``, else ``./runs``; the suite keeps them in tmp."""

from __future__ import annotations

import json
import os
import platform
from pathlib import Path

import pytest

from petswarm.lab.records import RunRecord, runs_dir
from petswarm.lab.run import RunOptions
from radio_hub.determinism import X86_ABOVE_BASELINE

ROOT = Path(__file__).resolve().parents[2]


def test_a_record_goes_under_petswarm_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PETSWARM_RUNS", str(tmp_path / "elsewhere"))
    record = RunRecord.create(RunOptions(robots=1, seed=7, duration=1.0, ping_interval=0.5), "w", "tcp/x:1")
    assert record.path.parent == tmp_path / "elsewhere" and record.path.name.endswith("-7")
    assert (record.path / "manifest.json").exists()
    monkeypatch.delenv("PETSWARM_RUNS")
    assert runs_dir() == Path("runs")


def test_the_suite_keeps_run_records_out_of_the_working_tree() -> None:
    runs = Path(os.environ["PETSWARM_RUNS"]).resolve()  # tests/conftest.py sets it for the whole session
    assert not runs.is_relative_to(ROOT.resolve()) and not runs.is_relative_to(Path.cwd().resolve())


def test_two_runs_with_one_seed_in_the_same_second_get_two_records(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("PETSWARM_RUNS", str(tmp_path))
    monkeypatch.setattr("petswarm.lab.records.time.strftime", lambda *_: "20261122T190000Z")  # one second
    opts = RunOptions(robots=1, seed=7, duration=1.0, ping_interval=0.5)
    first, second = (RunRecord.create(opts, "w", "tcp/x:1") for _ in range(2))
    assert first.path.name == "20261122T190000Z-7" and second.path.name == "20261122T190000Z-7-2"


def test_a_named_record_keeps_files_it_does_not_own(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    opts = RunOptions(robots=1, seed=7, duration=1.0, ping_interval=0.5, record_dir=str(tmp_path))
    RunRecord.create(opts, "w", "tcp/x:1")
    (tmp_path / "notes.txt").write_text("mine")
    (tmp_path / "summary.json").write_text("{}")
    RunRecord.create(opts, "w", "tcp/x:1")
    assert (tmp_path / "notes.txt").read_text() == "mine" and not (tmp_path / "summary.json").exists()
    assert "held an earlier run" in capsys.readouterr().err


def test_the_manifest_says_which_numeric_paths_the_digest_was_made_on(tmp_path: Path) -> None:
    opts = RunOptions(robots=1, seed=7, duration=1.0, ping_interval=0.5, record_dir=str(tmp_path / "r"))
    record = RunRecord.create(opts, "w", "tcp/x:1")
    numeric = json.loads((record.path / "manifest.json").read_text())["numeric"]
    assert numeric["machine"] == platform.machine()
    if platform.machine().lower() in ("x86_64", "amd64"):
        assert numeric["numpy_disabled"] == X86_ABOVE_BASELINE  # the pin every process of the run inherits
        import numpy  # noqa: F401  (this process's own paths are said only where numpy is loaded)

        again = RunRecord.create(opts, "w", "tcp/x:1")
        assert json.loads((again.path / "manifest.json").read_text())["numeric"]["numpy_dispatch"] == []
