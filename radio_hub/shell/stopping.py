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
import queue
import signal
import sys
import threading
import time
from typing import Protocol

SHUTDOWN_GRACE_S = 4.0
"""Wall seconds from the first stop signal to the forced end: under the 5 s a supervisor waits before SIGKILL
(``Supervisor.stop``), so the stack dump reaches the log first."""
EXIT_STUCK = 3
"""The exit status of a hub that had to be ended by its deadline."""


class Stoppable(Protocol):
    """A hub: ``stop`` asks its loop to end (from any thread)."""

    def stop(self) -> None:
        """Ask the loop to end."""


def stop_on_signals(hub: Stoppable, grace_s: float = SHUTDOWN_GRACE_S) -> None:
    """Install the SIGINT and SIGTERM handlers of a hub process (main thread only).

    The handler only queues the signal; a thread of its own stops the hub and keeps the deadline. Why: a Python
    handler runs on the main thread between any two of its bytecodes, also while that thread holds a lock of
    its own (inside ``queue.Queue.get`` or ``Event.set``). A handler that called ``hub.stop()`` there took the
    same lock again and waited for itself for good, before its deadline was set: a hub whose run was killed
    outright was found so, alive twenty minutes later. ``SimpleQueue.put`` is reentrant."""
    signals: queue.SimpleQueue[int] = queue.SimpleQueue()

    def on_signal(signum: int, _frame: object) -> None:
        signals.put(signum)

    stopper = threading.Thread(target=_stop_when_signalled, args=(hub, signals, grace_s), name="hub-stopper")
    stopper.daemon = True
    stopper.start()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, on_signal)


def _stop_when_signalled(hub: Stoppable, signals: queue.SimpleQueue[int], grace_s: float) -> None:
    """The first signal stops the hub and starts the clock; later ones change neither."""
    signals.get()
    deadline = time.monotonic() + grace_s
    hub.stop()
    time.sleep(max(0.0, deadline - time.monotonic()))
    _end_stuck(grace_s)  # the process ends (os._exit) before this when the hub closed in time


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
