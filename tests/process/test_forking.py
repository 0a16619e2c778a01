"""Robots forked from the fork server (petswarm.lab.forking) are robot processes to everyone who looks:
their own logs, exit codes, command line, parent-death signal; a bad request or a dead server harms nothing."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from petswarm.lab.forking import TITLE_ROOM, ForkedProcess
from petswarm.lab.processes import Supervisor, free_tcp_port
from petswarm.lab.runtime import check_process, start_time

pytestmark = pytest.mark.timeout(60)


def _waiting_robot(rid: int, world: str = "forked") -> list[str]:
    """A robot with no hub to reach: it waits (up to 15 s), long enough to look at."""
    return ["robot", "--id", str(rid), "--hub", f"tcp/127.0.0.1:{free_tcp_port()}", "--world", world]


def _log_says(sup: Supervisor, name: str, text: str, within_s: float = 15.0) -> bool:
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        if text in sup.log_tail(name, 50):
            return True
        time.sleep(0.05)
    return False


def test_a_forked_robot_is_a_robot_process_by_its_command_line_log_and_exit_code(tmp_path: Path) -> None:
    sup = Supervisor(tmp_path / "logs")
    try:
        robot = sup.spawn("robot-3", _waiting_robot(3))
        assert isinstance(robot, ForkedProcess)
        assert _log_says(sup, "robot-3", "robot 3: waiting for a hub of world 'forked'")
        cmdline = [a for a in Path(f"/proc/{robot.pid}/cmdline").read_bytes().decode().split("\0") if a]
        assert cmdline[1:5] == ["-m", "cli", "robot", "--id"], cmdline
        check_process(robot.pid, start_time(robot.pid), "forked", 3)  # what petswarm chaos checks before a signal
        assert robot.poll() is None
        with pytest.raises(subprocess.TimeoutExpired):
            robot.wait(0.2)
        robot.kill()
        assert robot.wait(5) == -signal.SIGKILL
        bad = sup.spawn("robot-bad", ["robot", "--id", "0x"])  # argparse refuses: exit code 2, its words in the log
        assert bad.wait(10) == 2
        assert "argument --id: '0x' is not an integer" in sup.log_tail("robot-bad")
    finally:
        codes = sup.stop_all()
    assert codes["robot-3"] == -signal.SIGKILL


def test_stop_all_ends_forked_robots_with_sigterm_and_then_the_server(tmp_path: Path) -> None:
    sup = Supervisor(tmp_path / "logs")
    try:
        robots = [sup.spawn(f"robot-{rid}", _waiting_robot(rid)) for rid in (1, 2, 3)]
        assert all(_log_says(sup, f"robot-{rid}", "waiting for a hub") for rid in (1, 2, 3))
        server = _server_pid(robots[0])
    except BaseException:  # the server and its robots would stay as long as this test's traceback holds sup
        sup.stop_all()
        raise
    codes = sup.stop_all()
    assert set(codes) == {"robot-1", "robot-2", "robot-3"}
    assert all(code is not None and code != -signal.SIGKILL for code in codes.values()), codes  # they ended on TERM
    assert not Path(f"/proc/{server}").exists()  # ended and reaped by its supervisor


def test_robots_die_with_their_fork_server(tmp_path: Path) -> None:
    """The server dies (SIGKILL): each child's parent-death signal ends it, and the supervisor hears of it."""
    sup = Supervisor(tmp_path / "logs")
    try:
        robot = sup.spawn("robot-4", _waiting_robot(4))
        assert _log_says(sup, "robot-4", "waiting for a hub")
        os.kill(_server_pid(robot), signal.SIGKILL)
        assert robot.wait(5) == -signal.SIGKILL
        assert not Path(f"/proc/{robot.pid}").exists() or _state(robot.pid) == "Z"
        after = sup.spawn("robot-5", _waiting_robot(5))  # the next robot starts the ordinary way
        assert isinstance(after, subprocess.Popen)
    finally:
        sup.stop_all()


def test_a_sigterm_to_the_whole_process_group_is_the_robots_to_handle_not_the_servers(tmp_path: Path) -> None:
    """``kill -TERM -PGID`` (a terminal, timeout, a CI runner) reaches the server too: it must stay, so that each
    robot ends its own way (its code, not the SIGKILL of a dead server) and is still reported."""
    sup = Supervisor(tmp_path / "logs")
    try:
        robot = sup.spawn("robot-8", _waiting_robot(8))
        assert _log_says(sup, "robot-8", "waiting for a hub")
        server = _server_pid(robot)
        os.kill(server, signal.SIGTERM)
        os.kill(robot.pid, signal.SIGTERM)
        code = robot.wait(10)
        assert code != -signal.SIGKILL, code
        assert _state(server) in ("S", "R")  # still serving
        assert isinstance(sup.spawn("robot-9", _waiting_robot(9)), ForkedProcess)
    finally:
        sup.stop_all()


def test_a_command_line_too_long_for_the_room_or_no_fork_starts_the_ordinary_way(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    sup = Supervisor(tmp_path / "logs")
    plain = Supervisor(tmp_path / "plain", fork=False)
    try:
        assert isinstance(sup.spawn("robot-5", _waiting_robot(5)), ForkedProcess)
        monkeypatch.setenv("PYTHONWARNINGS", "error")  # read at an interpreter's start: the server started without it
        assert isinstance(sup.spawn("robot-4", _waiting_robot(4)), subprocess.Popen)
        monkeypatch.delenv("PYTHONWARNINGS")
        long_world = "w" * 60
        argv = [*_waiting_robot(6, long_world), "--record", str(tmp_path / ("x" * TITLE_ROOM) / "e.jsonl")]
        assert isinstance(sup.spawn("robot-6", argv), subprocess.Popen)
        assert isinstance(plain.spawn("robot-7", _waiting_robot(7)), subprocess.Popen)
    finally:
        sup.stop_all()
        plain.stop_all()


def test_the_server_refuses_malformed_requests_and_keeps_serving(tmp_path: Path) -> None:
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    argv = [sys.executable, "-m", "cli.forkserver", str(theirs.fileno()), " " * 64]
    server = subprocess.Popen(argv, pass_fds=(theirs.fileno(),), cwd=_root())
    theirs.close()
    try:
        ours.settimeout(30)
        fine = {"argv": ["robot", "--help"], "log": str(tmp_path / "x.log"), "env": {}, "cwd": "/", "deathsig": 9}
        for bad in (
            b"\xff\x00",
            b"[]",
            b'{"argv": "robot"}',
            json.dumps({**fine, "argv": [1]}).encode(),
            json.dumps({**fine, "log": str(tmp_path / "no" / "such" / "dir.log")}).encode(),
            json.dumps({**fine, "deathsig": 999}).encode(),
            b"[" * 100_000,  # nested past Python's recursion limit
            json.dumps({**fine, "cwd": "/tmp\u0000x"}).encode(),
        ):
            ours.send(bad)
            assert "refused" in json.loads(ours.recv(1 << 20)), bad
        good = {"argv": ["robot", "--help"], "log": str(tmp_path / "help.log"), "env": dict(os.environ)}
        ours.send(json.dumps({**good, "cwd": str(tmp_path), "deathsig": int(signal.SIGKILL)}).encode())
        spawned = json.loads(ours.recv(1 << 20))
        assert json.loads(ours.recv(1 << 20)) == {"exited": spawned["spawned"], "code": 0}
        assert "usage: petswarm robot" in (tmp_path / "help.log").read_text()
    finally:
        ours.close()  # the server's end of work
        assert server.wait(10) == 0


def _server_pid(child: ForkedProcess) -> int:
    return int(Path(f"/proc/{child.pid}/stat").read_text().rsplit(")", 1)[1].split()[1])


def _state(pid: int) -> str:
    return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]


def _root() -> Path:
    return Path(__file__).resolve().parents[2]


def test_a_robot_stopped_just_after_it_was_forked_ends_on_that_sigterm(tmp_path: Path) -> None:
    """The server ignores the stop signals (they are its supervisor's to act on); a child stopped before it has
    taken on its own (``become``) must still end on that SIGTERM, not on the SIGKILL that follows 5 s later."""
    sup = Supervisor(tmp_path / "logs")
    try:
        sup.spawn("robot-1", _waiting_robot(1))  # the server is up and has imported once this one waits
        assert _log_says(sup, "robot-1", "waiting for a hub")
        ends = []
        for rid in range(2, 10):
            sup.spawn(f"robot-{rid}", _waiting_robot(rid))
            started = time.monotonic()
            code = sup.stop([f"robot-{rid}"])[f"robot-{rid}"]
            ends.append((code, round(time.monotonic() - started, 2)))
    finally:
        sup.stop_all()
    assert all(code == -signal.SIGTERM for code, _ in ends), ends


def test_a_stop_whose_exit_reports_never_come_ends_all_the_same_with_the_codes_unknown(tmp_path: Path) -> None:
    """The fork server reaps the robots and reports their exit codes. Stopped (SIGSTOP), it reports nothing: the
    stop still ends within its bounds, saying which codes it does not know, rather than waiting for ever; and
    its robots share one wait after their SIGKILL (one each was 5 s per robot: 100 s for 20)."""
    sup = Supervisor(tmp_path / "logs")
    server = 0
    names = [f"robot-{rid}" for rid in (6, 7, 8, 9)]
    try:
        robots = [sup.spawn(name, _waiting_robot(int(name[6:]))) for name in names]
        assert all(_log_says(sup, name, "waiting for a hub") for name in names)
        server = _server_pid(robots[0])
        os.kill(server, signal.SIGSTOP)
        started = time.monotonic()
        codes = sup.stop(names, timeout=0.5, killed_within_s=2.0)
        took = time.monotonic() - started
    finally:
        if server:
            os.kill(server, signal.SIGCONT)
        sup.stop_all()
    assert codes == dict.fromkeys(names), codes
    assert took < 6.0, took  # 0.5 + 2 s of waits; a wait per robot was 0.5 + 4 x 2 s, and before that for ever
    assert all(not Path(f"/proc/{r.pid}").exists() or _state(r.pid) == "Z" for r in robots)  # ended: only codes lost
