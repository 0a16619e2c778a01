"""One case in model time: the scenario's tables run as ``petswarm run FILE --clock model`` runs a file, the
record judged by every property that applies, the verdicts and digest returned (the record kept only on request).

A run that raises (a robot's, the user's or the environment's uncaught exception) is itself a verdict: the case
fails ``no_exception`` with the traceback kept."""

from __future__ import annotations

import contextlib
import io
import shutil
import tempfile
import time
import traceback
from pathlib import Path
from typing import Any

from petswarm.explore.properties import Record, judge
from petswarm.lab.digest import record_digest
from petswarm.lab.model_run import execute, scenario_options
from petswarm.scenario import parse


def run_case(data: dict[str, Any], seed: int, family: str, *, keep: Path | None = None) -> dict[str, Any]:
    """Run one case's scenario tables with ``seed``; its result: verdicts (``failures``: the properties that
    failed, with what, when and who), digest, model and CPU time. ``keep``: where to leave the record."""
    scenario = parse(data)
    started = time.process_time()
    workdir = Path(tempfile.mkdtemp(prefix="petswarm-explore-"))
    record_dir = keep if keep is not None else workdir / "record"
    opts = scenario_options(scenario, seed, record_dir)
    crash = None
    summary: dict[str, Any] = {}
    try:
        try:
            with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
                summary = execute(opts, scenario)
        except Exception:  # the case's verdict, not the campaign's end (an interrupt is the campaign's)
            crash = traceback.format_exc()
        path = Path(summary["record"]) if "record" in summary else (record_dir if record_dir.exists() else None)
        record = Record.read(path, scenario, family, crash)
        failures = judge(record)
        digest = summary.get("digest") or (record_digest(path) if path is not None else "")
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    return {
        "family": family,
        "robots": scenario.robot_count,
        "fault_kinds": sorted({str(f.get("kind")) for f in scenario.faults if "kind" in f}),
        "digest": digest,
        "model_time_s": summary.get("model_time_s", 0.0),
        "cpu_s": round(time.process_time() - started, 3),
        "ok": not failures,
        "failures": failures,
    }
