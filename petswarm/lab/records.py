"""Run records: every ``petswarm run`` leaves a directory that can be read, reported and replayed.

    runs/<UTC time>-<seed>/
        manifest.json          seed, versions, command line, options, medium configuration
        events/robot-N.jsonl   every robot's structured events, one JSON object per line, as they happen
        logs/*.log             every process's stdout and stderr
        air.pcap               the hub's frame log: every 802.15.4 frame on the air (Wireshark, tshark)

        summary.json           the final summary (also written when the run fails or is interrupted, and
                               rewritten every second while it runs, so a killed run leaves one)
        supervision.jsonl      children that died during the run (petswarm/lab/supervision.py), one line each

Files are written as the run goes (the robots flush every event), so a run that is killed midway
still leaves a readable record. Records go under ``runs/``, or under ``$PETSWARM_RUNS`` when it is set
(the test suite points it into pytest's temporary directory), unless ``--record`` names the directory.

A directory holds one run. ``--record DIR`` naming a directory with an earlier run replaces that run's files
(said on stderr): robots append to their event streams, so an earlier run's lines would otherwise end up in
this run's events and digest. Files the record does not own are left alone. A default name already taken
(two runs with one seed in the same second) gets a suffix instead.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from dataclasses import asdict, dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

from radio_hub.determinism import DISPATCH_VARIABLE, numeric_dispatch

_PACKAGES = ("petswarm", "eclipse-zenoh", "numpy", "msgpack")
RUNS_ENV = "PETSWARM_RUNS"


def runs_dir() -> Path:
    """Where records go by default: ``$PETSWARM_RUNS``, else ``runs`` in the current directory."""
    return Path(os.environ.get(RUNS_ENV) or "runs")


@dataclass(frozen=True)
class RunRecord:
    """The directory of one run."""

    path: Path

    @classmethod
    def create(cls, opts: Any, world: str, endpoint: str) -> RunRecord:
        """Make the directory (``opts.record_dir``, or ``<runs_dir()>/<UTC time>-<seed>``) and write the manifest."""
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
        if opts.record_dir:
            path = Path(opts.record_dir)
            _clear_earlier_run(path)
        else:
            path = _free_name(runs_dir() / f"{stamp}-{opts.seed}")
        (path / "events").mkdir(parents=True, exist_ok=True)
        manifest = {
            "seed": opts.seed,
            "world": world,
            "endpoint": endpoint,
            "started": stamp,
            "command": sys.argv,
            "options": asdict(opts),
            "medium_config_file": _read(opts.config),
            "versions": {"python": platform.python_version(), **{p: _version(p) for p in _PACKAGES}},
            # a digest is the same on another machine of this architecture and these numeric paths: the pin every
            # process of the run inherits, and numpy's paths where this one has loaded it (null: not loaded here)
            "numeric": {
                "machine": platform.machine(),
                "numpy_disabled": os.environ.get(DISPATCH_VARIABLE),
                "numpy_dispatch": numeric_dispatch(),
            },
        }
        record = cls(path)
        record.write("manifest.json", manifest)
        return record

    def events_of(self, name: str) -> Path:
        """Where process ``name`` appends its events."""
        return self.path / "events" / f"{name}.jsonl"

    def write(self, name: str, body: dict[str, Any]) -> None:
        """One JSON file of the record, replaced whole: a run killed while writing leaves the previous one."""
        part = self.path / f".{name}.part"
        part.write_text(json.dumps(body, indent=2, default=str) + "\n")
        os.replace(part, self.path / name)

    def finish(self, summary: dict[str, Any], exit_codes: dict[str, int | None]) -> None:
        """The summary, with every process's exit code."""
        self.write("summary.json", {**summary, "exit_codes": exit_codes})


RECORD_FILES = ("manifest.json", "summary.json", "world.jsonl", "air.pcap", "supervision.jsonl")
"""The files a run writes at the top of its directory (besides ``events/``, ``logs/`` and report plots)."""


def _clear_earlier_run(path: Path) -> None:
    """Remove the files an earlier run left in ``path``; nothing else there is touched."""
    owned = [path / name for name in RECORD_FILES]
    owned += [*path.glob("events/*.jsonl"), *path.glob("logs/*.log"), *path.glob("*.png"), *path.glob(".*.part")]
    earlier = [file for file in owned if file.is_file()]
    if not earlier:
        return
    print(f"petswarm run: {path} held an earlier run; its {len(earlier)} files are replaced", file=sys.stderr)
    for file in earlier:
        file.unlink()


def _free_name(path: Path) -> Path:
    """``path``, or ``path-2``, ``path-3``... whichever does not exist yet."""
    candidate, n = path, 1
    while candidate.exists():
        n += 1
        candidate = path.with_name(f"{path.name}-{n}")
    return candidate


def read_events(path: Path) -> list[dict[str, Any]]:
    """A JSON-lines events file; a line cut short by a kill is skipped."""
    events = []
    for line in path.read_text().splitlines():
        try:
            events.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return events


def _version(package: str) -> str:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return "unknown"


def _read(path: str | None) -> str | None:
    return Path(path).read_text() if path else None
