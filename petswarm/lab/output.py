"""What every benchmark does with its results: a table for people, JSON and a plot for the record."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any


def emit(lines: list[str], summary: dict[str, Any], as_json: bool) -> None:
    """The table on stdout; with ``as_json`` the JSON ``summary`` on stdout and the table on stderr."""
    stream = sys.stderr if as_json else sys.stdout
    for line in lines:
        print(line, file=stream)
    if as_json:
        print(json.dumps(summary, indent=2))


def save(
    results: dict[str, Any],
    out: Path,
    name: str,
    plot: Callable[[dict[str, Any], Path], None],
    record: dict[str, Any] | None = None,
) -> None:
    """``<out>/<name>.json`` (``record``, by default the results) and ``<out>/<name>.png``."""
    results["files"] = {"json": str(out / f"{name}.json"), "png": str(out / f"{name}.png")}
    plot(results, out / f"{name}.png")
    (out / f"{name}.json").write_text(json.dumps(record if record is not None else results, indent=2) + "\n")
