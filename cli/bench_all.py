"""``petswarm bench all``: its options, and the call into ``petswarm.bench.all`` with typed options."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``petswarm bench all``."""
    from petswarm.bench.all import FIGURES

    parser.add_argument(
        "--out",
        default="docs/figures",
        help="folder for every bench's JSON and plots, index.md and figures.json (default %(default)s)",
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="a few runs of each bench: checks that every bench and the index work, in minutes; not the figures",
    )
    parser.add_argument(
        "--only",
        type=_names,
        default=(),
        help=f"comma-separated figures to run (default: all: {','.join(f.name for f in FIGURES)})",
    )


def _names(text: str) -> tuple[str, ...]:
    from petswarm.bench.all import select

    names = tuple(part.strip() for part in text.split(",") if part.strip())
    try:
        select(names)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None
    return names


def run(args: argparse.Namespace) -> int:
    """Parsed options -> ``petswarm.bench.all.bench_all``."""
    from petswarm.bench.all import AllOptions, bench_all

    return bench_all(AllOptions(out=Path(args.out), quick=args.quick, only=args.only))
