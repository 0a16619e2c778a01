"""A robot process imports only what a robot uses: no plotting, no web stack, not the hub's side (issue 14).

Each check runs in a fresh interpreter, as a robot process starts, and lists what ``sys.modules`` holds.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

NOT_ON_A_ROBOT = (
    "matplotlib",  # plots: reports and benches
    "aiohttp",  # the live view's web server
    "websockets",
    "http.server",
    "petswarm.lab.watch",
    "petswarm.lab.report",
    "numpy.random",  # petswarm.draws gives a robot numpy's draws
    "radio_hub.air.medium",  # the hub's side of the air
    "radio_hub.coordinator",
    "radio_hub.environment",
    "radio_hub.physics.world",
    "importlib.metadata",  # the installed version, for --version only: 40-100 ms of CPU in every process that read it
)

ROBOT_ENTRIES = {
    "robot middleware": "import petswarm.robot",
    "robot process (wall clock)": "import cli.main; import petswarm.robot",
    "robot process (lockstep)": "import cli.main; import petswarm.robot; import petswarm.lab.lockstep_node",
    "robot command line read": (
        "import cli.main\nfrom petswarm.lab.robot_command import robot_config\n"
        "robot_config(cli.main.robot_options(cli.main.build_parser().parse_args(['robot', '--id', '3'])))"
    ),
}


def loaded_after(code: str) -> set[str]:
    """The modules a fresh interpreter holds after running ``code`` (not those marked absent)."""
    probe = f"{code}\nimport json, sys\nprint(json.dumps(sorted(k for k, v in sys.modules.items() if v is not None)))"
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, check=True)
    return set(json.loads(done.stdout.splitlines()[-1]))


@pytest.mark.parametrize("entry", ROBOT_ENTRIES)
def test_a_robot_process_does_not_load_plotting_web_or_hub_modules(entry: str) -> None:
    loaded = loaded_after(ROBOT_ENTRIES[entry])
    unwanted = sorted(m for m in loaded if any(m == bad or m.startswith(bad + ".") for bad in NOT_ON_A_ROBOT))
    assert unwanted == [], f"{entry} loads {unwanted}"


def test_the_probe_sees_a_module_that_is_loaded() -> None:
    """The check above could pass vacuously if the probe saw nothing: it must see what is imported."""
    assert {"petswarm.robot", "zenoh", "radio_hub.link.port"} <= loaded_after("import petswarm.robot")


LEAN_ROBOT = (
    "import sys\n"
    "from cli.lean import leave_out_openssl\n"
    "assert leave_out_openssl(['robot', '--id', '3'])\n"
    "import cli.main, petswarm.robot, petswarm.lab.lockstep_node, asyncio, hashlib\n"
    "assert asyncio.run(asyncio.sleep(0, 'ran')) == 'ran'\n"
    "assert hashlib.sha256(b'x').hexdigest().startswith('2d711642')\n"
)


def test_a_robot_process_leaves_out_openssl_and_still_runs_asyncio_and_hashes() -> None:
    loaded = loaded_after(LEAN_ROBOT)
    assert {"ssl", "_ssl", "_hashlib"}.isdisjoint(loaded)
    assert {"asyncio", "petswarm.robot", "hashlib"} <= loaded


def test_other_commands_keep_openssl() -> None:
    """The hub, runs and benches may need TLS or OpenSSL's hashes: only robot processes go without."""
    loaded = loaded_after("from cli.lean import leave_out_openssl\nassert not leave_out_openssl(['hub'])\nimport ssl")
    assert "_ssl" in loaded


PLAIN_ROBOT = (
    "import sys\n"
    "from cli.lean import leave_out_openssl\n"
    "argv = ['robot', '--id', '3']\n"
    "assert leave_out_openssl(argv)\n"
    "import cli.main, petswarm.robot, petswarm.lab.lockstep_node\n"
    "from petswarm.lab.robot_command import robot_config\n"
    "config = robot_config(cli.main.robot_options(cli.main.build_parser().parse_args(argv)))\n"
    "from petswarm.controllers.driving_core import CONTROL_PERIOD_S, DriverCore\n"
    "from petswarm.managers.event_log import EventLog\n"
    "from petswarm.managers.sequence import SequenceManager\n"
    "from radio_hub.interface import OwnSensors\n"
    "class Formation:\n"
    "    swarm = None\n"
    "    me = 3\n"
    "class Fixes:\n"
    "    table = {}\n"
    "def ring():\n"
    "    import numpy\n"
    "    return numpy.linspace(0.0, 6.28, 8, endpoint=False)\n"
    "core = DriverCore(3, SequenceManager(EventLog()), Formation(), Fixes(), now=0.0)\n"
    "core.start(0.0)\n"
    "ticks = 0\n"
    "for k in range(1, 76):  # 3 s of the hub's 25 Hz sensors, as they come off the air\n"
    "    t = k * 0.04\n"
    "    core.sensors_sample(OwnSensors.of_wire(int(t * 1e6), bytes(32), ring, 0.0, (0.0, 0.0, 0.0)), t)\n"
    "    while (when := core.next_timer()) is not None and when <= t:\n"
    "        core.handle_timer(when)\n"
    "        ticks += len(core.actions())\n"
    "assert ticks > 3 / CONTROL_PERIOD_S, ticks  # the control loop ran: a Drive every period at least\n"
)


def test_a_plain_robot_imports_no_numpy_until_it_needs_it() -> None:
    """The middleware's modules take numpy lazily: read its command line, build its middleware and step its
    driver through 3 s of own-body sensors, and numpy is still not loaded (so the CLI's other commands go
    without it; a robot process itself loads it as it starts, the test at the end of this file)."""
    loaded = loaded_after(PLAIN_ROBOT)
    assert {"petswarm.robot", "petswarm.controllers.driving_core", "radio_hub.link.port"} <= loaded
    assert sorted(m for m in loaded if m == "numpy" or m.startswith("numpy.")) == []


def test_numpy_comes_in_when_a_robot_estimates_or_reads_its_echoes() -> None:
    """The lazy numpy is numpy: an IR estimate and the echoes' ranges load it and compute as before."""
    code = (
        PLAIN_ROBOT
        + "assert 'numpy' not in sys.modules\n"
        + "import petswarm.controllers.driving_core as driving_core\n"
        + "import petswarm.managers.ir_estimator as ir_estimator\n"
        + "from radio_hub.physics.light import IrConfig\n"
        + "fix = ir_estimator.estimate([0.0] * 3 + [300.0] + [0.0] * 8, IrConfig(), 'paper')\n"
        + "assert fix is not None and abs(fix.bearing_rad - 3.14159265 / 2) < 1e-6, fix\n"
        + "import numpy\n"
        + "assert ir_estimator.np is numpy  # the first use put the real module in place\n"
        + "ranges = driving_core.EchoRanges().ranges(core.sensors)\n"
        + "assert [r for _, r in ranges.readings] == [0.0] * 8, ranges\n"
    )
    assert "numpy" in loaded_after(code)


def test_a_robot_process_has_numpy_before_it_looks_for_its_hub() -> None:
    """numpy comes in as a robot process starts, not with its first IR sweep: loaded there it held the loop
    inside the join handshake (a second on a loaded machine) and the master gave the robot up as missing.
    A real robot process with no hub to find: every import it made is on record before it says it waits."""
    from petswarm.lab.processes import free_tcp_port

    argv = ["robot", "--id", "3", "--hub", f"tcp/127.0.0.1:{free_tcp_port()}", "--world", "no-hub-here"]
    proc = subprocess.Popen(
        [sys.executable, "-X", "importtime", "-m", "cli", *argv], stderr=subprocess.PIPE, text=True, cwd=ROOT
    )
    lines: list[str] = []
    try:
        assert proc.stderr is not None
        for line in proc.stderr:
            if "waiting for a hub" in line:
                break
            lines.append(line)
    finally:
        proc.kill()
        proc.wait(timeout=30)
    imported = {line.rsplit("|", 1)[-1].strip() for line in lines if line.startswith("import time:")}
    assert "zenoh" in imported, lines[-5:]  # the record is the robot's own imports
    assert "numpy._core.multiarray" in imported, sorted(m for m in imported if m.startswith("numpy"))[:5]


def test_a_runs_orchestrator_does_not_load_the_robot_middleware() -> None:
    """``petswarm run`` on the wall or lockstep clock starts robots as processes: its own process needs their
    waiting PAN, not their middleware (about 90 ms of CPU at every run's start)."""
    assert "petswarm.robot" not in loaded_after("import petswarm.lab.run")
