"""Invariants every run must keep, checked on its record after it ends.

- counters add up: at every receiver, heard = delivered + collided + lost + filtered;
- event records are complete and ordered: each robot's stream starts with ``start``, ends with
  ``stop`` (for a run that finished), and its timestamps never go back;
- state transitions chain: each transition starts from the state the previous one ended in, so no
  robot was ever in two swarms at once (a slave leaves one swarm before it can join another);
- every robot ends in a valid state: waiting or driving with its user, never half-way through a swarm;
- no two IR modules shone at once (the hub's overlap counter), so no IR reading came from two sources;
- a robot that died during the run (``supervision.jsonl``) is held to what it did while alive: its events
  may end without ``stop`` and in any state, but they must still start, keep order and chain; a robot
  restarted after (model-time scenarios' ``restart``) starts a new life, checked as a robot of its own.

Pure functions over the record's data; ``check_record`` reads a run directory.
"""

from __future__ import annotations

import itertools
import json
from pathlib import Path
from typing import Any

from petswarm.lab.records import read_events

FINAL_STATES = {"waiting", "following", "leading", "remote-control", "command-waiting"}
"""Command-waiting too: a robot paired with its owner whose user cancelled the operation (a watch circle) rests
there, with its user, outside any swarm."""


def check_counters(nodes: dict[str, dict[str, int]]) -> list[str]:
    """heard = delivered + collided + lost + filtered at every node."""
    problems = []
    for name, n in nodes.items():
        parts = n["delivered"] + n["collided"] + n["lost"] + n["filtered"]
        if n["heard"] != parts:
            problems.append(f"{name}: heard {n['heard']} != delivered + collided + lost + filtered = {parts}")
    return problems


def check_events(name: str, events: list[dict[str, Any]], finished: bool) -> list[str]:
    """Completeness, order, chained transitions and the final state of one robot's events."""
    if not events:
        return [f"{name}: no events at all"]
    problems = []
    if events[0]["kind"] != "start":
        problems.append(f"{name}: the first event is {events[0]['kind']!r}, not 'start'")
    if finished and events[-1]["kind"] != "stop":
        problems.append(f"{name}: the last event is {events[-1]['kind']!r}, not 'stop' (record incomplete)")
    for before, after in itertools.pairwise(events):
        if after["t"] < before["t"] or after["mono"] < before["mono"]:
            problems.append(f"{name}: events out of order at {after['kind']!r} (t {after['t']})")
            break
    state = events[0].get("state", "waiting")
    for event in (e for e in events if e["kind"] == "state"):
        if event["frm"] != state:
            problems.append(f"{name}: transition {event['frm']} -> {event['to']} while in {state}")
        state = event["to"]
    if finished and state not in FINAL_STATES:
        problems.append(f"{name}: ends in {state}, not waiting or driving with its user")
    return problems


def check_ir(ir: dict[str, Any] | None) -> list[str]:
    """No two IR transmitters at once."""
    if ir and ir.get("overlap_episodes", 0):
        return [f"IR: {ir['overlap_episodes']} moments with two or more modules transmitting"]
    return []


def died_during(run: Path) -> set[str]:
    """The processes a run recorded as dying while it ran and not restarted after (their events end early, by
    no fault of theirs)."""
    path = run / "supervision.jsonl"
    dead: set[str] = set()
    for entry in read_events(path) if path.exists() else []:
        if entry.get("kind") == "died":
            dead.add(entry["process"])
        elif entry.get("kind") == "restarted":
            dead.discard(entry["process"])
    return dead


def lives(events: list[dict[str, Any]]) -> list[list[dict[str, Any]]]:
    """A robot's events split at each ``start``: one list per process life (a robot killed and restarted appends
    to the same events file; its new process starts over in waiting)."""
    split: list[list[dict[str, Any]]] = []
    for event in events:
        if event["kind"] == "start" or not split:
            split.append([])
        split[-1].append(event)
    return split


def check_record(run: Path) -> list[str]:
    """Every invariant of one run record; an empty list when all hold."""
    summary_file = run / "summary.json"
    summary = json.loads(summary_file.read_text()) if summary_file.exists() else None
    finished = summary is not None and "nodes" in summary
    problems = check_counters(summary["nodes"]) if finished else []
    died = died_during(run)
    for path in sorted((run / "events").glob("*.jsonl")):
        split = lives(read_events(path)) or [[]]
        for i, life in enumerate(split):  # every life but the last was ended by a kill
            last = i == len(split) - 1
            problems += check_events(path.stem, life, finished and last and path.stem not in died)
    return problems + check_ir(summary.get("ir") if summary else None)
