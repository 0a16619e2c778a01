"""``petswarm explore``: run a campaign (or one case, or a replay), shrink its failures, write its report."""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from petswarm.explore.campaign import Progress, run_dask, run_local, run_seed
from petswarm.explore.generate import DEFAULT_WEIGHTS, FAMILIES, case, pick_family
from petswarm.explore.report import plot, table, write_json
from petswarm.explore.shrink import shrink, write_scenario
from petswarm.lab.processes import Interrupts


def parse_families(text: str | None) -> dict[str, float]:
    """``--family organize,drive:2,...``: the families and their weights (default weights when none is given);
    ValueError naming a family that does not exist."""
    if not text:
        return dict(DEFAULT_WEIGHTS)
    weights: dict[str, float] = {}
    for part in text.split(","):
        name, _, weight = part.strip().partition(":")
        if name not in FAMILIES:
            raise ValueError(f"no family {name!r} (families: {', '.join(FAMILIES)})")
        try:
            weights[name] = float(weight) if weight else float(DEFAULT_WEIGHTS[name])
        except ValueError:
            raise ValueError(f"family weight must be a number: {part!r}") from None
        if not weights[name] >= 0:
            raise ValueError(f"family weight must be >= 0: {part!r}")
    if not any(weights.values()):
        raise ValueError("every family has weight 0")
    return weights


@dataclass
class ExploreOptions:
    """What ``petswarm explore`` is asked to do (its options, as a notebook gives them)."""

    seed: int = 1
    """The campaign's seed: case i draws from (seed, i) only."""
    cases: int = 100
    case: int | None = None
    """Run case i alone."""
    family: str | None = None
    """Families and weights, e.g. ``organize,drive:2`` (None: all, the default weights)."""
    workers: int = 1
    scheduler: str | None = None
    """A Dask distributed scheduler's address (instead of local workers)."""
    replay: str | None = None
    """Rerun a scenario file explore wrote, and check its properties."""
    out: str | None = None
    shrink: int = 5
    """Shrink at most this many failures."""


def explore(args: ExploreOptions) -> int:
    """The command; its exit status: 0 no failure, 1 a case failed, 2 bad arguments or file."""
    try:
        weights = parse_families(args.family)
    except ValueError as err:
        print(f"petswarm explore: --family: {err}", file=sys.stderr)
        return 2
    if args.replay:
        return replay(Path(args.replay))
    out = Path(args.out or f"runs/explore-{args.seed}")
    out.mkdir(parents=True, exist_ok=True)
    indices = [args.case] if args.case is not None else list(range(args.cases))
    progress = Progress(len(indices))
    # SIGTERM stops the campaign as Ctrl-C does; a second signal waits for the workers' stop and the report
    interrupts = Interrupts()
    started = time.perf_counter()
    if args.scheduler:
        stream = run_dask(args.seed, indices, args.scheduler, weights)
    else:
        stream = run_local(args.seed, indices, args.workers, weights)
    results: list[dict[str, Any]] = []
    interrupted = False
    try:
        with (out / "results.jsonl").open("w") as partial:  # as they finish: a campaign cut short keeps what it ran
            for result in stream:
                results.append(result)
                partial.write(json.dumps(result) + "\n")
                partial.flush()
                progress.step(result["ok"])
        wall = time.perf_counter() - started
        for result in sorted((r for r in results if not r["ok"]), key=lambda r: r["index"])[: args.shrink]:
            _shrink_one(result, weights, out)
    except KeyboardInterrupt:
        interrupted = True
        wall = time.perf_counter() - started
    finally:
        with interrupts.deferred():
            if interrupted:
                print(
                    f"\ninterrupted: stopping the workers; {len(results)} of {len(indices)} cases ran", file=sys.stderr
                )
            stream.close()  # an interrupted campaign's workers stopped, its Dask futures cancelled
            if interrupted:
                _report(args, weights, out, results, wall, interrupted=True)
    if interrupted:
        return 130
    _report(args, weights, out, results, wall)
    return 1 if any(not r["ok"] for r in results) else 0


def _report(
    args: argparse.Namespace,
    weights: dict[str, float],
    out: Path,
    results: list[dict[str, Any]],
    wall: float,
    interrupted: bool = False,
) -> None:
    """Write results.json, results.txt and failures.png, and print the table."""
    meta = {
        "seed": args.seed,
        "cases": len(results),
        "families": weights,
        "where": args.scheduler or f"{args.workers} local workers",
        "wall_s": round(wall, 3),
    }
    if interrupted:
        meta["interrupted"] = True
    write_json(out / "results.json", meta, results)
    text = table(results, wall)
    if interrupted:
        asked = 1 if args.case is not None else args.cases
        cut = "shrinking cut short" if len(results) == asked else "none shrunk"
        text = f"interrupted after {len(results)} of {asked} cases ({cut})\n{text}"
    (out / "results.txt").write_text(text + "\n")
    with contextlib.suppress(ImportError):  # matplotlib comes with the package; a stripped install gets the table
        plot(out / "failures.png", results)
    print(text)
    print(f"\nresults: {out / 'results.json'}, {out / 'results.txt'}, {out / 'failures.png'}")


def _shrink_one(result: dict[str, Any], weights: dict[str, float], out: Path) -> None:
    """Shrink one failed case while its first failed property still fails; write the scenario and note the replay."""
    seed, index = result["seed"], result["index"]
    family = pick_family(seed, index, weights)
    prop = result["failures"][0]["property"]
    own_seed = run_seed(seed, index)

    from petswarm.explore.runner import run_case

    def run(data: dict[str, Any]) -> dict[str, Any]:
        return run_case(data, own_seed, family)

    print(f"shrinking case {index} ({family}, fails {prop})...", file=sys.stderr)
    small, small_result, runs = shrink(case(seed, index, family), prop, run)
    what = next(f for f in small_result["failures"] if f["property"] == prop)["violations"][0]["what"]
    path = out / f"case-{index}-{prop}.toml"
    meta = {"seed": seed, "index": index, "family": family, "property": prop, "what": what.splitlines()[0]}
    result["replay"] = write_scenario(path, small, {**meta, "run_seed": own_seed})
    result["shrunk"] = {
        "file": str(path),
        "robots": small["robots"]["count"],
        "faults": len(small.get("faults", [])),
        "runs": runs,
        "failures": small_result["failures"],
    }
    print(
        f"  {path}: {small['robots']['count']} robots, {len(small.get('faults', []))} faults ({runs} runs)",
        file=sys.stderr,
    )


def replay(path: Path) -> int:
    """Rerun a scenario file ``petswarm explore`` wrote (its ``[explore]`` table gives the family and seed)."""
    from petswarm.explore.runner import run_case
    from petswarm.scenario import ScenarioError, load

    try:
        load(path)  # every problem named as for petswarm run
        data = tomllib.loads(path.read_text())
    except (ScenarioError, OSError, tomllib.TOMLDecodeError) as err:
        print(f"petswarm explore: --replay: {err}", file=sys.stderr)
        return 2
    meta = data.get("explore", {})
    family, seed = meta.get("family", "mixed"), int(meta.get("seed", 1))
    result = run_case(data, seed, family)
    print(
        f"{path}: family {family}, seed {seed}, digest {result['digest'][:16]}, "
        f"{result['model_time_s']} s of model time"
    )
    if result["ok"]:
        print("every property held")
        return 0
    for failure in result["failures"]:
        for v in failure["violations"]:
            when = "" if v["when"] is None else f" at {v['when']:.3f} s"
            who = f" [{', '.join(v['who'])}]" if v["who"] else ""
            print(f"FAILED {failure['property']}{when}{who}: {v['what']}")
    return 1
