"""Supervision with real processes: signals only to our own robots, a run that survives its robots, and a
run killed outright that leaves a summary and no children behind."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from petswarm.lab.processes import free_tcp_port
from petswarm.lab.supervision import DEATHS_ONLY

from ..waiting import read_until, wait_for

pytestmark = pytest.mark.process


def _env(tmp_path: Path) -> dict[str, str]:
    """A private runtime directory of the test's own, so registrations of parallel tests never meet."""
    runtime = tmp_path / "xdg"
    runtime.mkdir(mode=0o700, exist_ok=True)
    return {**os.environ, "XDG_RUNTIME_DIR": str(runtime), "PYTHONUNBUFFERED": "1"}


def _petswarm(env: dict[str, str], *args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "cli", *args], capture_output=True, text=True, timeout=timeout, env=env
    )


def _state(pid: int) -> str | None:
    """The process's state letter (R, S, T, Z...), None when there is no such process."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return None


STOP_WAIT_S = 10.0
"""A SIGSTOP is sent when ``chaos pause`` returns, but the process stops (state T) only once it is scheduled to
take the signal: on a loaded machine, later than the next read of /proc."""


def _wait_stopped(pid: int) -> None:
    wait_for(f"process {pid} stopped (T)", lambda: _state(pid) == "T", STOP_WAIT_S, every=0.05)


def _wait_registered(runtime: Path, name: str, proc: subprocess.Popen[bytes]) -> dict[str, Any]:
    entry = runtime / "petswarm" / name
    deadline = time.monotonic() + 20
    while not entry.exists():
        assert proc.poll() is None and time.monotonic() < deadline, f"{name} never registered"
        time.sleep(0.05)
    return json.loads(entry.read_text())


def _forge(runtime: Path, world: str, robot: int, pid: int, start: int) -> None:
    body = {"world": world, "robot": robot, "pid": pid, "start": start, "token": "forged"}
    (runtime / "petswarm" / f"{world}.robot-{robot}.json").write_text(json.dumps(body))


def test_chaos_signals_only_a_registered_robot_of_that_world(tmp_path: Path) -> None:
    env = _env(tmp_path)
    runtime = Path(env["XDG_RUNTIME_DIR"])
    hub = f"tcp/127.0.0.1:{free_tcp_port()}"
    quiet: dict[str, Any] = {"env": env, "stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    hub_proc = subprocess.Popen([sys.executable, "-m", "cli", "hub", "--listen", hub, "--world", "alpha"], **quiet)
    robot = subprocess.Popen(
        [sys.executable, "-m", "cli", "robot", "--id", "1", "--world", "alpha", "--hub", hub], **quiet
    )
    # alive until the test kills it: a 30 s sleep ended by itself on a loaded machine, and the test read its exit
    bystander = subprocess.Popen(["sleep", "infinity"])
    try:
        registered = _wait_registered(runtime, "alpha.robot-1.json", robot)
        assert registered["pid"] == robot.pid
        assert (runtime / "petswarm").stat().st_mode & 0o777 == 0o700

        refusals = {
            "pid 1": (1, registered["start"]),
            "a process that is no robot": (bystander.pid, _start(bystander.pid)),
            "another world's robot": (robot.pid, registered["start"]),
        }
        for why, (pid, start) in refusals.items():
            _forge(runtime, "beta", 1, pid, start)
            done = _petswarm(env, "chaos", "kill", "--robot", "1", "--world", "beta")
            assert done.returncode == 2 and "refused" in done.stderr, (why, done.stderr)
        unregistered = _petswarm(env, "chaos", "pause", "--robot", "7", "--world", "alpha")
        assert unregistered.returncode == 2 and "not registered" in unregistered.stderr
        assert bystander.poll() is None and _state(robot.pid) in ("R", "S")

        assert _petswarm(env, "chaos", "pause", "--robot", "1", "--world", "alpha").returncode == 0
        _wait_stopped(robot.pid)
        assert _petswarm(env, "chaos", "resume", "--robot", "1", "--world", "alpha").returncode == 0
        assert _state(robot.pid) in ("R", "S")
        assert _petswarm(env, "chaos", "kill", "--robot", "1", "--world", "alpha").returncode == 0
        assert robot.wait(10) == -signal.SIGKILL
    finally:
        for proc in (robot, bystander, hub_proc):
            proc.kill()
            proc.wait()


def _start(pid: int) -> int:
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[19])


def _run(env: dict[str, str], record: Path, world: str, *args: str) -> subprocess.Popen[str]:
    argv = [sys.executable, "-m", "cli", "run", "--record", str(record), "--world", world, "--seed", "3", *args]
    return subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _running_summary(record: Path, run: subprocess.Popen[str], until: str, timeout: float = 30) -> dict[str, Any]:
    """The summary the run rewrites as it goes, once its phase has reached ``until`` (a key of it)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert run.poll() is None, run.communicate()[1][-3000:]
        try:
            summary = json.loads((record / "summary.json").read_text())
        except (OSError, ValueError):
            summary = {}
        if summary.get("running") and until in summary:
            return summary
        time.sleep(0.2)
    raise AssertionError("the run never wrote a summary while running")


def test_a_run_survives_a_robot_killed_from_outside(tmp_path: Path) -> None:
    """In lockstep, so that the swarm it asks for forms on a loaded machine too: on the wall clock, starved
    robots miss the protocol's step deadlines (seen twice at load 7-20: members [2, 4] after 5 retries)."""
    env, record = _env(tmp_path), tmp_path / "record"
    argv = ["--robots", "5", "--organize", "3", "--duration", "20", "--json", "--clock", "lockstep"]
    run = _run(env, record, "survive", *argv)
    try:
        # model time runs once every node is there: the robots are attached, and the swarm forms at 20 s
        seen = read_until(run.stderr, "t=  2.0/20s", timeout=60)
        assert "t=  2.0/20s" in seen, seen[-3000:]
        summary = _running_summary(record, run, "processes")
        os.kill(summary["processes"]["robot-5"], signal.SIGKILL)
        out, rest = run.communicate(timeout=120)
        err = seen + rest
    finally:
        run.kill()
        run.wait()
    assert run.returncode == DEATHS_ONLY, err[-3000:]
    final = json.loads(out)
    assert final["ok"] and final["problems"] == [] and final["invariants"] == "all hold", final["problems"]
    assert [(d["process"], d["cause"]) for d in final["deaths"]] == [("robot-5", "SIGKILL")]
    assert final["organization"]["members"] == [2, 3, 4]  # robot 5 gone, the swarm of 3 formed without it
    assert final["dispersal"]["unconfirmed"] == []
    assert final["nodes"]["robot-5"]["died"] is True
    died = [json.loads(line) for line in (record / "supervision.jsonl").read_text().splitlines()]
    assert [d["process"] for d in died] == ["robot-5"]
    assert "robot-5 died (SIGKILL)" in err


def test_a_wall_clock_run_survives_a_robot_killed_during_its_pings(tmp_path: Path) -> None:
    """The wall-clock path of the same: no swarm to form (that depends on the machine's load), only the death
    recorded, the dead robot left out of the hearing checks, and the exit status saying robots died."""
    env, record = _env(tmp_path), tmp_path / "record"
    run = _run(env, record, "survive-wall", "--robots", "3", "--duration", "4", "--json")
    try:
        summary = _running_summary(record, run, "totals")  # the ping phase has begun: every robot attached
        os.kill(summary["processes"]["robot-3"], signal.SIGKILL)
        out, err = run.communicate(timeout=60)
    finally:
        run.kill()
        run.wait()
    assert run.returncode == DEATHS_ONLY, err[-3000:]
    final = json.loads(out)
    assert final["ok"] and final["problems"] == [], final["problems"]
    assert [(d["process"], d["cause"]) for d in final["deaths"]] == [("robot-3", "SIGKILL")]
    assert final["nodes"]["robot-3"]["died"] is True and "died" not in final["nodes"]["robot-2"]


def test_a_lockstep_robot_taken_as_gone_while_alive_fails_the_run(tmp_path: Path) -> None:
    """A robot process that stops answering (paused, not dead) is taken as gone by the lockstep hub after the
    run's ``--dead-after`` of wall time and the world goes on; the run does not excuse it as it excuses a death:
    it says so. (4 s, not the default 10: long enough that a live process a loaded machine starves still answers,
    as the run node and robot 1 must.)"""
    env, record = _env(tmp_path), tmp_path / "record"
    argv = ["--robots", "2", "--duration", "3", "--json", "--clock", "lockstep", "--dead-after", "4"]
    run = _run(env, record, "paused", *argv)
    try:
        seen = read_until(run.stderr, "t=  1.0/3s", timeout=60)
        assert "t=  1.0/3s" in seen, seen[-3000:]
        pid = _running_summary(record, run, "processes")["processes"]["robot-2"]
        os.kill(pid, signal.SIGSTOP)
        hub_log = record / "logs" / "hub.log"
        gone = "robot-2 is gone at model time"
        wait_for("robot-2 taken as gone", lambda: gone in hub_log.read_text(errors="replace"), 30)
        assert "no idle within 4 s of wall time" in hub_log.read_text(errors="replace")  # the run's --dead-after
        with contextlib.suppress(ProcessLookupError):  # the run's own stop may have resumed and ended it already
            os.kill(pid, signal.SIGCONT)
        out, _ = run.communicate(timeout=120)
    finally:
        run.kill()
        run.wait()
    final = json.loads(out)
    assert run.returncode == 1 and not final["ok"], final["problems"]
    assert [g["node"] for g in final["gone"]] == ["robot-2"] and final["deaths"] == []
    assert any("robot 2 could not be told to stop" in p for p in final["problems"]), final["problems"]


def _signal_mid_run(tmp_path: Path, world: str, process: str, signum: int, *args: str) -> tuple[int, str, dict]:
    """A wall-clock run of 2 robots with ``args``; once its ping phase runs, ``signum`` to its child ``process``.
    The run's exit status, its stderr and its final summary."""
    env, record = _env(tmp_path), tmp_path / "record"
    run = _run(env, record, world, "--robots", "2", *args)
    try:
        summary = _running_summary(record, run, "totals")
        os.kill(summary["processes"][process], signum)
        _, err = run.communicate(timeout=60)
    finally:
        run.kill()
        run.wait()
    return run.returncode, err, json.loads((record / "summary.json").read_text())


def test_a_robot_death_ends_the_run_under_fail_fast(tmp_path: Path) -> None:
    code, err, final = _signal_mid_run(tmp_path, "fast", "robot-2", signal.SIGKILL, "--duration", "20", "--fail-fast")
    assert code == 1, err[-3000:]
    assert not final["ok"] and "robot-2 died (SIGKILL)" in final["problems"][0]
    assert [d["process"] for d in final["deaths"]] == ["robot-2"]


def test_a_hub_that_ends_cleanly_mid_run_ends_the_run_too(tmp_path: Path) -> None:
    """A hub stopped by someone else's SIGTERM closes and exits 0; that is still the end of the air, not a
    user walking off. The run took a clean exit of any child but a robot as work done, and went on for its
    whole --duration with the progress frozen and the summary saying running."""
    code, err, final = _signal_mid_run(tmp_path, "hub-ends", "hub", signal.SIGTERM, "--duration", "600")
    assert code == 1, err[-3000:]
    assert not final["ok"] and final["problems"][0].startswith("failed: hub died (exit 0)"), final["problems"]
    assert not final.get("running") and [d["process"] for d in final["deaths"]] == ["hub"]


def test_a_run_killed_outright_leaves_a_summary_and_no_children(tmp_path: Path) -> None:
    env, record = _env(tmp_path), tmp_path / "record"
    run = _run(env, record, "orphans", "--robots", "3", "--duration", "30")
    try:
        summary = _running_summary(record, run, "totals")
        paused = _petswarm(env, "chaos", "pause", "--robot", "2", "--world", "orphans")
        assert paused.returncode == 0, paused.stderr
        children = summary["processes"]
        _wait_stopped(children["robot-2"])
        run.kill()  # SIGKILL: run's own code gets no say
        run.wait()
    finally:
        run.kill()
        run.communicate()
    left = json.loads((record / "summary.json").read_text())
    assert left["running"] is True and not left["ok"] and "totals" in left
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(_state(pid) not in (None, "Z") for pid in children.values()):
        time.sleep(0.1)
    alive = {name: _state(pid) for name, pid in children.items() if _state(pid) not in (None, "Z")}
    assert alive == {}, f"children outlived their run: {alive}"
