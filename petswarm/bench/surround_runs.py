"""Runs of a surround scenario for the benches: under a chosen law, on model or lockstep time, their world states
and what their summaries say. Apart from ``bench surround`` so that its plots (the snapshots) use them without an
import cycle."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

from petswarm.lab.metrics import read_world

if TYPE_CHECKING:
    from petswarm.lab.run import RunOptions
    from petswarm.scenario import Scenario

INTERRUPTED = 130
CLOCKS = ("model", "lockstep")
"""The clocks a bench run can take: both repeat exactly from a seed (wall-clock runs do not)."""


def with_law(scenario: Scenario, law: str) -> Scenario:
    """``scenario`` with its robots running ``law`` (its other ``[surround]`` settings kept)."""
    return dataclasses.replace(scenario, surround={**scenario.surround, "law": law})


def model_time_run(scenario: Scenario, seed: int, record_dir: str | Path | None = None) -> list[dict[str, Any]]:
    """One ``--clock model`` run of ``scenario``: the world's states at 50 Hz, from the run's world.jsonl."""
    return scenario_run(scenario, seed, "model", record_dir)[0]


def scenario_run(
    scenario: Scenario, seed: int, clock: str = "model", record_dir: str | Path | None = None
) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """One run of ``scenario`` on ``clock`` (one of ``CLOCKS``): the world's states at 50 Hz, from the run's
    world.jsonl, and what its summary says of it (``digest``, ``ok``, ``problems``)."""
    from petswarm.lab.run import RunOptions

    if scenario.user is None:
        raise ValueError(f"scenario {scenario.name!r} has no user to surround")
    if clock not in CLOCKS:
        raise ValueError(f"clock {clock!r}: a bench run takes one of {', '.join(CLOCKS)}")
    with tempfile.TemporaryDirectory(prefix="bench-surround-") as scratch:
        record = Path(record_dir or scratch) / f"{scenario.name}-{seed}"
        opts = RunOptions(
            robots=scenario.robot_count,
            seed=seed,
            duration=scenario.duration_s,
            ping_interval=0.5,
            record_dir=str(record),
            scenario=str(scenario.path),
            clock=clock,
        )
        summary = _execute(opts, scenario, record)
        run = {"digest": summary.get("digest"), "ok": summary.get("ok", False), "problems": summary.get("problems")}
        world = record / "world.jsonl"  # none when a process run failed before its hub wrote a tick
        return (read_world(world) if world.exists() else []), run


def _execute(opts: RunOptions, scenario: Scenario, record: Path) -> dict[str, Any]:
    """Run and return the run's summary; a lockstep run's printed summary goes to stderr, not the bench's stdout."""
    # the hub's side and the run's orchestration, imported here: see bench_surround
    if opts.clock == "model":
        from petswarm.lab.model_run import execute

        return execute(opts, scenario)
    from petswarm.lab.lockstep_run import run_lockstep

    with contextlib.redirect_stdout(sys.stderr):
        code = run_lockstep(opts, scenario)
    if code == INTERRUPTED:  # Ctrl-C or SIGTERM stopped the run: it stops the bench too, as in model time
        raise KeyboardInterrupt
    summary = record / "summary.json"
    return json.loads(summary.read_text()) if summary.exists() else {"ok": False, "problems": ["no summary"]}
