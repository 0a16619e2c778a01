"""Starting and stopping the OS processes of a run: no process outlives the run that started it."""

from __future__ import annotations

import contextlib
import ctypes
import os
import random
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import IO, Any, Protocol

from petswarm.lab.forking import ForkServer, ForkServerGone, can_fork_server, child_environment

_PR_SET_PDEATHSIG = 1
FORKED_COMMANDS = ("robot",)
"""The ``petswarm`` commands a Supervisor forks from its fork server (``petswarm.lab.forking``) rather than
starting anew: robots, the processes a run starts by the dozen."""


class ChildProcess(Protocol):
    """What the Supervisor needs of a child: ``subprocess.Popen`` or a forked ``ForkedProcess``."""

    pid: int
    returncode: int | None

    def poll(self) -> int | None: ...
    def wait(self, timeout: float | None = None) -> int: ...
    def send_signal(self, signum: int) -> None: ...
    def kill(self) -> None: ...


def _die_with_parent(signum: int) -> Callable[[], None]:
    """A preexec hook: on Linux the kernel sends ``signum`` to the child when the supervisor dies, even by
    SIGKILL (it survives exec, so also through a wrapper such as ``ip netns exec``).

    A supervisor that died between the fork and the arming sends nothing: the child, already someone else's,
    ends there (as ``petswarm.lab.forking.become`` does) rather than run for good (a hub waits for a signal)."""
    parent = os.getpid()

    def arm() -> None:
        arm_parent_death(signum, parent)

    return arm


def arm_parent_death(signum: int, parent: int) -> None:
    """In a child of ``parent``: have the kernel send ``signum`` when the parent dies (Linux), and end at once if
    it died already (the child, someone else's by then, would otherwise run for good)."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signum)
    if os.getppid() != parent:
        os._exit(1)


def parent_death_signal(name: str) -> int:
    """What a child gets when its supervisor dies: SIGTERM for the hub, so it closes its pcap and world log;
    SIGKILL for every other child, since a robot paused by ``petswarm chaos pause`` (SIGSTOP) cannot act on
    SIGTERM and would be left behind in state T (its events are flushed line by line: nothing is lost)."""
    return signal.SIGTERM if name == "hub" else signal.SIGKILL


EPHEMERAL_RANGE_FILE = Path("/proc/sys/net/ipv4/ip_local_port_range")
LISTEN_PORTS_SPAN = 16384
"""How many ports below the kernel's ephemeral range ``free_tcp_port`` draws from."""


def free_tcp_port() -> int:
    """A port on 127.0.0.1 nobody listens on right now, for a hub to listen on a moment later.

    Drawn below the kernel's ephemeral range: a port the kernel hands out for ``bind(0)`` is one it also hands
    out as the source port of any outgoing connection, so between our check and the hub's listen another
    process's zenoh client could take it ("Address already in use": 1 of 6 runs started at once, measured).
    The draw is not from the run's seed: which port a hub listens on is no part of what a run does."""
    low = _ephemeral_low()
    start = max(1024, low - LISTEN_PORTS_SPAN)
    draw = random.SystemRandom()
    for _ in range(64 if start < low else 0):
        port = draw.randrange(start, low)
        with socket.socket() as sock, contextlib.suppress(OSError):
            sock.bind(("127.0.0.1", port))
            return port
    with socket.socket() as sock:  # that span is full (or the range starts low): any port the kernel gives
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _ephemeral_low() -> int:
    """The first port of the kernel's ephemeral range (Linux's default 32768 where it cannot be read)."""
    try:
        return int(EPHEMERAL_RANGE_FILE.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768


def _wait_all(procs: Iterable[ChildProcess], within_s: float) -> None:
    """Wait for each to end, all within one deadline."""
    deadline = time.monotonic() + within_s
    for proc in procs:
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(max(deadline - time.monotonic(), 0.05))


KILLED_WITHIN_S = 5.0
"""How long a stop waits for a child's exit code after its SIGKILL. A killed process ends at once, but the code
of a forked robot comes from its fork server, and a server that is stopped (SIGSTOP) or wedged never sends it:
the stop waited for ever and the run never wrote its summary."""


class Supervisor:
    """Owns child processes running ``petswarm`` subcommands; ``stop_all`` ends every one of them."""

    def __init__(self, log_dir: Path, fork: bool = True) -> None:
        self.log_dir = log_dir
        log_dir.mkdir(parents=True, exist_ok=True)
        self.children: dict[str, ChildProcess] = {}
        self._fork = fork and can_fork_server()
        """Whether robots come from a fork server (started at the first robot)."""
        self._server: ForkServer | None = None
        self._logs: dict[str, IO[bytes]] = {}
        self._accounted: set[str] = set()
        """Children whose end is known: stopped here, or already reported by ``unexpected_deaths``."""

    def spawn(self, name: str, args: list[str], wrapper: Sequence[str] = ()) -> ChildProcess:
        """Start ``petswarm <args>`` as a child; its stdout and stderr go to ``<log_dir>/<name>.log``.

        ``wrapper`` runs it inside another command that execs it, e.g. ``ip netns exec NS`` (another host).
        A robot is forked from the fork server when it can be, else started as any other command.
        """
        if not wrapper and args[:1] and args[0] in FORKED_COMMANDS and self._fork:
            forked = self._spawn_forked(name, args)
            if forked is not None:
                return forked
        return self.spawn_module(name, "cli", args, wrapper)

    def _spawn_forked(self, name: str, args: list[str]) -> ChildProcess | None:
        env = child_environment()
        if self._server is None:
            log = open(self.log_dir / "forkserver.log", "wb")  # noqa: SIM115 - closed in stop_all
            self._logs["forkserver"] = log
            self._server = ForkServer(log, _die_with_parent(signal.SIGKILL))
        if not self._server.fits(args, env):
            return None
        try:
            child = self._server.spawn(args, self.log_dir / f"{name}.log", env, parent_death_signal(name))
        except ForkServerGone as err:
            print(f"petswarm: starting {name} without the fork server: {err}", file=sys.stderr)
            return None
        self.children[name] = child
        return child

    def spawn_module(
        self, name: str, module: str, args: list[str], wrapper: Sequence[str] = ()
    ) -> subprocess.Popen[bytes]:
        """Start ``python -m <module> <args>`` as a child, logged and stopped like ``spawn``'s."""
        log = open(self.log_dir / f"{name}.log", "wb")  # noqa: SIM115 - closed in stop_all
        proc = subprocess.Popen(
            [*wrapper, sys.executable, "-m", module, *args],
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=subprocess.STDOUT,
            preexec_fn=_die_with_parent(parent_death_signal(name)),
            env=child_environment(),
        )
        self.children[name] = proc
        self._logs[name] = log
        return proc

    def dead(self) -> dict[str, int]:
        """Children that have exited, with their exit codes."""
        return {name: p.returncode for name, p in self.children.items() if p.poll() is not None}

    def unexpected_deaths(self) -> dict[str, int]:
        """Children that exited since the last call without being stopped here, with their exit codes
        (negative: the signal that killed them); each is reported once."""
        deaths = {name: code for name, code in self.dead().items() if name not in self._accounted}
        self._accounted.update(deaths)
        return deaths

    def log_tail(self, name: str, lines: int = 15) -> str:
        """The last lines a child wrote."""
        path = self.log_dir / f"{name}.log"
        text = path.read_text(errors="replace") if path.exists() else ""
        return "\n".join(text.splitlines()[-lines:])

    def stop(
        self, names: list[str], timeout: float = 5.0, killed_within_s: float = KILLED_WITHIN_S
    ) -> dict[str, int | None]:
        """SIGTERM the named children, SIGKILL any still alive after ``timeout``; returns exit codes (None: not
        known ``killed_within_s`` after the SIGKILL, said on stderr).

        A paused child (``petswarm chaos pause``) is continued first: a stopped process keeps SIGTERM pending."""
        procs = {n: self.children[n] for n in names if n in self.children}
        self._accounted.update(procs)
        for proc in procs.values():
            if proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    proc.send_signal(signal.SIGCONT)
                proc.send_signal(signal.SIGTERM)
        _wait_all(procs.values(), timeout)
        overdue = [proc for proc in procs.values() if proc.poll() is None]
        for proc in overdue:
            proc.kill()
        _wait_all(overdue, killed_within_s)  # one deadline for all: a wedged fork server costs it once, not per robot
        for name, proc in procs.items():
            if proc.returncode is None:
                print(f"petswarm: no exit code for {name} {killed_within_s:g} s after its SIGKILL", file=sys.stderr)
            log = self._logs.pop(name, None)
            if log is not None:
                log.close()
        return {n: p.returncode for n, p in procs.items()}

    def stop_all(self, timeout: float = 5.0) -> dict[str, int | None]:
        """Stop every child: robots first, so the hub sees them leave, then the rest."""
        order = sorted(self.children, key=lambda n: n == "hub")
        codes: dict[str, int | None] = {}
        robots = [n for n in order if n != "hub"]
        codes.update(self.stop(robots, timeout))
        codes.update(self.stop([n for n in order if n == "hub"], timeout))
        if self._server is not None:
            self._server.close(timeout)
            self._server = None
            self._logs.pop("forkserver").close()
        return codes


HARD_EXIT_SIGINTS = 3
"""Ctrl-Cs (SIGINT) after which a process that is stopping its children ends at once (``Interrupts``)."""


class Interrupts:
    """The stop signals of a process that stops its children and writes down how they ended when it is
    interrupted (``petswarm run`` on every clock, the benches).

    From its creation the first SIGINT or SIGTERM raises KeyboardInterrupt (SIGTERM unwinds as Ctrl-C does), so
    that ``finally`` blocks stop the children; every later one is only noted. ``deferred()``, the first thing in
    that ``finally``, makes a first one only noted too until it ends; then, in a run no signal touched, every
    handler is back as it was before ``Interrupts()`` (an experiment's next run takes them), and a signal noted
    in a run no signal had interrupted raises KeyboardInterrupt. Once a signal came the process is on its way
    out with status 130, and later ones stay only noted: handed back, a second Ctrl-C 30-60 ms after the first
    raised KeyboardInterrupt on the way out (exit -2, not 130) or inside an experiment's save of its results.

    Why: a second Ctrl-C, or ``timeout`` or compose following its SIGTERM with SIGINT, raised KeyboardInterrupt
    inside that ``finally`` while it stopped the children and wrote the record: the stop was cut short and
    summary.json was left saying ``running``, without the children's exit codes. The stop is bounded
    (``Supervisor.stop``: SIGKILL after its timeout), and SIGKILL still ends the process at once. A SIGINT that
    whoever started the process ignored (nohup) stays ignored.

    A person's third Ctrl-C (``HARD_EXIT_SIGINTS``) ends the process at once, as many command-line tools do: a
    stop that waits on something (a robot's answer, up to a minute for an organize) is theirs to cut short. The
    children go with it (their parent-death signal); the record keeps what it had. SIGTERMs never add up to
    that: a process manager may send several, and means the stop to be whole.

    ``at_safe_points``: the first signal is only made pending, and ``check()`` raises it where the caller polls
    (a model-time loop, once per pass). A handler's KeyboardInterrupt lands wherever the main thread is, and
    where that is a weakref callback or a ``__del__`` Python prints "Exception ignored" and drops it: the signal
    was spent, every later one only noted, and the run went on. A model run drops a weakref per timer it fires,
    and an experiment in CI ran on after its SIGINT until the test's minute was up. Without ``at_safe_points``
    (a run of processes, whose main thread may block on a robot's answer for a minute and must be interrupted
    there) the handler still raises where it lands, and ``check()``, called from the run's own loop, raises
    again a first signal whose KeyboardInterrupt never reached it."""

    def __init__(self, at_safe_points: bool = False) -> None:
        self.noted: list[int] = []
        self.pending = False
        """A first signal that ``check()`` has not raised yet (``at_safe_points``)."""
        self._at_safe_points = at_safe_points
        self._raised = False
        self._raised_by_sigint = 0
        self._stopping = False
        self._stop_began = False
        """In or past ``deferred()``: the KeyboardInterrupt has done its work (or none came)."""
        self._previous: dict[int, Any] = {}
        if threading.current_thread() is not threading.main_thread():
            return  # only the main thread may take signals: a run in a host's worker thread (a Dask worker) leaves
            # the host's own handling alone
        for signum in (signal.SIGINT, signal.SIGTERM):
            current = signal.getsignal(signum)
            if current not in (signal.SIG_IGN, None):  # None: a handler not set from Python, not ours to replace
                self._previous[signum] = signal.signal(signum, self._on_signal)

    def _on_signal(self, signum: int, _frame: Any) -> None:
        # runs between any two bytecodes of the main thread: no locks, no I/O but a plain write(2)
        if self._stopping:
            self.noted.append(signum)
            if self.noted.count(signal.SIGINT) + self._raised_by_sigint >= HARD_EXIT_SIGINTS:
                os.write(2, b"\npetswarm: third Ctrl-C: ending now, without waiting for the stop\n")
                os._exit(130)
            return
        self._raised_by_sigint = int(signum == signal.SIGINT)
        self._stopping = True
        if self._at_safe_points:
            self.pending = True
            return
        self._raised = True
        raise KeyboardInterrupt

    def release(self) -> None:
        """Hand the signals back to the handlers from before ``Interrupts()`` (``deferred`` does when no signal
        came; a process that goes on after an interrupted run, such as a test, does it itself)."""
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)

    def check(self) -> None:
        """A safe point of the run's own loop: raise the first signal's KeyboardInterrupt here when it is
        pending (``at_safe_points``), or when the handler raised it and yet the loop goes on (it was lost)."""
        if self.pending or (self._raised and not self._stop_began):
            self.pending = False
            self._raised = True
            raise KeyboardInterrupt

    @contextlib.contextmanager
    def deferred(self) -> Iterator[None]:
        """Signals only noted within the block; after it, the handlers from before ``Interrupts()`` if no signal
        came at all (else they stay noted: the process is ending), and KeyboardInterrupt if a signal came within
        it, or is still pending, and none had been raised."""
        self._stopping = self._stop_began = True
        try:
            yield
        finally:
            if not (self._raised or self.pending or self.noted):
                self.release()
        if (self.noted or self.pending) and not self._raised:
            self.pending = False
            self._raised = True
            raise KeyboardInterrupt


def run_supervised(
    out: Path, body: Callable[[Supervisor], dict[str, Any]], failures: tuple[type[Exception], ...]
) -> dict[str, Any] | int:
    """Run a bench's ``body`` with a Supervisor logging to ``out/logs``; every child is stopped at the end.

    Returns the body's results with ``elapsed_s`` added, or an exit code: 1 on one of ``failures``,
    130 on Ctrl-C or SIGTERM.
    """
    sup = Supervisor(out / "logs")
    interrupts = Interrupts()
    started = time.monotonic()
    try:
        results = body(sup)
    except failures as err:
        _progress(f"failed: {err}")
        return 1
    except KeyboardInterrupt:
        _progress("interrupted; stopping every process")
        return 130
    finally:
        with interrupts.deferred():  # a second Ctrl-C or SIGTERM waits for the stop (Interrupts)
            codes = sup.stop_all()
            _progress(f"stopped {len(codes)} processes in total; logs in {out / 'logs'}")
    results["elapsed_s"] = time.monotonic() - started
    return results


def _progress(text: str) -> None:
    print(f"[bench] {text}", file=sys.stderr, flush=True)
