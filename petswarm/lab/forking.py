"""A fork server for robot processes: import a robot's code once per run, fork every robot from it.

Why: a robot process spends about 0.3 CPU-s importing its middleware before it does anything (half of it
Python 3.11 making dataclasses), and a run or the test suite starts robots by the dozen. The fork server is one
``python -m cli.forkserver`` process per ``Supervisor`` that imports what a robot imports (lean, as
``cli.lean`` says), then forks a robot for each request; the child is that robot's ``petswarm robot``
command from then on.

What the child keeps of a robot started with exec (so nothing else has to know):
- its own pid, log file (stdout and stderr), working directory, environment and stdin from /dev/null;
- its command line as ``ps`` and ``petswarm chaos`` read it (``/proc/<pid>/cmdline``): the server starts with
  room after its own arguments and the child writes its ``python -m cli robot ...`` there;
- its parent-death signal: the server dies with its supervisor (SIGKILL), and each child with the server.

The supervisor's side keeps a Popen-like handle per child (``ForkedProcess``); the server reaps its children
and reports each exit code over the socket, negative for a signal as ``subprocess`` does.

Protocol (a SOCK_SEQPACKET socket pair, one JSON object per packet): the supervisor sends
``{"argv", "log", "env", "cwd", "deathsig"}``; the server answers ``{"spawned": pid}`` or ``{"refused": why}``
and, whenever a child ends, ``{"exited": pid, "code": n}``.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import os
import selectors
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

from petswarm.lab.runtime import stat_fields

TITLE_ROOM = 4096
"""Bytes of command line the server reserves for a child's own (a scenario robot's is under 600)."""
PACKET_BYTES = 1 << 20
"""The largest request or answer (a request carries the child's environment)."""
STARTUP_PREFIXES = ("PYTHON", "LC_", "LANG")
"""Environment an interpreter reads only at its start (hash seed, path, warnings, encodings, locale): a child
whose own differs from the server's in any of it is not forked (it would not get it)."""
SPAWN_WITHIN_S = 60.0
"""How long a supervisor waits for the server's answer (its first one comes after the server's imports)."""
_PR_SET_PDEATHSIG = 1
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""What the server leaves to its supervisor (blocked and ignored) and each child acts on again (``become``)."""


class ForkServerGone(Exception):
    """The fork server ended or refused: the caller starts the process another way."""


def can_fork_server() -> bool:
    """Whether this platform has what the server needs (Linux: pidfds, /proc, prctl)."""
    return sys.platform == "linux" and hasattr(os, "pidfd_open")


def child_environment() -> dict[str, str]:
    """The environment of every child a supervisor starts, forked or not: its own, unbuffered (a log line is
    written as it is printed, so a child killed outright loses none)."""
    return {**os.environ, "PYTHONUNBUFFERED": "1"}


def title(argv: list[str]) -> bytes:
    """The command line a forked child shows: ``<python> -m cli <argv>``, NUL-separated as the kernel keeps it."""
    return b"".join(os.fsencode(arg) + b"\0" for arg in [sys.executable, "-m", "cli", *argv])


class ForkedProcess:
    """A child of the fork server, seen from the supervisor as a ``subprocess.Popen`` is."""

    def __init__(self, server: ForkServer, pid: int, args: list[str]) -> None:
        self._server = server
        self.pid = pid
        self.args = args
        self.returncode: int | None = None

    def poll(self) -> int | None:
        """The exit code once the child has ended, else None."""
        if self.returncode is None:
            self.returncode = self._server.exit_code(self.pid, timeout=0.0)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        """Wait for the child's end; subprocess.TimeoutExpired after ``timeout`` seconds."""
        if self.returncode is None:
            self.returncode = self._server.exit_code(self.pid, timeout)
        if self.returncode is None:
            raise subprocess.TimeoutExpired(self.args, timeout or 0.0)
        return self.returncode

    def send_signal(self, signum: int) -> None:
        """Signal the child unless it is known to have ended (its pid may be someone else's by now)."""
        if self.poll() is None:
            self._server.send_signal(self.pid, signum)

    def terminate(self) -> None:
        """SIGTERM, as Popen.terminate."""
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        """SIGKILL, as Popen.kill."""
        self.send_signal(signal.SIGKILL)


class ForkServer:
    """The supervisor's end of one fork server process; ``close`` ends it (after its children)."""

    def __init__(self, log: IO[bytes], die_with_parent: Callable[[], None]) -> None:
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self._env = child_environment()
        with theirs:
            self._proc = subprocess.Popen(
                [sys.executable, "-m", "cli.forkserver", str(theirs.fileno()), " " * TITLE_ROOM],
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=subprocess.STDOUT,
                pass_fds=(theirs.fileno(),),
                preexec_fn=die_with_parent,
                env=self._env,
            )
        self._sock = ours
        self._exits: dict[int, int] = {}
        self._pidfds: dict[int, int] = {}
        """Each live child's pidfd. The server reaps a child before we hear of it, so its pid alone could be
        someone else's by then: a pidfd names this very process (a signal to it fails once it has ended, and it
        reads ready when it ends). Closed once the child's exit is known."""
        self._gone = False

    def fits(self, argv: list[str], env: dict[str, str]) -> bool:
        """Whether a child with this command line and environment can be forked rather than started anew."""
        startup = {k for k in (*env, *self._env) if k.startswith(STARTUP_PREFIXES)}
        same_start = all(env.get(k) == self._env.get(k) for k in startup)
        return not self._gone and same_start and len(title(argv)) <= TITLE_ROOM

    def spawn(self, argv: list[str], log: Path, env: dict[str, str], deathsig: int) -> ForkedProcess:
        """Fork ``petswarm <argv>``; ForkServerGone if the server is not there or refuses."""
        request = {"argv": argv, "log": str(log), "env": env, "cwd": os.getcwd(), "deathsig": int(deathsig)}
        try:
            self._sock.send(json.dumps(request).encode())
        except OSError as err:
            self._gone = True
            raise ForkServerGone(f"the fork server is gone: {err}") from None
        deadline = time.monotonic() + SPAWN_WITHIN_S
        while True:
            answer = self._receive(timeout=max(deadline - time.monotonic(), 0.0))
            if not answer:  # a server that does not answer is ended with anything it forked since
                self._gone = True
                self._proc.kill()
                raise ForkServerGone(f"the fork server did not answer within {SPAWN_WITHIN_S:.0f} s")
            if "spawned" in answer:
                pid = int(answer["spawned"])
                with contextlib.suppress(OSError):  # else already ended and reaped: its report will say how
                    self._pidfds[pid] = os.pidfd_open(pid)
                return ForkedProcess(self, pid, argv)
            if "refused" in answer:
                raise ForkServerGone(f"the fork server refused: {answer['refused']}")

    def exit_code(self, pid: int, timeout: float | None) -> int | None:
        """The exit code of child ``pid`` once the server has reported it, waiting up to ``timeout``."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while pid not in self._exits:
            left = None if deadline is None else max(deadline - time.monotonic(), 0.0)
            if self._gone:
                if self._lost(pid) is None and left == 0.0:
                    return None
                time.sleep(0.01)
                continue
            if not self._poll_socket(left):
                return None
            with contextlib.suppress(ForkServerGone):  # then _lost says what became of the child
                self._receive(timeout=0.0)
        pidfd = self._pidfds.pop(pid, None)
        if pidfd is not None:
            os.close(pidfd)
        return self._exits[pid]

    def send_signal(self, pid: int, signum: int) -> None:
        """Signal child ``pid`` through its pidfd; nothing if it has ended."""
        pidfd = self._pidfds.get(pid)
        if pidfd is not None:
            with contextlib.suppress(ProcessLookupError):
                signal.pidfd_send_signal(pidfd, signum)

    def close(self, timeout: float = 5.0) -> None:
        """End the server: it exits once the socket closes (any child left dies with it)."""
        self._sock.close()
        self._gone = True
        for pidfd in self._pidfds.values():
            os.close(pidfd)
        self._pidfds.clear()
        try:
            self._proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()

    def _poll_socket(self, timeout: float | None) -> bool:
        return _readable(self._sock, timeout)

    def _receive(self, timeout: float) -> dict[str, Any]:
        """One answer of the server (an exit report is filed as it comes); {} when there is none in time."""
        if not self._poll_socket(timeout):
            return {}
        try:
            data = self._sock.recv(PACKET_BYTES)
        except OSError:
            data = b""
        if not data:
            self._gone = True
            raise ForkServerGone("the fork server ended")
        answer: dict[str, Any] = json.loads(data)
        if "exited" in answer:
            self._exits[int(answer["exited"])] = int(answer["code"])
        return answer

    def _lost(self, pid: int) -> int | None:
        """A child whose server is gone: it dies with the server (parent-death signal); None while it runs.
        (Its exit code went with the server.)"""
        pidfd = self._pidfds.get(pid)
        if pidfd is not None and not _readable(pidfd, 0.0):
            return None
        self._exits[pid] = -signal.SIGKILL
        return self._exits[pid]


def _readable(fd: int | socket.socket, timeout: float | None) -> bool:
    with selectors.DefaultSelector() as sel:
        sel.register(fd, selectors.EVENT_READ)
        return bool(sel.select(timeout))


# --- the server's side (runs in ``python -m cli.forkserver``) ---


def serve(sock: socket.socket) -> dict[str, Any] | None:
    """Answer requests until the supervisor closes the socket (returns None); in a forked child, return its
    request, with the child set up to run it (``become``)."""
    # Ctrl-C or a SIGTERM to the whole process group is the supervisor's to handle: the server keeps reporting
    # exits while the robots end their own way (it ends when the socket closes, or with its supervisor).
    # Blocked as well as ignored: a child inherits both, and until ``become`` gives it its own it would discard
    # a signal that is ignored; one that is blocked waits for it. A robot the supervisor stopped just after it
    # was forked ignored that SIGTERM and was SIGKILLed 5 s later (3 of 6 stopped so, measured).
    signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
    for signum in STOP_SIGNALS:
        signal.signal(signum, signal.SIG_IGN)
    children: dict[int, int] = {}
    with selectors.DefaultSelector() as sel:
        sel.register(sock, selectors.EVENT_READ, None)
        while True:
            for key, _ in sel.select():
                if key.data is not None:
                    _report_exit(sock, sel, children, key.data)
                    continue
                data = sock.recv(PACKET_BYTES)
                if not data:
                    return None
                request = _request(data)
                if isinstance(request, str):
                    _answer(sock, {"refused": request})
                    continue
                try:
                    log = os.open(request["log"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
                except OSError as err:
                    _answer(sock, {"refused": f"cannot open its log: {err}"})
                    continue
                try:
                    pid = os.fork()
                except OSError as err:  # out of processes or memory: this robot, not the others
                    os.close(log)
                    _answer(sock, {"refused": f"cannot fork: {err}"})
                    continue
                if pid == 0:  # the child: nothing of the server's stays open in it
                    for fd in children.values():
                        os.close(fd)
                    sock.close()
                    return {**request, "log_fd": log}
                os.close(log)
                _watch(sock, sel, children, pid)


def become(request: dict[str, Any], server_pid: int) -> list[str]:
    """In a freshly forked child: take on the robot's log, environment, directory, signals and command line;
    returns the argv to run. Exits at once if the server died before the parent-death signal was armed."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(request["deathsig"]))
    if os.getppid() != server_pid:
        os._exit(1)
    for signum in (signal.SIGTERM, signal.SIGHUP, signal.SIGCHLD):
        signal.signal(signum, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)  # what came since the fork acts now
    log = int(request["log_fd"])
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    os.dup2(log, 1)
    os.dup2(log, 2)
    os.close(log)
    os.close(null)
    os.chdir(request["cwd"])
    os.environ.clear()
    os.environ.update(request["env"])
    argv: list[str] = request["argv"]
    if not retitle(title(argv)):
        print("fork server: could not write this robot's command line; petswarm chaos will not know it", flush=True)
    sys.argv = [sys.argv[0], *argv]
    return argv


def retitle(cmdline: bytes) -> bool:
    """Write ``cmdline`` over this process's own command line, NUL-padded to its end (what /proc/<pid>/cmdline
    and ps show); False if it does not fit or /proc does not say where it is."""
    try:
        fields = stat_fields()
        start, end = int(fields[45]), int(fields[46])  # arg_start, arg_end: fields 48 and 49 of proc(5)
    except (OSError, ValueError, IndexError):
        return False
    if len(cmdline) > end - start:
        return False
    ctypes.memmove(start, cmdline.ljust(end - start, b"\0"), end - start)
    return True


def _request(data: bytes) -> dict[str, Any] | str:
    """A request checked for shape, or why it is refused."""
    try:
        request = json.loads(data)
    except (ValueError, RecursionError) as err:
        return f"not JSON: {err}"
    fields = {"argv": list, "log": str, "env": dict, "cwd": str, "deathsig": int}
    if not isinstance(request, dict) or any(not isinstance(request.get(k), t) for k, t in fields.items()):
        return f"a request needs {sorted(fields)}"
    if not all(isinstance(a, str) for a in request["argv"]) or not request["argv"]:
        return "argv must be a non-empty list of strings"
    if not all(isinstance(k, str) and isinstance(v, str) for k, v in request["env"].items()):
        return "env must map strings to strings"
    if "\0" in request["log"] or "\0" in request["cwd"]:
        return "a path with a NUL in it"
    if request["deathsig"] not in signal.valid_signals():
        return f"no such signal: {request['deathsig']}"
    return request


def _watch(sock: socket.socket, sel: selectors.BaseSelector, children: dict[int, int], pid: int) -> None:
    """Learn of a new child's end through its pidfd; one that cannot be watched is ended, not left unseen."""
    try:
        children[pid] = os.pidfd_open(pid)
    except OSError as err:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        _answer(sock, {"refused": f"cannot watch it: {err}"})
        return
    sel.register(children[pid], selectors.EVENT_READ, pid)
    _answer(sock, {"spawned": pid})


def _report_exit(sock: socket.socket, sel: selectors.BaseSelector, children: dict[int, int], pid: int) -> None:
    fd = children.pop(pid)
    sel.unregister(fd)
    os.close(fd)
    _, status = os.waitpid(pid, 0)
    _answer(sock, {"exited": pid, "code": os.waitstatus_to_exitcode(status)})


def _answer(sock: socket.socket, answer: dict[str, Any]) -> None:
    with contextlib.suppress(OSError):  # the supervisor left: the next recv sees it
        sock.send(json.dumps(answer).encode())
