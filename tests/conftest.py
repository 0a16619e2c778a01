"""Every test keeps its run records out of the working tree: ``./runs`` is for people's runs.

The session also compiles the project's sources to bytecode once, before any test starts a process (see
``pytest_sessionstart``), and runs the files marked ``long`` first (see ``pytest_collection_modifyitems``).

``petswarm run`` and ``petswarm experiment`` write to ``$PETSWARM_RUNS`` (default ``./runs``) unless given
``--record`` / ``--out``; the whole session points it into pytest's temporary directory, and the child
processes the tests start inherit it. Each test then checks that it left nothing new in ``./runs``.
"""

from __future__ import annotations

import compileall
import os
from collections.abc import Iterator
from pathlib import Path

import pytest

import radio_hub.determinism  # noqa: F401  (before any test module loads numpy: the digests every process computes)

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("petswarm", "radio_hub", "cli")


def pytest_sessionstart(session: pytest.Session) -> None:
    """Write the sources' bytecode before the tests start hundreds of hub, robot and user processes.

    Where PYTHONDONTWRITEBYTECODE is set (as on the CI machines), no process writes a ``.pyc``, so every child
    would compile every module it imports from source again: a third of a robot process's start (0.55 -> 0.37
    CPU-s measured). Processes still read bytecode that exists; ``compileall`` writes it whatever the setting.
    Only the controlling process does it (an xdist worker has ``workerinput``), before the workers start."""
    if hasattr(session.config, "workerinput"):
        return
    for package in SOURCES:
        compileall.compile_dir(ROOT / package, quiet=1)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The tests marked ``long`` first, in their collection order, then the rest in theirs.

    xdist hands whole files to its workers in the order they were collected; a file of a minute or more (a
    20-robot lockstep run, the compose stack, a run of wall-clock process tests) that came after the short
    ones started last and ran on alone at the end, a minute of one busy core while the other idled. Longest
    first is the classic fix for the makespan of jobs on parallel machines."""
    items.sort(key=lambda item: item.get_closest_marker("long") is None)


@pytest.fixture(scope="session", autouse=True)
def run_records_in_tmp(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """``PETSWARM_RUNS`` in pytest's temporary directory for the whole session."""
    runs = tmp_path_factory.mktemp("runs")
    before = os.environ.get("PETSWARM_RUNS")
    os.environ["PETSWARM_RUNS"] = str(runs)
    yield runs
    if before is None:
        os.environ.pop("PETSWARM_RUNS", None)
    else:
        os.environ["PETSWARM_RUNS"] = before


def _listing(folders: set[Path]) -> set[Path]:
    return {entry for folder in folders if folder.is_dir() for entry in folder.iterdir()}


@pytest.fixture(autouse=True)
def no_records_in_the_working_tree() -> Iterator[None]:
    """Fail the test that leaves a new entry in ``./runs`` (of the repository or of the current directory)."""
    folders = {ROOT / "runs", Path.cwd() / "runs"}
    before = _listing(folders)
    yield
    new = sorted(str(p) for p in _listing(folders) - before)
    assert not new, f"this test left run records in the working tree: {new} (pass --record/--out under tmp_path)"
