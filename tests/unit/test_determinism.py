"""numpy held to its baseline float paths in every petswarm process (radio_hub/determinism.py).

Each check runs a fresh interpreter: the pin acts once, before numpy first loads.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys

import pytest

from radio_hub.determinism import DISPATCH_VARIABLE, X86_ABOVE_BASELINE

x86_only = pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"), reason="the pin is x86-64's")


def _python(code: str, **env: str) -> str:
    environ = {k: v for k, v in os.environ.items() if k != DISPATCH_VARIABLE}
    environ.update(env)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=environ, timeout=60)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


@x86_only
@pytest.mark.parametrize("first", ["cli.main", "petswarm.controllers.surround_improved", "radio_hub.environment"])
def test_importing_any_package_first_holds_numpy_to_its_baseline(first: str) -> None:
    out = _python(
        f"import {first}, numpy, os; from radio_hub.determinism import numeric_dispatch; "
        f"print(os.environ['{DISPATCH_VARIABLE}'], '|', numeric_dispatch())"
    )
    assert out == f"{X86_ABOVE_BASELINE} | []"


@x86_only
def test_a_users_own_setting_wins_and_the_pin_says_it_does_not_hold() -> None:
    out = _python(
        "import radio_hub.determinism as d, os; print(repr(os.environ[d.DISPATCH_VARIABLE]), d.pin_numeric_dispatch())",
        **{DISPATCH_VARIABLE: ""},
    )
    assert out == "'' False"


@x86_only
def test_numpy_loaded_before_petswarm_is_reported_not_pinned() -> None:
    out = _python(
        "import numpy, radio_hub.determinism as d, os; "
        "print(d.DISPATCH_VARIABLE in os.environ, d.pin_numeric_dispatch())"
    )
    assert out == "False False"
