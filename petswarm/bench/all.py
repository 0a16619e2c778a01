"""``petswarm bench all``: every bench the documentation quotes, rerun by one command, under one header.

Each figure of the guide comes from one bench command listed in ``FIGURES``; this reruns them one after another,
each in a fresh ``petswarm bench ...`` process writing its JSON and plots into a folder of its own, and writes
``index.md`` (and ``figures.json``) with one generated header (the command, the date, the machine, its load
average) and per figure the exact command, its exit status, wall time, load before and after, its table and its
plots. ``--quick`` runs a small version of each (a handful of runs) to check that the whole chain works; its
figures are not the documented ones and its header says so.
"""

from __future__ import annotations

import json
import os
import platform
import shlex
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
"""The checkout's top folder: the benches run there, so the scenario files they name (``scenarios/...``) are found
from wherever ``bench all`` was started."""


@dataclass(frozen=True)
class Figure:
    """One bench command the documentation quotes: its name, its full arguments and a quick version of them."""

    name: str
    args: tuple[str, ...]
    quick: tuple[str, ...]
    quoted_in: str
    """The guide page whose figures this command makes."""


FIGURES: tuple[Figure, ...] = (
    Figure("hub", ("hub", "--floor"), ("hub", "--rounds", "20", "--nodes", "4", "--load-seconds", "1"), "RESULTS.md"),
    Figure(
        "organize",
        ("organize", "--slaves", "1-5", "--runs", "50", "--protocol", "both"),
        ("organize", "--slaves", "1-2", "--runs", "2"),
        "RESULTS.md",
    ),
    Figure(
        "organize-mac-ack-off",
        ("organize", "--slaves", "1-5", "--runs", "50", "--mac-ack", "off"),
        ("organize", "--slaves", "1", "--runs", "2", "--mac-ack", "off"),
        "RESULTS.md",
    ),
    Figure(
        "organize-kim2017",
        ("organize", "--protocol", "paper", "--slaves", "1-5", "--runs", "50", "--profile", "kim2017"),
        ("organize", "--protocol", "paper", "--slaves", "1", "--runs", "2", "--profile", "kim2017"),
        "PROFILES.md",
    ),
    Figure("ir", ("ir",), ("ir", "--runs", "5", "--no-wire", "--members", "2-3"), "RESULTS.md"),
    Figure(
        "ir-kim2017",
        ("ir", "--no-wire", "--profile", "kim2017"),
        ("ir", "--runs", "5", "--no-wire", "--profile", "kim2017", "--members", "2-3"),
        "PROFILES.md",
    ),
    Figure(
        "reaction",
        ("reaction", "--clock", "model", "--runs", "50"),
        ("reaction", "--clock", "model", "--runs", "1"),
        "RESULTS.md",
    ),
    Figure(
        "reaction-kim2017",
        ("reaction", "--clock", "model", "--runs", "50", "--profile", "kim2017"),
        ("reaction", "--clock", "model", "--runs", "1", "--profile", "kim2017"),
        "PROFILES.md",
    ),
    Figure(
        "surround",
        ("surround", "--law", "both", "--seeds", "10"),
        ("surround", "--law", "paper", "--seeds", "1", "scenarios/surround-cylinder.toml"),
        "RESULTS.md",
    ),
    Figure(
        "scale",
        ("scale", "--robots", "10,20,50,100", "--model-robots", "1000", "--duration", "2"),
        ("scale", "--robots", "2", "--model-robots", "none", "--duration", "0.5"),
        "concepts/clocks.md",
    ),
    Figure(
        "start",
        ("start", "--robots", "20", "--rounds", "3"),
        ("start", "--robots", "2", "--rounds", "1"),
        "concepts/clocks.md",
    ),
)
"""Every bench command whose figures the guide quotes, in the order ``bench all`` runs them."""


@dataclass
class AllOptions:
    """What ``petswarm bench all`` takes: where to write, the quick versions or the full ones, which figures."""

    out: Path = Path("docs/figures")
    quick: bool = False
    only: tuple[str, ...] = ()
    """Names of ``FIGURES`` to run (empty: all of them)."""
    timeout_s: float = 4 * 3600.0
    """Longest one bench may take before it is stopped and recorded as failed."""


@dataclass
class Outcome:
    """What one bench command did: its exit status, its wall time, the machine's load around it, its output."""

    name: str
    command: str
    status: int
    wall_s: float
    load_before: tuple[float, float, float]
    load_after: tuple[float, float, float]
    table: str
    plots: list[str] = field(default_factory=list)
    quoted_in: str = ""
    made_by: str = ""
    """The ``petswarm bench all`` command whose run made this figure."""
    date: str = ""
    """When that run started (UTC, ISO 8601)."""
    machine: dict[str, Any] = field(default_factory=dict)
    quick: bool = False


def select(names: Sequence[str]) -> list[Figure]:
    """The figures named (all when none are); ValueError naming an unknown one and the known ones."""
    known = {figure.name: figure for figure in FIGURES}
    unknown = [name for name in names if name not in known]
    if unknown:
        raise ValueError(f"no figure {', '.join(unknown)} (known: {', '.join(known)})")
    return [figure for figure in FIGURES if not names or figure.name in names]


def machine() -> dict[str, Any]:
    """The machine a figure was measured on: CPU, cores, memory, OS, Python, numpy and petswarm's commit."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    memory_gib = None
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                memory_gib = round(int(line.split()[1]) / 2**20, 1)
    except OSError:
        pass
    import numpy

    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "memory_gib": memory_gib,
        "os": platform.platform(),
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "commit": _commit(),
        # at niceness 19 (nice -n 19) a loaded machine's other work comes first: the wall-clock benches show it
        "nice": os.nice(0),
    }


def _commit() -> str:
    try:
        done = subprocess.run(
            ["git", "describe", "--always", "--dirty"],
            capture_output=True,
            text=True,
            timeout=10,
            cwd=ROOT,
        )
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return done.stdout.strip() or "unknown"


def _load() -> tuple[float, float, float]:
    try:
        one, five, fifteen = os.getloadavg()
    except OSError:
        nan = float("nan")  # no load average on this system
        return (nan, nan, nan)
    return (round(one, 2), round(five, 2), round(fifteen, 2))


def run_one(figure: Figure, out: Path, quick: bool, timeout_s: float, made_by: str = "", date: str = "") -> Outcome:
    """Run one bench in a fresh process with its own ``--out`` folder; its table is what it printed. The folder gets
    ``figure.json`` and ``figure.md`` (``write_figure``) once the bench has ended."""
    folder = out / figure.name
    folder.mkdir(parents=True, exist_ok=True)
    args = [*(figure.quick if quick else figure.args), "--out", str(folder)]
    command = "petswarm bench " + shlex.join(args)
    argv = [sys.executable, "-m", "cli", "bench", *args[:-1], str(folder.resolve())]
    before, start = _load(), time.monotonic()
    try:
        done = subprocess.run(argv, capture_output=True, text=True, timeout=timeout_s, cwd=ROOT)
        status, table = done.returncode, done.stdout
        if done.returncode != 0:
            table += "\n" + "\n".join(done.stderr.strip().splitlines()[-20:])
    except subprocess.TimeoutExpired as err:
        status, table = 124, f"stopped after {timeout_s:g} s\n{err.stdout or ''}"
    wall = time.monotonic() - start
    table = table.replace(str(folder.resolve()), str(folder))  # the folder as given, not this machine's path to it
    (folder / "table.txt").write_text(table)
    plots = sorted(str(p.relative_to(out)) for p in folder.glob("*.png"))
    outcome = Outcome(figure.name, command, status, round(wall, 1), before, _load(), table, plots, figure.quoted_in)
    outcome.made_by, outcome.date, outcome.machine, outcome.quick = made_by, date, machine(), quick
    write_figure(folder, outcome)
    return outcome


def figure_header(o: Outcome) -> str:
    """The header a figure stands under wherever it is shown: the command that made it, when, on what machine and
    at what load, and the bench's own command."""
    host = o.machine
    when = o.date[:16].replace("T", " ") + " UTC" if o.date else "unknown date"
    where = f"{host.get('cpu')}, {host.get('cores')} cores, petswarm {host.get('commit')}" if host else "unknown"
    where += f", niceness {host['nice']}" if host.get("nice") else ""
    return (
        f"Generated by `{o.made_by}` ({when}; {where}): `{o.command}`, exit {o.status}, {o.wall_s:g} s, "
        f"load {o.load_before[0]:g} -> {o.load_after[0]:g}" + (" (--quick: not the documented figures)" * o.quick)
    )


def figure_markdown(o: Outcome, plot_prefix: str = "") -> list[str]:
    """A figure as Markdown: its header, its table, its plots (their paths relative to the figures folder, after
    ``plot_prefix``)."""
    return [
        f"*{figure_header(o)}*",
        "",
        "```text",
        o.table.rstrip() or "(no output)",
        "```",
        "",
        *(f"![{o.name}]({plot_prefix}{plot})\n" for plot in o.plots),
    ]


def write_figure(folder: Path, o: Outcome) -> None:
    """``figure.json`` and ``figure.md`` in a figure's folder: what the guide's pages include."""
    (folder / "figure.json").write_text(json.dumps(asdict(o), indent=2) + "\n")
    lines = ["<!-- generated by petswarm bench all: rerun the command below rather than editing this file -->", ""]
    (folder / "figure.md").write_text("\n".join([*lines, *figure_markdown(o, "../")]))


def read_figures(out: Path) -> list[Outcome]:
    """The figures made so far under ``out`` (by this run or an earlier one), in ``FIGURES``' order."""
    found = []
    for figure in FIGURES:
        path = out / figure.name / "figure.json"
        if path.exists():
            data = json.loads(path.read_text())
            data["load_before"], data["load_after"] = tuple(data["load_before"]), tuple(data["load_after"])
            found.append(Outcome(**data))
    return found


def header(command: str, started: datetime, host: dict[str, Any], loads: Sequence[tuple[float, ...]]) -> list[str]:
    """The one header every figure of a run of ``bench all`` stands under."""
    ones = [load[0] for load in loads]
    return [
        "# Figures",
        "",
        "<!-- generated by petswarm bench all: rerun the command below rather than editing this page -->",
        "",
        f"- **command**: `{command}`",
        f"- **date**: {started.strftime('%Y-%m-%d %H:%M UTC')}",
        f"- **machine**: {host['cpu']}, {host['cores']} cores, {host['memory_gib']} GiB; {host['os']}; "
        f"Python {host['python']}, numpy {host['numpy']}; petswarm {host['commit']}",
        f"- **load average** (1 min) over the run: {min(ones):g}-{max(ones):g}; niceness {host.get('nice', 0)}",
        "",
    ]


def write_index(out: Path, command: str, quick: bool, started: datetime, outcomes: list[Outcome]) -> Path:
    """``index.md`` (for people and the guide) and ``figures.json`` (for programs) under ``out``: this run's header,
    then every figure under ``out``, this run's and those an earlier run made (``--only`` reruns some), each
    with the header of the run that made it."""
    host = machine()
    loads = [load for o in outcomes for load in (o.load_before, o.load_after)] or [_load()]
    lines = header(command, started, host, loads)
    if quick:
        lines += ["!!! warning", "    `--quick`: a few runs of each bench, to check the chain; not the figures.", ""]
    figures = read_figures(out)
    for o in figures:
        lines += [
            f"## {o.name}",
            "",
            f"`{o.command}` (exit {o.status}, {o.wall_s:g} s, load {o.load_before[0]:g} -> {o.load_after[0]:g};"
            f" quoted in {o.quoted_in})",
            "",
            *figure_markdown(o),
        ]
    index = out / "index.md"
    index.write_text("\n".join(lines))
    record = {"command": command, "date": started.isoformat(), "quick": quick, "machine": host}
    record["figures"] = [asdict(o) for o in figures]
    (out / "figures.json").write_text(json.dumps(record, indent=2) + "\n")
    return index


def plan_markdown() -> list[str]:
    """What ``bench all`` runs, one section per figure (the anchors the guide links to), full and quick."""
    lines: list[str] = []
    for f in FIGURES:
        lines += [
            f"## {f.name}",
            "",
            f"`petswarm bench {shlex.join(f.args)}` (quick: `petswarm bench {shlex.join(f.quick)}`), quoted in"
            f" {f.quoted_in}.",
            "",
        ]
    return lines


def bench_all(options: AllOptions, progress: Callable[[str], None] | None = None) -> int:
    """Run the figures' benches in order; 0 when every one exited 0, else 1 (each outcome is in the index); 130 when
    interrupted (Ctrl-C), with the index of the benches that finished."""
    say = progress or (lambda text: print(text, file=sys.stderr, flush=True))
    figures = select(options.only)
    options.out.mkdir(parents=True, exist_ok=True)
    started = datetime.now(UTC)
    command = "petswarm bench all --out " + shlex.quote(str(options.out))
    command += " --quick" * options.quick + (f" --only {','.join(options.only)}" if options.only else "")
    outcomes: list[Outcome] = []
    write_index(options.out, command, options.quick, started, outcomes)
    for i, figure in enumerate(figures, 1):
        args = figure.quick if options.quick else figure.args
        say(f"[bench all] {i}/{len(figures)} {figure.name}: petswarm bench {shlex.join(args)}")
        try:
            outcome = run_one(figure, options.out, options.quick, options.timeout_s, command, started.isoformat())
        except KeyboardInterrupt:  # subprocess.run has stopped the bench; the page keeps what finished
            say(
                f"[bench all] interrupted during {figure.name}; {len(outcomes)} finished, in {options.out / 'index.md'}"
            )
            return 130
        say(f"[bench all] {figure.name}: exit {outcome.status} in {outcome.wall_s:g} s")
        outcomes.append(outcome)
        write_index(options.out, command, options.quick, started, outcomes)  # a stopped run keeps what it did
    index = write_index(options.out, command, options.quick, started, outcomes)
    failed = [o.name for o in outcomes if o.status != 0]
    say(f"[bench all] {len(outcomes) - len(failed)}/{len(outcomes)} benches exited 0; {index}")
    if failed:
        say(f"[bench all] exited non-zero: {', '.join(failed)}")
    return 1 if failed else 0
