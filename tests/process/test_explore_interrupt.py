"""``petswarm explore --workers 2`` stopped with SIGTERM mid-campaign: it stops its worker processes (none is left
behind, and none leaves a case's scratch directory), writes the report of the cases that finished, and exits 130."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tests.waiting import wait_for

pytestmark = pytest.mark.long

CASES = 60


def _children(pid: int) -> list[int]:
    """The processes ``pid`` started (every thread's), by /proc."""
    out: list[int] = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        out += [int(p) for p in (task / "children").read_text().split()]
    return out


def _identity(pid: int) -> tuple[str, str] | None:
    """(start time, command line) of a live process, None once it is gone (a zombie is gone too)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except (FileNotFoundError, ProcessLookupError):
        return None
    fields = stat.rsplit(")", 1)[1].split()
    return None if fields[0] == "Z" else (fields[19], cmdline)


def _finished_cases(path: Path) -> int:
    return len(path.read_text().splitlines()) if path.exists() else 0


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="reads the process tree from /proc")
@pytest.mark.timeout(240)
def test_sigterm_stops_the_campaigns_workers_and_keeps_the_cases_that_finished(tmp_path: Path) -> None:
    out, scratch = tmp_path / "out", tmp_path / "scratch"
    scratch.mkdir()
    petswarm = Path(sys.executable).with_name("petswarm")
    argv = [str(petswarm), "explore", "--seed", "2", "--cases", str(CASES), "--workers", "2", "--shrink", "0"]
    env = {**os.environ, "TMPDIR": str(scratch)}  # where the workers' cases keep their records meanwhile
    with (tmp_path / "stderr").open("w") as err:
        proc = subprocess.Popen([*argv, "--out", str(out)], stdout=subprocess.PIPE, stderr=err, env=env, text=True)
        try:
            wait_for("two cases finished", lambda: _finished_cases(out / "results.jsonl") >= 2, timeout=120)
            workers = {
                pid: who
                for pid in _children(proc.pid)
                if (who := _identity(pid)) is not None and "multiprocessing" in who[1] and "spawn_main" in who[1]
            }
            assert len(workers) == 2, workers
            proc.send_signal(signal.SIGTERM)
            stdout, _ = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    assert proc.returncode == 130, (tmp_path / "stderr").read_text()[-2000:]
    left = {pid: who for pid, who in workers.items() if _identity(pid) == who}
    assert left == {}, f"workers left running: {left}"
    assert list(scratch.iterdir()) == []  # every case stopped midway removed its scratch record
    lines = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
    report = json.loads((out / "results.json").read_text())
    assert report["interrupted"] is True and 2 <= len(report["cases"]) == len(lines) < CASES
    assert sorted(r["index"] for r in lines) == [r["index"] for r in report["cases"]]
    assert all(len(r["digest"]) >= 16 and "failures" in r for r in lines)  # each a finished, judged case
    assert f"interrupted after {len(lines)} of {CASES} cases" in stdout
    assert (out / "results.txt").read_text().startswith(f"interrupted after {len(lines)} of {CASES} cases")
