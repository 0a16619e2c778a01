"""A hub process stops on SIGTERM, and never outlives its stop by more than ``SHUTDOWN_GRACE_S``
(radio_hub/shell/stopping.py): a run killed outright leaves its hub only SIGTERM, and nobody follows with SIGKILL."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from petswarm.lab.processes import free_tcp_port
from radio_hub.shell.stopping import EXIT_STUCK, SHUTDOWN_GRACE_S

pytestmark = pytest.mark.process
ROOT = Path(__file__).resolve().parents[2]

STUCK_HUB = """
import threading, time
from radio_hub.shell.stopping import stop_on_signals

class StuckHub:
    def stop(self):  # asked to stop, its loop never ends (as a close that hangs in zenoh)
        pass

stop_on_signals(StuckHub())
print("ready", flush=True)
threading.Event().wait()  # the main thread blocked for good, as in a close that never returns
"""

SIGNALLED_AGAIN_HUB = """
import os, signal, threading
from radio_hub.shell.stopping import stop_on_signals

class Hub:
    def __init__(self):
        self.lock = threading.Lock()  # as the locks a real hub's stop takes (Event.set, Queue.put)
        self.stopped = threading.Event()

    def stop(self):
        with self.lock:
            if not self.stopped.is_set():
                os.kill(os.getpid(), signal.SIGTERM)  # a second signal while stop holds its lock
                self.stopped.set()

hub = Hub()
stop_on_signals(hub)
print("ready", flush=True)
while not hub.stopped.wait(0.01):  # the main thread in and out of a lock, as the hub's loop in its inbox
    pass
print("stopped", flush=True)
os._exit(0)
"""


def _ready(proc: subprocess.Popen[str], word: str) -> None:
    assert proc.stdout is not None
    line = proc.stdout.readline()
    assert word in line, (line, proc.stderr.read() if proc.stderr else "")


def test_a_hub_asked_to_stop_ends_at_once_with_status_0() -> None:
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    argv = [sys.executable, "-m", "cli", "hub", "--listen", endpoint, "--world", "stopping"]
    hub = subprocess.Popen(argv, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _ready(hub, "hub_ready")
        hub.send_signal(signal.SIGTERM)
        assert hub.wait(timeout=30) == 0  # it stopped by itself: its deadline would have ended it with EXIT_STUCK
    finally:
        hub.kill()
        hub.communicate()


def test_a_hub_that_cannot_stop_ends_by_its_deadline_and_says_where_it_was() -> None:
    stuck = subprocess.Popen(
        [sys.executable, "-c", STUCK_HUB], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        _ready(stuck, "ready")
        t = time.monotonic()
        stuck.send_signal(signal.SIGTERM)
        stuck.send_signal(signal.SIGTERM)  # a second signal does not restart the clock or end it early
        code = stuck.wait(timeout=SHUTDOWN_GRACE_S + 30)
        took = time.monotonic() - t
    finally:
        stuck.kill()
        _, err = stuck.communicate()
    assert code == EXIT_STUCK, err
    assert took > SHUTDOWN_GRACE_S - 0.5, took  # ended by the deadline, not by the signal
    assert "not stopped" in err and "Current thread" in err and "<string>" in err, err  # the stack dump


def test_a_second_signal_while_the_hub_stops_neither_deadlocks_nor_delays_it() -> None:
    """A signal handler runs on the main thread between any two bytecodes: one that stopped the hub itself took
    the hub's locks again while that thread held them (a killed run's hub was found so, hung for good)."""
    hub = subprocess.Popen(
        [sys.executable, "-c", SIGNALLED_AGAIN_HUB], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        _ready(hub, "ready")
        hub.send_signal(signal.SIGTERM)
        code = hub.wait(timeout=SHUTDOWN_GRACE_S + 30)
    finally:
        hub.kill()
        out, err = hub.communicate()
    assert code == 0 and "stopped" in out, (code, err)  # stopped by itself, not ended by the deadline
