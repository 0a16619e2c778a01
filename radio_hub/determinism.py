"""The same float results on every x86-64 machine: numpy held to its baseline code paths.

numpy picks, at import, the fastest SIMD code its CPU has for some of its functions (AVX2, AVX-512). Those
paths round differently in the last bit, and a swarm is chaotic: a last bit on one robot at one instant
changes every digest after it. Measured: the paper's cylinder, seed 1, gave digest 6cc04e51 on an AVX-512
machine and 2e683ab2 on AVX2 ones. Held to the baseline (x86-64-v2), both give 2e683ab2, in the same time.

``NPY_DISABLE_CPU_FEATURES`` is read once, when numpy is first imported, so every petswarm package sets it on
its own import (``radio_hub``, ``petswarm`` and ``cli`` each import this module first). A user's own setting
of it wins. Other architectures (arm64) keep numpy's choice: their digests are their own.
"""

from __future__ import annotations

import os
import platform
import sys

DISPATCH_VARIABLE = "NPY_DISABLE_CPU_FEATURES"
X86_ABOVE_BASELINE = "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"
"""numpy 2.4's dispatch targets above its x86-64 baseline (X86_V2): its ``__cpu_dispatch__``."""


def pin_numeric_dispatch() -> bool:
    """Set numpy's dispatch to its baseline for this process and its children, before numpy loads; whether the
    pin holds (False: numpy was imported before it, or another architecture, or the user's own setting)."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return False
    if DISPATCH_VARIABLE in os.environ:
        return os.environ[DISPATCH_VARIABLE] == X86_ABOVE_BASELINE and "numpy" not in sys.modules
    if "numpy" in sys.modules:
        return False
    os.environ[DISPATCH_VARIABLE] = X86_ABOVE_BASELINE
    return True


def numeric_dispatch() -> list[str] | None:
    """numpy's SIMD dispatch targets enabled in this process (empty when held to its baseline); None when this
    process has not loaded numpy (it is not loaded just to say: a wall-clock run's orchestrator never needs it)."""
    if "numpy" not in sys.modules:
        return None
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    return [name for name in __cpu_dispatch__ if __cpu_features__.get(name)]


pin_numeric_dispatch()
