"""A child of a supervisor dies with it even when the supervisor died before the child had armed its
parent-death signal (``petswarm.lab.processes._die_with_parent``)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.timeout(60)

SUPERVISOR = textwrap.dedent(
    """
    import signal, subprocess, time
    from petswarm.lab.processes import _die_with_parent

    arm = _die_with_parent(signal.SIGTERM)  # what a hub gets when its supervisor dies

    def late():  # a child the machine is slow to run: its supervisor dies before it arms the signal
        time.sleep(2.0)
        arm()

    subprocess.Popen(["sleep", "60"], preexec_fn=late)
    """
)


def _children_of(pid: int) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
            found.append(int(entry.name))
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_a_child_whose_supervisor_died_before_it_armed_its_parent_death_signal_ends() -> None:
    supervisor = subprocess.Popen([sys.executable, "-c", SUPERVISOR])
    children: list[int] = []
    try:
        deadline = time.monotonic() + 20
        while not children and time.monotonic() < deadline:
            children = _children_of(supervisor.pid)
            time.sleep(0.01)
        assert children, "the supervisor started no child"
        supervisor.kill()  # SIGKILL while its child sleeps before arming: no signal will come from the kernel
        supervisor.wait(10)
        deadline = time.monotonic() + 10  # the child arms 2 s after its start, then must end at once
        while any(_alive(pid) for pid in children) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(_alive(pid) for pid in children), "the child outlived its supervisor"
    finally:
        supervisor.kill()
        for pid in children:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
