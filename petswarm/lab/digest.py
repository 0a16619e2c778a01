"""A run's ``digest``: one hash of what the run did, with wall-clock times left out.

It covers every node's event stream (``events/*.jsonl`` without the wall-clock stamp ``t``; ``mono`` stays,
which in model time is model time), the ground truth (``world.jsonl``) and every frame on the air
(``air.pcap``, stamped in model time in a model run). Files are taken in name order and events in file order,
so in model and lockstep time equal seeds and options give equal digests; in wall-clock time the digest
differs from run to run and says only that two records are the same record.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

_WALL_KEYS = ("t",)
"""Event fields that carry wall-clock time."""


def record_digest(path: str | Path) -> str:
    """The SHA-256 hex digest of the run record at ``path``."""
    path = Path(path)
    digest = hashlib.sha256()
    for events in sorted((path / "events").glob("*.jsonl")):
        digest.update(events.name.encode())
        for line in events.read_text().splitlines():
            try:
                event = json.loads(line)
            except json.JSONDecodeError:  # a line cut short by a kill: not part of what the run did
                continue
            for key in _WALL_KEYS:
                event.pop(key, None)
            digest.update(json.dumps(event, sort_keys=True, separators=(",", ":")).encode())
    for name in ("world.jsonl", "air.pcap"):
        part = path / name
        if part.exists():
            digest.update(name.encode())
            digest.update(part.read_bytes())
    return digest.hexdigest()
