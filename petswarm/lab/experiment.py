"""``petswarm experiment FILE``: one file names a run, a fault timeline, repetitions and seeds.

    name = "organizing under loss"
    repetitions = 5            # runs, with seeds seed, seed + 1, ... unless `seeds` lists them
    seed = 1
    require = []               # checks of `petswarm run` a run must also pass (default: all_pairs_heard, full_swarm)
    [run]                      # any `petswarm run` option: robots, duration, organize, protocol, config,
    robots = 5                 # clock (wall, model, lockstep; --clock overrides it), profile
    duration = 2
    organize = 3
    [[faults]]                 # `petswarm chaos` requests, `at` seconds into the traffic phase
    at = 0.5
    kind = "loss"
    p = 0.3
    [[faults]]
    at = 1.5
    clear = true

Each repetition is a full `petswarm run` with its own record under the experiment's directory; the
results (a table per repetition and the aggregates) go to stdout, ``results.json`` and ``results.png``. In
model or lockstep time each run's ``digest`` is in the results: the same file and seeds repeat every run exactly,
on any machine.

A run passes when it completed and is consistent: no process failed, every robot's state agreed with the
master's after organizing and after dispersing, the record's invariants hold and the transport lost
nothing. ``require`` adds the checks that an experiment under faults may instead want to measure:
``all_pairs_heard`` (every robot heard every other in the ping phase) and ``full_swarm`` (every robot the
swarm asked for and the run had joined it). Both are required unless the file says otherwise, as in
``petswarm run``; the table shows both either way.
"""

from __future__ import annotations

import io
import json
import sys
import time
import tomllib
from contextlib import redirect_stderr, redirect_stdout
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from petswarm.lab.arguments import CLOCKS
from petswarm.lab.launch import run
from petswarm.lab.output import emit, save
from petswarm.lab.palette import OUTCOME_COLOURS
from petswarm.lab.records import runs_dir
from petswarm.lab.run import RunOptions
from petswarm.scenario import parse_toml, read_bounded
from radio_hub.datasheet import check_keys
from radio_hub.values import check_timed_fault

RADIO_KEYS = ("sent", "delivered", "collided", "lost", "filtered", "mac_retries")
"""The hub's counters a run's row sums over its robots."""
INTERRUPTED = 130
"""The exit status of a run that Ctrl-C or SIGTERM stopped: it stops the experiment too, rather than its next run
(each run takes the signals itself and returns this)."""
_TOP_KEYS = ("name", "repetitions", "seed", "seeds", "require", "run", "faults")
WAIVABLE = {
    "all_pairs_heard": "not every robot heard every other robot",
    "full_swarm": "robots it could take joined the swarm",
}
"""The checks of `petswarm run` an experiment's ``require`` may leave out, by the wording of the problem the
run reports for each (petswarm/lab/run.py; a unit test keeps the two in step). Every other problem fails a run."""
_RUN_KEYS = ("robots", "duration", "ping_interval", "organize", "protocol", "config", "clock", "profile")


def load(path: Path) -> dict[str, Any]:
    """The experiment file, checked (every table, and the hub config file ``[run] config`` names);
    ValueError naming the file, the table and what is wrong."""
    try:
        return _check(parse_toml(read_bounded(path)))
    except (ValueError, RecursionError) as err:
        raise ValueError(f"{path}: {err}") from None


def _check(data: dict[str, Any]) -> dict[str, Any]:
    check_keys(data, _TOP_KEYS, "the top level")
    check_keys(data.get("run", {}), _RUN_KEYS, "[run]")
    seeds = data.get("seeds") or [int(data.get("seed", 1)) + i for i in range(int(data.get("repetitions", 1)))]
    if not seeds or not all(isinstance(s, int) and s >= 0 for s in seeds):
        raise ValueError("seeds must be non-negative integers (or give repetitions and seed)")
    require = data.get("require", list(WAIVABLE))
    if not isinstance(require, list) or not set(require) <= set(WAIVABLE):
        raise ValueError(f"require is a list of {', '.join(WAIVABLE)} (or []), not {require!r}")
    for i, fault in enumerate(data.get("faults", [])):
        check_timed_fault(fault, f"[[faults]][{i}]")
    _check_clock_and_profile(data.get("run", {}))
    config = data.get("run", {}).get("config")
    if config is not None:
        from radio_hub.hosting import config_problem

        problem = config_problem(config)
        if problem is not None:
            raise ValueError(f"[run] config: {problem}")
    return {**data, "seeds": seeds, "require": require}


def _check_clock_and_profile(run_table: dict[str, Any]) -> None:
    clock = run_table.get("clock", "wall")
    if clock not in CLOCKS:
        raise ValueError(f"[run] clock is one of {', '.join(CLOCKS)}, not {clock!r}")
    if "profile" in run_table:
        from petswarm.profiles import check_profile

        check_profile(run_table["profile"])


@dataclass
class ExperimentOptions:
    """What ``petswarm experiment`` is asked to do (its options, as a notebook gives them)."""

    file: str
    """The TOML experiment file."""
    out: str | None = None
    """Directory for the records and results (None: runs/experiment-<time>, or under $PETSWARM_RUNS)."""
    json: bool = False
    clock: str | None = None
    """Every run's clock, over the file's ``[run] clock`` (None: the file's, else wall)."""


def experiment_command(args: ExperimentOptions) -> int:
    """Run every repetition with a progress bar; 0 when every run was OK."""
    try:
        spec = load(Path(args.file))
    except OSError as err:  # as a person reads it: the file and what is wrong, not Python's errno
        print(f"petswarm experiment: {args.file}: {(err.strerror or str(err)).lower()}", file=sys.stderr)
        return 2
    except (ValueError, tomllib.TOMLDecodeError) as err:
        print(f"petswarm experiment: {err}", file=sys.stderr)  # every error names the file already
        return 2
    if getattr(args, "clock", None):
        spec["run"] = {**spec.get("run", {}), "clock": args.clock}
    out = Path(args.out or runs_dir() / f"experiment-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}")
    out.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, Any]] = []
    seeds = spec["seeds"]
    clock = spec.get("run", {}).get("clock", "wall")
    print(
        f"[experiment] {spec.get('name') or args.file}: {len(seeds)} runs, {clock} clock", file=sys.stderr, flush=True
    )
    for i, seed in enumerate(seeds):
        rows.append(_one_run(spec, seed, out / f"run-{i + 1}-seed-{seed}"))
        print(progress_line(len(rows), len(seeds), rows[-1]), file=sys.stderr, flush=True)
        if rows[-1]["exit_code"] == INTERRUPTED:  # the run took the Ctrl-C or SIGTERM: it was meant for us all
            save(_results(spec, args, rows, interrupted=True), out, "results", _plot)  # what was found so far
            print(
                f"[experiment] interrupted in run {len(rows)} of {len(seeds)}; results so far in {out}", file=sys.stderr
            )
            raise KeyboardInterrupt
    results = _results(spec, args, rows)
    save(results, out, "results", _plot)
    emit([*table(results), f"records and results in {out}"], results, args.json)
    return 0 if all(r["ok"] for r in rows) else 1


def _results(spec: dict[str, Any], args: ExperimentOptions, rows: list[dict[str, Any]], **extra: Any) -> dict[str, Any]:
    """results.json: the file's spec, a row per run and their aggregate (``interrupted``: a Ctrl-C or SIGTERM
    stopped the last run, whose row is in as it ended)."""
    return {
        "name": spec.get("name"),
        "file": str(args.file),
        "spec": spec,
        "runs": rows,
        "aggregate": _aggregate(rows),
        **extra,
    }


def _one_run(spec: dict[str, Any], seed: int, record: Path) -> dict[str, Any]:
    options = {f.name for f in fields(RunOptions)}
    opts = RunOptions(
        **{k: v for k, v in spec.get("run", {}).items() if k in options}
        | {
            "robots": spec.get("run", {}).get("robots", 5),
            "seed": seed,
            "duration": float(spec.get("run", {}).get("duration", 2.0)),
            "ping_interval": float(spec.get("run", {}).get("ping_interval", 0.5)),
            "as_json": True,
            "record_dir": str(record),
            "faults": tuple(spec.get("faults", [])),
        }
    )
    # the run's own progress lines would break into the experiment's; they go to the run's record instead
    with redirect_stdout(io.StringIO()) as captured, redirect_stderr(io.StringIO()) as run_progress:
        code = run(opts)
    if record.is_dir():
        (record / "progress.log").write_text(run_progress.getvalue())
    summary = json.loads(captured.getvalue()) if code in (0, 1) and captured.getvalue().strip() else {}
    if not summary:  # the run failed before its summary: the record still says why
        summary_file = record / "summary.json"
        summary = json.loads(summary_file.read_text()) if summary_file.exists() else {"problems": ["run failed"]}

    organization = summary.get("organization") or {}
    nodes = summary.get("nodes", {}).values()
    ok, problems, waived = judge(code, summary.get("problems", []), spec["require"])
    return {
        "seed": seed,
        "clock": opts.clock,
        "digest": summary.get("digest"),
        "exit_code": code,
        "ok": ok,
        "record": str(record),
        "problems": problems,
        "waived": waived,
        "all_pairs_heard": summary.get("all_pairs_heard"),
        "requested": organization.get("requested"),
        "members": len(organization.get("members", [])),
        "organize_ms": round(organization["organize_time_s"] * 1000, 1) if "organize_time_s" in organization else None,
        "retries": organization.get("retries"),
        **{k: sum(n.get(k, 0) for n in nodes) for k in RADIO_KEYS},
    }


def judge(code: int, problems: list[str], require: list[str]) -> tuple[bool, list[str], list[str]]:
    """Whether a run passes its experiment: (ok, the problems that fail it, the problems the experiment does
    not require to be absent). ``code`` is the run's exit code, ``problems`` its summary's."""
    waived_words = [WAIVABLE[check] for check in WAIVABLE if check not in require]
    waived = [p for p in problems if any(words in p for words in waived_words)]
    failing = [p for p in problems if p not in waived]
    # exit 1 is a run with problems; any other non-zero code (2, 130) is a run that did not happen
    return (code == 0 or (code == 1 and bool(problems))) and not failing, failing, waived


def _aggregate(rows: list[dict[str, Any]]) -> dict[str, Any]:
    times = [r["organize_ms"] for r in rows if r["organize_ms"] is not None]
    return {
        "runs": len(rows),
        "ok": sum(r["ok"] for r in rows),
        "organize_ms_mean": round(float(np.mean(times)), 1) if times else None,
        "organize_ms_max": max(times) if times else None,
        "retry_probability": round(sum(1 for r in rows if r["retries"]) / len(rows), 3) if rows else None,
        "lost_fraction": lost_fraction(rows),
    }


def lost_fraction(rows: list[dict[str, Any]]) -> float:
    """Of the receptions a loss could take, the fraction lost: lost / (delivered + filtered + lost).

    Every counter counts at every receiver in range, and the medium decides collisions first, then loss,
    then the address filter (radio_hub/air/medium.py), so a frame meant for another robot is still a reception
    a fault can lose (filtered) and a collided one is not. A fault losing 30 % of receptions reads 0.3
    (plus the range model's small loss); before the fault starts, or after it ends, nothing is lost."""
    lost = sum(r["lost"] for r in rows)
    return round(lost / max(sum(r["delivered"] + r.get("filtered", 0) + r["lost"] for r in rows), 1), 4)


def table(results: dict[str, Any]) -> list[str]:
    """One line per run, then the aggregates."""
    require = results["spec"].get("require", list(WAIVABLE))
    lines = [
        f"experiment {results['name'] or results['file']}: {len(results['runs'])} runs; a run passes when it is "
        f"consistent{''.join(f' and {check}' for check in require)}",
        f"{'seed':>6}{'ok':>5}{'all pairs':>11}{'members':>9}{'org ms':>9}{'retries':>9}{'sent':>7}"
        f"{'delivered':>11}{'collided':>10}{'lost':>7}  digest",
    ]
    for r in results["runs"]:
        org = "-" if r["organize_ms"] is None else f"{r['organize_ms']:.1f}"
        members = f"{r['members']}/{r['requested']}" if r.get("requested") else "-"
        pairs = {True: "yes", False: "no", None: "-"}[r.get("all_pairs_heard")]
        retries = "-" if r["retries"] is None else r["retries"]
        lines.append(
            f"{r['seed']:>6}{'yes' if r['ok'] else 'NO':>5}{pairs:>11}{members:>9}{org:>9}{retries:>9}"
            f"{r['sent']:>7}{r['delivered']:>11}{r['collided']:>10}{r['lost']:>7}  {(r.get('digest') or '-')[:8]}"
        )
        lines += [f"        problem: {p}" for p in r["problems"]]
        lines += [f"        measured, not required: {p}" for p in r.get("waived", [])]
    lines.append("aggregate: " + ", ".join(f"{k} {v}" for k, v in results["aggregate"].items()))
    return lines


def _plot(results: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = results["runs"]
    fig, (org, radio) = plt.subplots(1, 2, figsize=(12, 4.2))
    org.bar([str(r["seed"]) for r in runs], [r["organize_ms"] or 0 for r in runs], color="#4c72b0")
    org.set(xlabel="seed", ylabel="organizing time (ms)", title="organizing time per run")
    draw_radio_per_run(radio, runs)
    fig.suptitle(results["name"] or results["file"])
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def draw_radio_per_run(ax: Any, runs: list[dict[str, Any]]) -> None:
    """Delivered, collided and lost receptions per run, in the colours every view of a run gives them."""
    for i, key in enumerate(("delivered", "collided", "lost")):
        values = [r[key] for r in runs]
        ax.bar([j + i * 0.27 for j in range(len(runs))], values, 0.27, label=key, color=OUTCOME_COLOURS[key])
    ax.set_xticks([j + 0.27 for j in range(len(runs))], [str(r["seed"]) for r in runs])
    ax.set(xlabel="seed", ylabel="receptions", title="radio per run")
    ax.legend(fontsize=8)


def progress_line(done: int, total: int, row: dict[str, Any]) -> str:
    """One line per finished run: the bar, the count, and how that run went (a line of its own, so nothing
    else printed meanwhile can run into it)."""
    filled = int(30 * done / total) if total else 30
    org = "" if row["organize_ms"] is None else f", organized in {row['organize_ms']:.0f} ms"
    members = f"members {row['members']}/{row['requested']}" if row.get("requested") else "no swarm"
    how = f"ok ({members}{org})" if row["ok"] else "NO: " + "; ".join(row["problems"] or ["see its record"])
    return f"[experiment] [{'#' * filled}{'.' * (30 - filled)}] {done}/{total} runs; seed {row['seed']} {how}"
