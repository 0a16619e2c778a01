"""Shrinking a failing case: fewer faults (delta debugging on the fault list), fewer robots, shorter and weaker
faults, a simpler world and a straighter path, each step a new deterministic run that must fail the SAME
property; the fixed point (or the budget's end) is written out as a scenario file with the command replaying it."""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from petswarm.explore.generate import turns_about
from petswarm.explore.toml_out import dumps
from petswarm.scenario import ACTIONS

Runner = Callable[[dict[str, Any]], dict[str, Any]]
"""Runs a case's tables: its result (``run_case``'s)."""


def fault_units(faults: list[dict[str, Any]]) -> list[list[dict[str, Any]]]:
    """The faults as the units shrinking drops together: a chaos fault with its clear, a kill with its restart,
    the wearable link lost with its return."""
    units: list[list[dict[str, Any]]] = []
    chaos: dict[int, list[dict[str, Any]]] = {}
    pending: dict[tuple[str, Any], list[dict[str, Any]]] = {}
    chaos_id = 0
    for fault in sorted(faults, key=lambda f: float(f["at"])):
        kind = fault.get("kind")
        if fault.get("clear"):
            unit = chaos.get(fault.get("id"))
            if unit is not None:
                unit.append(fault)
            else:
                units.append([fault])
        elif kind in ("restart", "wearable_back"):
            key = ("kill" if kind == "restart" else "wearable_lost", fault.get("robot"))
            unit = pending.pop(key, None)
            if unit is not None:
                unit.append(fault)
            else:
                units.append([fault])
        elif kind in ACTIONS:
            unit = [fault]
            pending[(kind, fault.get("robot"))] = unit
            units.append(unit)
        else:
            chaos_id += 1
            unit = [fault]
            chaos[chaos_id] = unit
            units.append(unit)
    return units


def join_units(units: list[list[dict[str, Any]]]) -> list[dict[str, Any]]:
    """The faults of ``units`` in time order, each clear renumbered to its fault's new id."""
    faults = sorted((f for unit in units for f in unit), key=lambda f: float(f["at"]))
    chaos_ids: dict[int, int] = {}
    for unit in units:
        head = unit[0]
        if not head.get("clear") and head.get("kind") not in ACTIONS:
            chaos_ids[id(head)] = 0
    number = 0
    for fault in faults:
        if id(fault) in chaos_ids:
            number += 1
            chaos_ids[id(fault)] = number
    out = []
    for unit in units:
        new_id = chaos_ids.get(id(unit[0]))
        for fault in unit:
            copy_ = dict(fault)
            if copy_.get("clear") and new_id is not None:
                copy_["id"] = new_id
            out.append(copy_)
    return sorted(out, key=lambda f: float(f["at"]))


def candidates(data: dict[str, Any]) -> Iterator[tuple[str, dict[str, Any]]]:
    """Smaller cases than ``data``, most shrinking first: (what was changed, the new tables)."""
    units = fault_units(data.get("faults", []))
    if units:
        yield "no faults", {**data, "faults": []}
    if len(units) > 1:
        half = len(units) // 2
        yield "first half of the faults", {**data, "faults": join_units(units[:half])}
        yield "second half of the faults", {**data, "faults": join_units(units[half:])}
    for k in range(len(units)):
        yield f"without fault unit {k}", {**data, "faults": join_units(units[:k] + units[k + 1 :])}
    count = data.get("robots", {}).get("count", 0)
    for fewer in dict.fromkeys([max(1, count // 2), count - 1]):
        if 1 <= fewer < count:
            smaller = _fewer_robots(data, fewer)
            if smaller is not None:
                yield f"{fewer} robots", smaller
    for k, unit in enumerate(units):
        for what, weaker in _weaker(unit):
            yield f"fault unit {k} {what}", {**data, "faults": join_units([*units[:k], weaker, *units[k + 1 :]])}
    if data.get("obstacles"):
        yield "no obstacles", {**data, "obstacles": []}
        for k in range(len(data["obstacles"])):
            yield f"without obstacle {k}", {**data, "obstacles": data["obstacles"][:k] + data["obstacles"][k + 1 :]}
    user = data.get("user")
    path = user.get("path", []) if user else []
    # a path with the user's turn-abouts before changes of side stays whole: each turns him to face robots placed
    # by the walks and turns before it, so without those it would ask what the generator never asks
    if path and not turns_about(path):
        if any("turn" in leg for leg in path):
            yield "a straight path", {**data, "user": {**user, "path": [leg for leg in path if "turn" not in leg]}}
        yield "the user standing", {**data, "user": {**user, "path": []}}
    duration = float(data.get("duration_s", 30.0))
    last = max([float(f["at"]) for f in data.get("faults", [])] + [0.0])
    if user:
        last = max([last] + [float(r["at"]) for r in user.get("watch", [])])
    shorter = round(max(last + 2.0, duration * 0.75), 2)
    if shorter < duration - 0.5:
        yield f"a {shorter:g} s run", {**data, "duration_s": shorter}


def _fewer_robots(data: dict[str, Any], count: int) -> dict[str, Any] | None:
    """``data`` with robots ``1..count`` only: their faults kept, requests for more robots cut to what is left."""
    out = copy.deepcopy(data)
    robots = out["robots"]
    robots["count"] = count
    robots["positions"] = robots.get("positions", [])[:count]
    names = {f"robot-{k}" for k in range(1, count + 1)}
    units = []
    for unit in fault_units(out.get("faults", [])):
        head = unit[0]
        if head.get("robot", 1) > count or head.get("node", "robot-1") not in names | {"user"}:
            continue
        if "group" in head:
            group = [n for n in head["group"] if n in names]
            if not group:
                continue
            unit = [{**head, "group": group}, *unit[1:]]
        units.append(unit)
    out["faults"] = join_units(units)
    if out.get("user"):
        if out["user"].get("owner", 1) > count:
            return None
        for request in out["user"].get("watch", []):
            if "robots" in request:
                request["robots"] = max(1, min(request["robots"], count - 1))
    return out


def _weaker(unit: list[dict[str, Any]]) -> Iterator[tuple[str, list[dict[str, Any]]]]:
    head, rest = unit[0], unit[1:]
    if rest:
        start, end = float(head["at"]), float(rest[0]["at"])
        if end - start > 0.4:
            mid = round(start + (end - start) / 2, 2)
            yield "half as long", [head, {**rest[0], "at": mid}, *rest[1:]]
    for key, floor in (("p", 0.02), ("ms", 1.0), ("sigma", 2.0), ("jitter_ms", 0.0), ("p_gb", 0.01)):
        if key in head and float(head[key]) > floor * 2:
            yield f"{key} halved", [{**head, key: round(float(head[key]) / 2, 4)}, *rest]


def shrink(
    data: dict[str, Any], prop: str, run: Runner, budget: int = 60, log: Callable[[str], None] | None = None
) -> tuple[dict[str, Any], dict[str, Any], int]:
    """The smallest case found from ``data`` that still fails ``prop``: (its tables, its result, runs spent)."""
    best, best_result, runs = data, None, 0
    improved = True
    while improved and runs < budget:
        improved = False
        for what, candidate in candidates(best):
            if runs >= budget:
                break
            runs += 1
            try:
                result = run(candidate)
            except ValueError:  # not a valid scenario (a shrink too far): skip it
                continue
            if any(f["property"] == prop for f in result["failures"]):
                best, best_result, improved = candidate, result, True
                if log is not None:
                    log(f"shrunk: {what} (still fails {prop})")
                break
    if best_result is None:
        best_result = run(best)
        runs += 1
    return best, best_result, runs


def write_scenario(path: Path, data: dict[str, Any], meta: dict[str, Any]) -> str:
    """Write the shrunk case with its provenance in the header; the command that replays it."""
    command = f"petswarm explore --replay {path}"
    header = (
        f"shrunk by petswarm explore from --seed {meta['seed']} --case {meta['index']} ({meta['family']})\n"
        f"fails {meta['property']}: {meta.get('what', '')}\n"
        f"replay: {command}\n"
        f"or: petswarm run {path} --clock model --seed {meta['run_seed']}"
    )
    tables = {**data, "explore": {"family": meta["family"], "seed": meta["run_seed"], "property": meta["property"]}}
    path.write_text(dumps(tables, header))
    return command
