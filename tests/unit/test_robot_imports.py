"""A robot process imports only what a robot uses: no plotting, no web stack, not the hub's side (issue 14).

Each check runs in a fresh interpreter, as a robot process starts, and lists what ``sys.modules`` holds.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

NOT_ON_A_ROBOT = (
    "matplotlib",  # plots: reports and benches
    "aiohttp",  # the live view's web server
    "websockets",
    "http.server",
    "cli.watch",
    "cli.report",
    "numpy.random",  # petswarm.draws gives a robot numpy's draws
    "radio_hub.medium",  # the hub's side of the air
    "radio_hub.coordinator",
    "radio_hub.environment",
    "radio_hub.world",
)

ROBOT_ENTRIES = {
    "robot middleware": "import petswarm.robot",
    "robot process (wall clock)": "import cli.main; import petswarm.robot",
    "robot process (lockstep)": "import cli.main; import petswarm.robot; import cli.lockstep_node",
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
    assert {"petswarm.robot", "zenoh", "radio_hub.port"} <= loaded_after("import petswarm.robot")


LEAN_ROBOT = (
    "import sys\n"
    "from cli.lean import leave_out_openssl\n"
    "assert leave_out_openssl(['robot', '--id', '3'])\n"
    "import cli.main, petswarm.robot, cli.lockstep_node, asyncio, hashlib\n"
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
