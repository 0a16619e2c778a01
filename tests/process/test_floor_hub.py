"""``petswarm hub --floor``, the floor ``petswarm bench hub --floor`` measures: real hub and robot processes.

It carries every frame at once to the nodes it is addressed to and models nothing, so the air log stays empty; a
frame still reaches only its PAN and address, and whatever is not a robot's frame is the hub's as always."""

from __future__ import annotations

import subprocess
import sys

import pytest

from ..conftest import ROOT

pytestmark = pytest.mark.process


def test_the_floor_hub_carries_frames_to_their_address_and_models_nothing(make_air):
    air = make_air(hub_args=["--floor"])
    air.robot(1, (0.0, 0.0))
    air.robot(2, (500.0, 0.0))  # far beyond any radio range: the floor knows no range
    air.robot(3, (1.0, 0.0), 0x2000)  # another PAN
    assert air.heard(1, {2}, dst=2, wait=0.5) == {2}
    assert air.heard(1, {2}, wait=0.5) == {2}  # a broadcast: robot 3's PAN never hears it
    stats = air.stats()
    assert stats["hub"]["carried"] >= 2
    assert stats["nodes"]["robot-3"]["heard"] == 0
    assert stats["nodes"]["robot-2"]["delivered"] >= 1 and stats["nodes"]["robot-1"]["sent"] >= 2
    assert [t for t in air.air_log() if t["type"] == "data"] == []  # nothing went through the medium
    assert set(air.close().values()) == {0}


def test_the_floor_hub_has_no_lockstep_time():
    argv = [sys.executable, "-m", "cli", "hub", "--floor", "--clock", "lockstep", "--listen", "tcp/127.0.0.1:1"]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert done.returncode == 2 and "--floor" in done.stderr and "--clock wall" in done.stderr
