"""``petswarm watch`` stops cleanly on SIGTERM (and so on Ctrl-C, the same handler): exit 0, no traceback,
live (waiting for a hub that is not there) and replaying a record. No browser needed."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from petswarm.lab.processes import free_tcp_port

from .world_samples import write_record

pytestmark = pytest.mark.process


def _stopped_by(sig: signal.Signals, *args: str) -> tuple[int, str]:
    """Start ``petswarm watch ARGS --port 0``, wait until it serves, send ``sig``; its exit code and stderr."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "cli", "watch", "--port", "0", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        line, deadline = "", time.monotonic() + 30
        while "watch: http://" not in line and time.monotonic() < deadline and proc.poll() is None:
            line = proc.stdout.readline()
        assert "watch: http://" in line, proc.communicate(timeout=10)
        time.sleep(0.5)  # let the feed get going (the live one is trying to reach its hub)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=20)
        return proc.returncode, err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_replaying_watch_stops_cleanly(tmp_path: Path, sig: signal.Signals) -> None:
    record = write_record(tmp_path / "run", frames=20, robots=3)
    code, err = _stopped_by(sig, "--replay", str(record))
    assert code == 0 and "Traceback" not in err, err


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_live_watch_stops_cleanly(sig: signal.Signals) -> None:
    nobody = f"tcp/127.0.0.1:{free_tcp_port()}"  # no hub listens there: the watcher keeps waiting for one
    code, err = _stopped_by(sig, "--hub", nobody, "--world", "nowhere")
    assert code == 0 and "Traceback" not in err, err


def test_a_live_watch_connected_to_a_hub_stops_cleanly(make_air) -> None:
    air = make_air()
    code, err = _stopped_by(signal.SIGTERM, "--hub", air.endpoint, "--world", air.world)
    assert code == 0 and "Traceback" not in err, err
