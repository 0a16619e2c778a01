"""What /proc says of a live test process."""

from __future__ import annotations

import os
from pathlib import Path

FLOOD_RSS_BOUND_MB = 60
"""What 2,000 x 100 kB messages on a robot's downlink may add to its peak resident memory, wall-clock
(tests/process/test_hostile.py) or lockstep (tests/process/test_lockstep.py): about 42 MB with the link's bounds;
without them 200-275 MB, never freed."""


def peak_rss_mb(pid: int) -> float:
    """The process's peak resident memory (VmHWM) in MB."""
    return _status_mb(pid, "VmHWM")


def rss_mb(pid: int) -> float:
    """The process's resident memory now (VmRSS) in MB."""
    return _status_mb(pid, "VmRSS")


def _status_mb(pid: int, field: str) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(f"{field}:"):
            return int(line.split()[1]) / 1024
    raise AssertionError(f"no {field} for {pid}")


def cpu_seconds(pid: int) -> float:
    """The process's CPU time so far, user and system, all threads (/proc/<pid>/stat)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
