"""``petswarm explore``'s arguments (the work is petswarm/explore/main.py's)."""

from __future__ import annotations

import argparse

from petswarm.lab.arguments import bounded, seed

EXPLORE_HELP = """Generate cases from a seed (a world, a mission, a fault schedule), run each in model time, check
named safety and liveness properties on its record, shrink each failure to a small scenario file and print the
command replaying it. Exit status: 0 no case failed, 1 a case failed, 2 bad arguments or file.

examples:
  petswarm explore --seed 1 --cases 200 --workers 2         200 cases on two local processes
  petswarm explore --seed 1 --case 17                       case 17 alone (the same case as in the campaign)
  petswarm explore --seed 1 --cases 50 --family organize,drive:2
  petswarm explore --seed 1 --cases 2000 --scheduler tcp://127.0.0.1:8786   on a Dask cluster
  petswarm explore --replay runs/explore-1/case-17-organize_completes.toml
"""


def add_explore(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """The ``explore`` subcommand."""
    exp = sub.add_parser(
        "explore",
        help="seed-driven exploration: generated worlds, missions and faults in model time, checked and shrunk",
        description=EXPLORE_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    exp.add_argument("--seed", type=seed, default=1, help="the campaign's seed: case i draws from (seed, i) only")
    exp.add_argument("--cases", type=bounded(int, 1, 10_000_000), default=100, help="cases 0..N-1 (default 100)")
    exp.add_argument("--case", type=bounded(int, 0, 10_000_000), default=None, help="run case i alone")
    exp.add_argument(
        "--family",
        default=None,
        help="families and weights, e.g. organize,drive:2 (families: organize, drive, surround, pings, follow, "
        "mixed; default all, weights 3,3,1,1,1,2)",
    )
    where = exp.add_mutually_exclusive_group()
    where.add_argument("--workers", type=bounded(int, 1, 256), default=1, help="local worker processes (default 1)")
    where.add_argument(
        "--scheduler", metavar="ADDRESS", help="a Dask distributed scheduler (pip install petswarm[explore])"
    )
    exp.add_argument("--replay", metavar="FILE", help="rerun a scenario file explore wrote, and check its properties")
    exp.add_argument(
        "--out", help="directory for results.json, results.txt, failures.png, shrunk cases (runs/explore-SEED)"
    )
    exp.add_argument(
        "--shrink", type=bounded(int, 0, 1000), default=5, help="shrink at most this many failures (default 5)"
    )


def explore(args: argparse.Namespace) -> int:
    """Run ``petswarm explore``."""
    import petswarm
    from cli.options import options_of
    from petswarm.explore.main import ExploreOptions

    return petswarm.run_explore(options_of(ExploreOptions, args))
