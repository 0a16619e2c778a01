"""``petswarm run`` as a user runs it: real processes, JSON out, clean stop on Ctrl-C."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from ..waiting import read_until, wait_for

pytestmark = [pytest.mark.process, pytest.mark.long]


def _petswarm(*args: str) -> list[str]:
    return [sys.executable, "-m", "cli", *args]


def _started_run(robots: int, *args: str) -> subprocess.Popen[str]:
    """``petswarm run`` in the background, returned once its robots are attached (it runs for 60 s)."""
    proc = subprocess.Popen(
        _petswarm("run", "--robots", str(robots), "--duration", "60", *args),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # Ctrl-C as a terminal delivers it: where this test runs in a background job of a shell, SIGINT comes
        # ignored (bash's rule for background jobs), Python keeps it so, and the run would never see it
        preexec_fn=_sigint_as_at_a_terminal,
    )
    seen = read_until(proc.stderr, f"{robots}/{robots} robots attached", timeout=60)
    if f"{robots}/{robots} robots attached" not in seen:
        proc.kill()
        raise AssertionError(seen)
    return proc


def _sigint_as_at_a_terminal() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _processes_mentioning(tag: str) -> list[int]:
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            cmdline = (entry / "cmdline").read_bytes()
        except OSError:
            continue
        if tag.encode() in cmdline:
            pids.append(int(entry.name))
    return pids


def _cmdline(pid: int) -> bytes:
    return Path(f"/proc/{pid}/cmdline").read_bytes()


def _parent(pid: int) -> int:
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])


def test_run_five_robots_exchanges_frames_among_all_and_reports_json():
    proc = subprocess.run(
        _petswarm("run", "--robots", "5", "--duration", "4", "--seed", "3", "--json"),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["seed"] == 3 and summary["ok"] and summary["all_pairs_heard"]
    assert set(summary["nodes"]) == {f"robot-{i}" for i in range(1, 6)}
    for rid, node in enumerate(summary["nodes"].values(), start=1):
        assert node["sent"] > 0 and node["delivered"] > 0
        assert node["heard_from"] == sorted(set(range(1, 6)) - {rid})
    assert summary["hub"]["transport_gaps"] == 0
    assert "robots attached" in proc.stderr  # progress is shown on stderr, not mixed into the JSON


def test_ctrl_c_stops_every_process_of_the_run():
    world = f"orphan{uuid.uuid4().hex[:8]}"
    proc = _started_run(3, "--world", world)
    try:
        assert len(_processes_mentioning(world)) >= 4  # the run, its hub and three robots
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=30) == 130
    finally:
        if proc.poll() is None:
            proc.kill()
    deadline = time.monotonic() + 5
    while _processes_mentioning(world) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _processes_mentioning(world) == []


def test_a_third_ctrl_c_ends_the_run_at_once_and_its_processes_go_with_it():
    """Ctrl-C, then two more before the stop is done: the run ends there (a stop can wait up to a minute on a
    robot's answer), saying so, and none of its processes outlives it. The fork server is paused first, so that
    the stop waits seconds for the robots' exit codes: the Ctrl-Cs all land in it however loaded the machine
    (10 ms apart, a stop over before the third made this test fail once in CI)."""
    world = f"thrice{uuid.uuid4().hex[:8]}"
    proc = _started_run(3, "--world", world)
    try:
        robot = next(pid for pid in _processes_mentioning(world) if b"\0robot\0" in _cmdline(pid))
        os.kill(_parent(robot), signal.SIGSTOP)  # the fork server: it reports the robots' exit codes
        for _ in range(3):
            proc.send_signal(signal.SIGINT)
            time.sleep(0.05)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130 and "third Ctrl-C: ending now" in err, err[-2000:]
    assert wait_for("the run's processes gone", lambda: not _processes_mentioning(world), 10, every=0.1)


def _first_frames_sent(proc: subprocess.Popen[str]) -> int:
    """The frames sent that a run's first progress line with any shows (its first lines may show none yet)."""
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        line = read_until(proc.stderr, "/60s  sent", timeout=max(deadline - time.monotonic(), 0.1))
        found = re.search(r"/60s  sent (\d+)", line)
        assert found, line[-2000:]
        if int(found.group(1)) > 0:
            return int(found.group(1))
    raise AssertionError("no progress line showed a frame sent within 30 s")


def test_signals_that_come_while_the_run_stops_wait_for_the_stop_and_its_record(tmp_path):
    """Ctrl-C, then SIGTERM after SIGTERM (a user pressing Ctrl-C again, ``timeout`` or compose following up)
    while the run stops its processes: the stop goes on, and the summary says how every process ended."""
    world = f"twice{uuid.uuid4().hex[:8]}"
    record = tmp_path / "twice"
    proc = _started_run(3, "--world", world, "--record", str(record))
    sent = 0
    try:
        shown = _first_frames_sent(proc)  # the ping phase's totals, once its frames are counted
        proc.send_signal(signal.SIGINT)
        deadline = time.monotonic() + 30
        while proc.poll() is None and time.monotonic() < deadline:
            proc.send_signal(signal.SIGTERM)
            sent += 1
            time.sleep(0.02)
        # 130: interrupted; -15: a SIGTERM came after the run had put SIGTERM's default action back
        assert proc.wait(timeout=5) in (130, -signal.SIGTERM), proc.stderr.read() if proc.stderr else ""
    finally:
        if proc.poll() is None:
            proc.kill()
    summary = json.loads((record / "summary.json").read_text())
    assert "running" not in summary and summary["problems"] == ["interrupted"], (sent, summary)
    assert set(summary["exit_codes"]) == {"hub", "robot-1", "robot-2", "robot-3"}, summary["exit_codes"]
    # what the run had found until then stays in its summary, as its running summary showed it
    assert summary["interrupted"] and summary["phase"] == "ping" and summary["totals"]["sent"] >= shown > 0, summary
    assert "pan_id" not in summary["totals"]  # a radio's name, not a counter to add up
    deadline = time.monotonic() + 5
    while _processes_mentioning(world) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _processes_mentioning(world) == []


def test_sigterm_ends_a_model_time_run_as_ctrl_c_does_with_its_summary(tmp_path):
    """``timeout`` or compose stops a run in model time (one process, no children) with SIGTERM: the record
    gets its summary, as on Ctrl-C and as a run of processes does, and the robots' tasks unwind quietly."""
    record = tmp_path / "model"
    argv = ["run", "--clock", "model", "--robots", "20", "--duration", "36000", "--record", str(record), "--json"]
    proc = subprocess.Popen(_petswarm(*argv), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        seen = read_until(proc.stderr, "20/20 robots attached", timeout=60)
        assert "20/20 robots attached" in seen, seen
        proc.send_signal(signal.SIGTERM)
        out, stderr = proc.communicate(timeout=30)  # read: the run's robots write on their way out
        assert proc.returncode == 130, stderr[-2000:]
    finally:
        if proc.poll() is None:
            proc.kill()
    summary = json.loads((record / "summary.json").read_text())
    assert summary["problems"] == ["interrupted"] and summary["clock"] == "model" and summary["interrupted"], summary
    assert {**json.loads(out), "exit_codes": {}} == summary  # --json: the interrupted summary on stdout too
    assert "Task was destroyed" not in stderr and len(stderr) < 20_000, stderr[-2000:]  # 300 kB of them for 50


def test_a_second_ctrl_c_as_an_interrupted_run_exits_keeps_its_status_130(tmp_path):
    """Two Ctrl-Cs 50 ms apart (a person pressing twice): the first stops the run, the second lands while the
    process exits, where Python had put SIGINT's default action back: it died of it (-2), 21 times in 21."""
    argv = ["run", "--clock", "model", "--robots", "10", "--duration", "600", "--record", str(tmp_path / "run")]
    proc = subprocess.Popen(
        _petswarm(*argv),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_sigint_as_at_a_terminal,
    )
    try:
        assert "10/10 robots attached" in read_until(proc.stderr, "10/10 robots attached", timeout=60)
        proc.send_signal(signal.SIGINT)
        time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130


def test_absurd_arguments_get_clear_errors():
    bad = subprocess.run(_petswarm("run", "--robots", "0"), capture_output=True, text=True, timeout=30)
    assert bad.returncode == 2 and "outside 1..2000" in bad.stderr
    bad = subprocess.run(_petswarm("run", "--robots", "201"), capture_output=True, text=True, timeout=30)
    assert bad.returncode == 2 and "--clock model" in bad.stderr  # 201 processes no, 201 in model time yes
    bad = subprocess.run(
        _petswarm("robot", "--id", "3", "--pos", "nowhere"), capture_output=True, text=True, timeout=30
    )
    assert bad.returncode == 2 and "position" in bad.stderr
    nohub = subprocess.run(_petswarm("stats", "--hub", "tcp/127.0.0.1:9"), capture_output=True, text=True, timeout=60)
    assert nohub.returncode == 2 and "petswarm stats:" in nohub.stderr


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (("scenarios", "--clock", "model"), "scenarios is a directory, not a scenario file"),
        (("--config", "no-such.toml"), "--config cannot read no-such.toml"),
        (("--config", "scenarios"), "--config cannot read scenarios"),
        (("--config", "{bad}", "--clock", "model"), "unknown key 'min_bee' (did you mean 'min_be'?)"),
        (("--config", "{bad}"), "unknown key 'min_bee'"),  # on the wall clock: before a hub starts and dies of it
        # options a scenario sets itself were ignored without a word (1 robot for 30 s, not 10 for 2)
        (
            ("scenarios/leading-arcs.toml", "--robots", "10", "--duration", "2", "--clock", "model"),
            "the scenario sets these itself (--robots: [robots] count; --duration: duration_s)",
        ),
    ],
)
def test_a_scenario_config_or_option_that_cannot_be_used_is_refused_before_anything_starts(
    tmp_path: Path, args: tuple[str, ...], says: str
) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[mac]\nmin_bee = 3\n")
    argv = [a.replace("{bad}", str(bad)) for a in args]
    proc = subprocess.run(
        _petswarm("run", *argv, "--record", str(tmp_path / "run")),
        capture_output=True,
        text=True,
        timeout=60,
        cwd=Path(__file__).resolve().parents[2],
    )
    assert proc.returncode == 2 and says in proc.stderr and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert len(proc.stderr.strip().splitlines()) == 1 and not (tmp_path / "run").exists()


def test_a_run_leaves_a_record_with_manifest_events_and_summary(tmp_path):
    """The record of a run of processes. In lockstep, so that the swarm it asks for forms on a loaded machine
    too: on the wall clock, starved robots miss the protocol's step deadlines (seen at load 9: no member)."""
    from petswarm.lab.records import read_events

    record = tmp_path / "rec"
    argv = ["run", "--robots", "3", "--duration", "1", "--organize", "2", "--seed", "9", "--clock", "lockstep"]
    proc = subprocess.run(
        _petswarm(*argv, "--record", str(record)),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    manifest = json.loads((record / "manifest.json").read_text())
    assert manifest["seed"] == 9 and manifest["options"]["organize"] == 2 and "eclipse-zenoh" in manifest["versions"]
    summary = json.loads((record / "summary.json").read_text())
    assert summary["ok"] and set(summary["exit_codes"].values()) == {0}, summary["exit_codes"]  # names who died
    events = read_events(record / "events" / "robot-2.jsonl")
    kinds = [e["kind"] for e in events]
    assert kinds[0] == "start" and kinds[-1] == "stop" and "state" in kinds
    assert [e["t"] for e in events] == sorted(e["t"] for e in events)
    report = subprocess.run(_petswarm("report", str(record)), capture_output=True, text=True, timeout=60)
    assert report.returncode == 0 and "OK" in report.stdout and "slave-driving" in report.stdout
    assert subprocess.run(_petswarm("report", str(tmp_path)), capture_output=True, timeout=60).returncode == 2


def test_a_run_killed_outright_still_leaves_a_readable_record(tmp_path):
    from petswarm.lab.records import read_events

    record = tmp_path / "killed"
    proc = _started_run(2, "--organize", "1", "--record", str(record))
    try:
        time.sleep(0.5)
        proc.kill()  # SIGKILL: no finally block runs in the run process
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert json.loads((record / "manifest.json").read_text())["options"]["robots"] == 2
    for rid in (1, 2):
        events = read_events(record / "events" / f"robot-{rid}.jsonl")
        assert events and events[0]["kind"] == "start"
    left = json.loads((record / "summary.json").read_text())  # the one the run rewrites as it goes
    assert left["running"] is True and not left["ok"]
    report = subprocess.run(_petswarm("report", str(record)), capture_output=True, text=True, timeout=60)
    assert report.returncode == 0, report.stderr
    assert "killed before it finished" in report.stdout and "robot-2" in report.stdout
    assert (record / "report.png").stat().st_size > 10_000


def test_an_experiment_file_runs_every_seed_with_its_fault_timeline(tmp_path):
    """Its runs in model time: what is under test is the file (seeds, fault timeline, results, plot, errors);
    the wall-clock path of an experiment is the next test's but one."""
    spec = tmp_path / "exp.toml"
    spec.write_text(
        'name = "robot 3 fades"\nseeds = [4, 5]\n[run]\nrobots = 3\nduration = 2\nclock = "model"\n'
        '[[faults]]\nat = 0.2\nkind = "loss"\nnode = "robot-3"\n'
    )
    out = tmp_path / "out"
    proc = subprocess.run(
        _petswarm("experiment", str(spec), "--out", str(out), "--json"), capture_output=True, text=True, timeout=180
    )
    assert proc.returncode in (0, 1), proc.stderr
    results = json.loads(proc.stdout)  # --json: the results on stdout, the table on stderr
    assert results == json.loads((out / "results.json").read_text()) and "experiment robot 3 fades" in proc.stderr
    assert [r["seed"] for r in results["runs"]] == [4, 5]
    for i, seed in enumerate((4, 5), start=1):
        summary = json.loads((out / f"run-{i}-seed-{seed}" / "summary.json").read_text())
        assert (
            summary["faults"][0]["fault"] == {"kind": "loss", "node": "robot-3"} and summary["faults"][0]["at"] == 0.2
        )
        assert sum(n["chaos_lost"] for n in summary["nodes"].values()) > 0  # the fade took frames
    assert "2/2 runs" in proc.stderr and (out / "results.png").stat().st_size > 10_000
    bad = tmp_path / "bad.toml"
    bad.write_text("[run]\nrobotz = 3\n")
    refused = subprocess.run(_petswarm("experiment", str(bad)), capture_output=True, text=True, timeout=60)
    assert refused.returncode == 2 and "robotz" in refused.stderr


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_ctrl_c_or_sigterm_stops_an_experiment_not_only_its_current_run(tmp_path, signum):
    spec = tmp_path / "long.toml"
    spec.write_text('name = "long"\nseeds = [1, 2]\n[run]\nrobots = 20\nduration = 36000\nclock = "model"\n')
    out = tmp_path / "out"
    proc = subprocess.Popen(
        _petswarm("experiment", str(spec), "--out", str(out)),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_sigint_as_at_a_terminal,
    )
    try:
        deadline = time.monotonic() + 60
        while not (out / "run-1-seed-1" / "manifest.json").exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(1.0)  # the run is under way (its record is made before its robots start)
        proc.send_signal(signum)
        _, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, stderr[-2000:]
    assert not (out / "run-2-seed-2").exists(), stderr[-2000:]
    results = json.loads((out / "results.json").read_text())  # what the experiment found until then
    assert results["interrupted"] and [r["seed"] for r in results["runs"]] == [1], results["runs"]
    assert "interrupted in run 1 of 2" in stderr


def test_the_shipped_example_experiment_passes_and_repeats_exactly_in_model_time(tmp_path):
    results = []
    for out in (tmp_path / "out", tmp_path / "again"):
        proc = subprocess.run(
            _petswarm("experiment", "examples/experiment-loss.toml", "--out", str(out)),
            capture_output=True,
            text=True,
            timeout=300,
            cwd=Path(__file__).resolve().parents[2],
        )
        assert proc.returncode == 0, proc.stdout + proc.stderr
        # the runs' own progress goes to their records: nothing runs into the experiment's progress lines
        assert all(line.startswith("[experiment] ") for line in proc.stderr.splitlines()), proc.stderr
        assert "3/3 runs; seed 3 ok" in proc.stderr and (out / "run-1-seed-1" / "progress.log").stat().st_size > 0
        results.append(json.loads((out / "results.json").read_text()))
    first, again = ([r["digest"] for r in result["runs"]] for result in results)
    runs = results[0]["runs"]
    assert len(runs) == 3 and all(r["ok"] and r["clock"] == "model" for r in runs)
    assert all(r["organize_ms"] is not None and r["members"] >= 1 for r in runs)  # every run organized
    assert len(set(first)) == 3 and first == again  # each seed its own run, and the same run every time


def test_an_experiment_runs_over_real_processes_with_clock_wall(tmp_path):
    """The example's first seed over a hub process and robot processes (``--clock wall`` over the file's model
    clock): the experiment's runner drives the wall-clock path too."""
    spec = tmp_path / "one.toml"
    example = (Path(__file__).resolve().parents[2] / "examples" / "experiment-loss.toml").read_text()
    spec.write_text(example.replace("repetitions = 3", "repetitions = 1"))
    out = tmp_path / "out"
    proc = subprocess.run(
        _petswarm("experiment", str(spec), "--out", str(out), "--clock", "wall"),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    [run] = json.loads((out / "results.json").read_text())["runs"]
    assert run["ok"] and run["clock"] == "wall" and run["digest"] is None and run["members"] >= 1


def test_organizing_more_robots_than_the_run_has_warns_and_says_why_fewer_joined(tmp_path):
    record = tmp_path / "rec"
    argv = ("run", "--robots", "3", "--duration", "1", "--organize", "10", "--seed", "2", "--record", str(record))
    proc = subprocess.run(_petswarm(*argv), capture_output=True, text=True, timeout=120)
    # the protocol did what it should (Table 2: fewer available than asked, so all of them join): not a failure
    assert proc.returncode == 0, proc.stdout + proc.stderr
    warning = next((line for line in proc.stderr.splitlines() if "warning" in line), "")
    assert "--organize 10" in warning and "2" in warning, proc.stderr
    summary = json.loads((record / "summary.json").read_text())
    assert len(summary["organization"]["members"]) == 2
    [note] = summary["notes"]
    assert "--organize 10" in note and "at most 2 can join" in note
    assert f"note: {note}" in proc.stdout and proc.stdout.rstrip().endswith("OK")


def _deep_toml(path: Path) -> Path:
    path.write_text("a = " + "[" * 100_000 + "]" * 100_000 + "\n")
    return path


def _scenario(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("args", "why"),
    [
        # an endless file was read for 4.7 GB in 7 s
        (lambda tmp: ["/dev/zero"], "longer than 1048576 bytes"),
        # a duration of 1e300 s ran until killed
        (lambda tmp: [str(_scenario(tmp / "long.toml", "duration_s = 1e300\n"))], "up to 86400"),
        (lambda tmp: [str(_scenario(tmp / "walk.toml", "[user]\npath = [{walk = 1e300}]\n"))], "up to 86400"),
        # TOML nested 100,000 deep: a RecursionError traceback
        (lambda tmp: [str(_deep_toml(tmp / "deep.toml"))], "nested too deeply"),
        # a seed past msgpack's range: a traceback after the hub could not answer
        (lambda tmp: ["--seed", str(2**64), "--robots", "2", "--duration", "1"], "seed must be in 0..2^64-1"),
        # a world name that is a key expression: a ValueError traceback
        (lambda tmp: ["--world", "a/b*", "--robots", "2", "--duration", "1"], "must be 1-64 letters"),
        # a record directory that cannot be written: an OSError traceback
        (
            lambda tmp: ["--record", "/sys/petswarm-record", "--robots", "2", "--duration", "1"],
            "cannot write the run record",
        ),
    ],
)
def test_bad_run_input_is_refused_in_one_line_with_status_2(tmp_path: Path, args, why: str) -> None:
    done = subprocess.run(
        _petswarm("run", *args(tmp_path), "--clock", "model"),
        capture_output=True,
        text=True,
        timeout=60,
    )
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and why in lines[-1], done.stderr[-2000:]
    assert "Traceback" not in done.stderr and not done.stdout
