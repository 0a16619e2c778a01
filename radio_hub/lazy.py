"""numpy loaded at its first use rather than at import (issue 13: a robot process's peak RSS at most 50 MB).

numpy maps about 13 MB into a process. A robot that only pings never computes with arrays, yet the
middleware's modules (IR estimation, LF location, surround, driving) and the radio port are all imported
when a robot starts. Those modules hold ``np = lazy_numpy(__name__)`` in place of ``import numpy as np``:
the first read of an attribute imports numpy and puts the real module in the owner's globals, so later
reads there cost nothing, and what numpy computes is unchanged.

A robot process itself loads numpy as it starts (``petswarm.robot.load_numpy``): at its first use, inside a
swarm's join handshake, the import stalled the loop. What stays lazy spares the commands and tools that
import the middleware without computing (``petswarm swarm``, ``chaos``, the CLI's parser).
"""

from __future__ import annotations

import importlib
import sys
from typing import Any


class LazyModule:
    """Stands for module ``name`` under ``alias`` in module ``owner`` until one of its attributes is read."""

    __slots__ = ("_alias", "_name", "_owner")

    def __init__(self, name: str, owner: str, alias: str) -> None:
        self._name = name
        self._owner = owner
        self._alias = alias

    def __getattr__(self, attr: str) -> Any:
        module = importlib.import_module(self._name)
        owner = sys.modules.get(self._owner)
        if owner is not None and getattr(owner, self._alias, None) is self:
            setattr(owner, self._alias, module)  # the owner's later reads go straight to the module
        return getattr(module, attr)

    def __repr__(self) -> str:
        return f"<{self._name}, imported at first use by {self._owner}>"


def lazy_numpy(owner: str) -> Any:
    """numpy for module ``owner`` (its ``__name__``), bound there as ``np``, imported when first used."""
    return LazyModule("numpy", owner, "np")
