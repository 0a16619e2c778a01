"""``petswarm bench all``: the quick path through real bench processes, and the plan covering every bench."""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from petswarm.bench.all import FIGURES

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.timeout(180)
def test_bench_all_quick_reruns_the_named_benches_under_one_header(tmp_path: Path) -> None:
    out = tmp_path / "figures"
    argv = [sys.executable, "-m", "cli", "bench", "all", "--quick", "--only", "ir,organize", "--out", str(out)]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=170, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-3000:]
    index = (out / "index.md").read_text()
    # one header: the command that made the page, the date, the machine and its load
    assert f"- **command**: `petswarm bench all --out {out} --quick --only ir,organize`" in index
    assert re.search(r"- \*\*date\*\*: \d{4}-\d\d-\d\d \d\d:\d\d UTC", index)
    assert re.search(r"- \*\*machine\*\*: .+, \d+ cores", index)
    assert re.search(r"- \*\*load average\*\* \(1 min\) over the run: [\d.]+-[\d.]+", index)
    assert index.count("# Figures") == 1 and "--quick" in index
    record = json.loads((out / "figures.json").read_text())
    assert [f["name"] for f in record["figures"]] == ["organize", "ir"]  # FIGURES' order, not the option's
    for figure in record["figures"]:
        assert figure["status"] == 0, figure
        assert figure["command"] in index
        assert figure["command"].endswith(f"--out {out / figure['name']}")
        # each bench's own files, in its own folder, its table on the page and its plot linked from it
        assert (out / figure["name"] / f"bench_{figure['name']}.json").exists()
        assert (out / figure["name"] / f"bench_{figure['name']}.png").stat().st_size > 10_000
        assert f"]({figure['name']}/bench_{figure['name']}.png)" in index
    assert "organizing time" in index and "lsq" in index  # the benches' tables themselves


def test_bench_all_refuses_an_unknown_figure_in_one_line(tmp_path: Path) -> None:
    argv = [sys.executable, "-m", "cli", "bench", "all", "--only", "ir,nonesuch", "--out", str(tmp_path)]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert done.returncode == 2
    assert "no figure nonesuch (known: hub," in done.stderr and "Traceback" not in done.stderr
    assert not list(tmp_path.iterdir())  # nothing ran


def test_every_bench_of_the_command_line_is_in_the_plan_and_every_plan_parses() -> None:
    from cli.main import build_parser

    parser = build_parser()
    bench = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices["bench"]
    benches = set(next(a for a in bench._actions if isinstance(a, argparse._SubParsersAction)).choices)
    assert benches - {"all"} == {f.args[0] for f in FIGURES}, "a bench bench all does not run (or runs no more)"
    for figure in FIGURES:  # each command as bench all will give it: full and quick, --out added
        for args in (figure.args, figure.quick):
            parsed = parser.parse_args(["bench", *args, "--out", "x"])
            assert parsed.bench == args[0]


@pytest.mark.timeout(120)
def test_bench_all_interrupted_keeps_what_finished_and_exits_130_in_one_line(tmp_path: Path) -> None:
    import os
    import signal
    import time

    out = tmp_path / "figures"
    argv = [sys.executable, "-m", "cli", "bench", "all", "--quick", "--only", "ir,reaction", "--out", str(out)]

    def own_group_with_default_sigint() -> None:  # as a terminal's foreground job: Ctrl-C reaches the group
        os.setpgid(0, 0)
        signal.signal(signal.SIGINT, signal.SIG_DFL)

    proc = subprocess.Popen(argv, stderr=subprocess.PIPE, text=True, cwd=ROOT, preexec_fn=own_group_with_default_sigint)
    index = out / "index.md"
    deadline = time.monotonic() + 90
    while not (index.exists() and "## ir" in index.read_text()):  # the first bench done
        assert time.monotonic() < deadline and proc.poll() is None, "the first bench never finished"
        time.sleep(0.2)
    time.sleep(1.0)  # the second bench (reaction, about 15 s) is under way
    os.killpg(proc.pid, signal.SIGINT)
    stderr = proc.communicate(timeout=60)[1]
    assert proc.returncode == 130, stderr
    assert "interrupted during reaction; 1 finished" in stderr and "Traceback" not in stderr
    assert "## ir" in index.read_text() and "## reaction" not in index.read_text()
