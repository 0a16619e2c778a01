"""``petswarm export RECORD --mcap FILE``: a run record as one MCAP file, for Foxglove and any MCAP reader.

The record's world log, events and air capture become the channels of ``petswarm.lab.foxglove_channels``, logged in
time order at the run's model time; its manifest and summary become MCAP metadata records (``manifest`` and
``summary``: each top-level key a JSON value), and ``petswarm.export`` says where model time 0 was taken from.

Model time: a model-time or lockstep run stamps everything from ``MODEL_EPOCH_S`` (model time 0), so the stamps
say model time exactly. A wall-clock run stamps with the wall clock, and the hub's model time 0 is when it opened:
the world log holds both for every frame (``wall`` and ``t_us``), so the offset comes from there; a wall-clock run
without a world log (robots pinging where they stand) takes its earliest stamp as time 0.

    from petswarm.lab.mcap_export import export_mcap
    result = export_mcap(Path("runs/20261128T115150Z-4"), Path("run.mcap"))
    result.counts["/world/scene"], result.size_bytes
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from petswarm.lab.foxglove_channels import MissingExtra, RunChannels, require_sdk
from petswarm.lab.records import read_events
from petswarm.lab.watch_frames import parse_replay
from radio_hub.hosting import read_pcap
from radio_hub.values import MODEL_EPOCH_S

PROFILE = "petswarm"
"""The MCAP header's profile: the channels are petswarm's (Foxglove schemas, and JSON ones of its own)."""
EXACT_CLOCKS = ("model", "lockstep")
"""Clocks whose records are stamped from ``MODEL_EPOCH_S``."""

__all__ = ["ExportResult", "MissingExtra", "RecordError", "export_mcap", "read_record"]


class RecordError(ValueError):
    """The directory is not a run record, or the output cannot be written: one line for the user."""


@dataclass(frozen=True)
class RecordItems:
    """A record's streams, each item with its model time in nanoseconds, and how model time 0 was found."""

    manifest: dict[str, Any]
    summary: dict[str, Any] | None
    world: list[tuple[int, dict[str, Any]]]
    events: list[tuple[int, str, dict[str, Any]]]
    """(model time, node, event), in time order (a node's own order kept within an instant)."""
    air: list[tuple[int, bytes]]
    epoch_us: int
    """The wall-clock stamp of model time 0, in microseconds since the Unix epoch."""
    time_origin: str
    dropped: dict[str, int] = field(default_factory=dict)
    """Lines or records of the record left out: world lines that are not frames, events without a time, a pcap
    record cut short."""


@dataclass(frozen=True)
class ExportResult:
    """What ``export_mcap`` wrote."""

    path: Path
    counts: dict[str, int]
    """Messages per topic."""
    size_bytes: int
    elapsed_s: float
    """Wall seconds the export took (reading the record and writing the file)."""
    time_origin: str
    dropped: dict[str, int]


def read_record(record: Path) -> RecordItems:
    """Every stream of a run record with its model times; RecordError when ``record`` is not a run record."""
    manifest_file = record / "manifest.json"
    if not manifest_file.is_file():
        raise RecordError(f"{record} is not a run record (no manifest.json)")
    try:
        manifest = json.loads(manifest_file.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise RecordError(f"{manifest_file}: {err}") from None
    summary = _json_or_none(record / "summary.json")
    dropped: dict[str, int] = {}
    frames: list[dict[str, Any]] = []
    world_file = record / "world.jsonl"
    if world_file.is_file():
        with world_file.open() as lines:
            replay = parse_replay(lines)
        frames, dropped["world"] = replay.frames, replay.dropped
    raw_events: list[tuple[float, str, dict[str, Any]]] = []
    for path in sorted((record / "events").glob("*.jsonl")):
        for event in read_events(path):
            t = event.get("t")
            if isinstance(t, int | float) and not isinstance(t, bool):
                raw_events.append((float(t), path.stem, event))
            else:
                dropped["events"] = dropped.get("events", 0) + 1
    pcap_records = []
    pcap_file = record / "air.pcap"
    if pcap_file.is_file():
        try:
            capture = read_pcap(pcap_file)
        except ValueError as err:
            raise RecordError(f"{pcap_file}: {err}") from None
        pcap_records = capture.records
        dropped["air"] = int(capture.truncated)
    clock = str((manifest.get("options") or {}).get("clock") or "wall")
    if clock in EXACT_CLOCKS:
        epoch_us, origin = round(MODEL_EPOCH_S * 1e6), f"{clock} clock: stamps are model time from its epoch"
    elif frames:
        first = frames[0]
        epoch_us = round(first["wall"] * 1e6) - first["t_us"]
        origin = "wall clock: model time 0 from the world log (the hub's wall clock at each frame's model time)"
    else:
        stamps = [t for t, _, _ in raw_events] + [r.ts_us / 1e6 for r in pcap_records[:1]]
        epoch_us = round(min(stamps) * 1e6) if stamps else 0
        origin = "wall clock without a world log: model time 0 is the record's earliest stamp"
    world = [(f["t_us"] * 1000, f) for f in frames]
    events = sorted(
        ((_ns(round(t * 1e6) - epoch_us), node, event) for t, node, event in raw_events), key=lambda item: item[0]
    )
    air = [(_ns(r.ts_us - epoch_us), r.data) for r in pcap_records]
    return RecordItems(manifest, summary, world, events, air, epoch_us, origin, dropped)


def export_mcap(record: Path, out: Path, *, overwrite: bool = False) -> ExportResult:
    """Write ``record`` (a run directory) to the MCAP file ``out``.

    RecordError when ``record`` is not a run record or ``out`` exists (without ``overwrite``) or cannot be written;
    MissingExtra when the Foxglove SDK is not installed."""
    fox = require_sdk()
    from foxglove.mcap import MCAPWriteOptions

    started = time.perf_counter()
    items = read_record(record)
    if out.exists() and not overwrite:
        raise RecordError(f"{out} exists (--force replaces it)")
    context = fox.Context()
    try:
        writer = fox.open_mcap(
            out, allow_overwrite=overwrite, context=context, writer_options=MCAPWriteOptions(profile=PROFILE)
        )
    except Exception as err:  # the SDK reports an unwritable path as a plain error of its own
        raise RecordError(f"cannot write {out}: {err}") from None
    channels = RunChannels(context)
    try:
        _log_in_order(channels, items)
        writer.write_metadata("manifest", _as_metadata(items.manifest))
        if items.summary is not None:
            writer.write_metadata("summary", _as_metadata(items.summary))
        writer.write_metadata(
            "petswarm.export",
            {
                "source": str(record),
                "time_origin": items.time_origin,
                "epoch_us": str(items.epoch_us),
                "counts": json.dumps(channels.counts, sort_keys=True),
                "dropped": json.dumps(items.dropped, sort_keys=True),
            },
        )
    finally:
        writer.close()
        channels.close()
    return ExportResult(
        out, dict(channels.counts), out.stat().st_size, time.perf_counter() - started, items.time_origin, items.dropped
    )


def _log_in_order(channels: RunChannels, items: RecordItems) -> None:
    """The three streams merged by model time (a world frame before the events and frames of its instant)."""
    merged: list[tuple[int, int, int, Any]] = []
    merged += [(t, 0, i, frame) for i, (t, frame) in enumerate(items.world)]
    merged += [(t, 1, i, (node, event)) for i, (t, node, event) in enumerate(items.events)]
    merged += [(t, 2, i, data) for i, (t, data) in enumerate(items.air)]
    merged.sort(key=lambda item: item[:3])
    for t, stream, _, payload in merged:
        if stream == 0:
            channels.world_frame(payload, t)
        elif stream == 1:
            channels.event(payload[0], payload[1], t)
        else:
            channels.air_frame(payload, t)


def _as_metadata(body: dict[str, Any]) -> dict[str, str]:
    """A JSON object as MCAP metadata (string to string): strings as they are, anything else as JSON."""
    return {
        str(key): value if isinstance(value, str) else json.dumps(value, default=str, separators=(",", ":"))
        for key, value in body.items()
    }


def _json_or_none(path: Path) -> dict[str, Any] | None:
    try:
        body = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None
    return body if isinstance(body, dict) else None


def _ns(us: int) -> int:
    """Microseconds of model time as the nanoseconds MCAP logs in (a stamp before time 0 is put at 0)."""
    return max(us, 0) * 1000


@dataclass
class ExportOptions:
    """What ``petswarm export`` takes."""

    run: str
    """A run record directory."""
    mcap: str
    """The MCAP file to write."""
    force: bool = False
    """Replace the MCAP file when it exists."""
    json: bool = False
    """Print the messages per topic, size and time as JSON (else one line)."""


def export_command(options: ExportOptions) -> int:
    """Write the record as MCAP and say what was written; 2 when the record cannot be read or the extra is
    missing."""
    try:
        result = export_mcap(Path(options.run), Path(options.mcap), overwrite=options.force)
    except (RecordError, MissingExtra) as err:
        print(f"petswarm export: {err}", file=sys.stderr)
        return 2
    if options.json:
        body = {"mcap": str(result.path), "size_bytes": result.size_bytes, "elapsed_s": round(result.elapsed_s, 3)}
        print(json.dumps({**body, "counts": result.counts, "time_origin": result.time_origin}, indent=2))
        return 0
    total = sum(result.counts.values())
    print(
        f"{result.path}: {total} messages on {len(result.counts)} topics, {result.size_bytes / 1e6:.2f} MB "
        f"in {result.elapsed_s:.2f} s ({result.time_origin})"
    )
    return 0
