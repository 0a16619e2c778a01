"""How a hub process stops on a signal, within a deadline.

SIGINT and SIGTERM ask the hub to stop (its loop ends, it closes its files, then its zenoh session). The first
signal also starts a clock: a hub still alive ``SHUTDOWN_GRACE_S`` later writes where each of its threads is to
its stderr (its log) and ends at once. Why: a hub whose run was killed outright gets SIGTERM from the kernel
(``petswarm.lab.processes.parent_death_signal``) and nobody will follow with SIGKILL, so a close that never
returns (a zenoh session closing while its transports to robots killed at the same moment go down; seen twice
in CI, never reproduced on demand) would leave it behind for good. The run's files are written as they go, so
ending early loses nothing a reader needs.
"""

from __future__ import annotations

import faulthandler
import os
import signal
import sys
import threading
from typing import Protocol

SHUTDOWN_GRACE_S = 4.0
"""Wall seconds from the first stop signal to the forced end: under the 5 s a supervisor waits before SIGKILL
(``Supervisor.stop``), so the stack dump reaches the log first."""
EXIT_STUCK = 3
"""The exit status of a hub that had to be ended by its deadline."""


class Stoppable(Protocol):
    """A hub: ``stop`` asks its loop to end (safe from a signal handler)."""

    def stop(self) -> None:
        """Ask the loop to end."""


def stop_on_signals(hub: Stoppable, grace_s: float = SHUTDOWN_GRACE_S) -> None:
    """Install the SIGINT and SIGTERM handlers of a hub process (main thread only)."""
    deadline: list[threading.Timer] = []

    def on_signal(signum: int, _frame: object) -> None:
        hub.stop()
        if not deadline:
            timer = threading.Timer(grace_s, _end_stuck, (grace_s,))
            timer.daemon = True
            timer.start()
            deadline.append(timer)

    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, on_signal)


def _end_stuck(grace_s: float) -> None:
    print(f"hub: not stopped {grace_s:g} s after the signal; ending now. Where each thread was:", file=sys.stderr)
    sys.stderr.flush()
    faulthandler.dump_traceback(file=sys.stderr, all_threads=True)
    os._exit(EXIT_STUCK)


def end_closed(code: int = 0) -> None:
    """End a hub process whose hub has closed: flush its output and exit at once, without the interpreter's
    finalization.

    Why: a closed hub sometimes died in finalization with "FATAL: exception not rethrown" (exit -6, 2 of 75
    lockstep runs on a loaded machine). That is glibc's word for a thread ended by pthread_exit whose forced
    unwind was caught on the way, as it is in Rust frames; CPython ends that way a thread that takes the GIL
    while the interpreter finalizes, and zenoh's runtime threads outlive a closed session. Everything the hub
    writes is closed by then; nothing is left for finalization to do."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
