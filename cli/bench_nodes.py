"""``python -m cli.bench_nodes echo|load ...``: the child processes of ``petswarm bench hub`` (the echo node and
the load generators), parsed here and run by ``petswarm.bench.hub.run_child``."""

from __future__ import annotations

import argparse


def build_parser() -> argparse.ArgumentParser:
    """The children's command line."""
    parser = argparse.ArgumentParser(prog="python -m cli.bench_nodes", description="children of petswarm bench hub")
    sub = parser.add_subparsers(dest="role", required=True)
    echo = sub.add_parser("echo", help="answer radio frames and plain zenoh requests")
    load = sub.add_parser("load", help="attach load-test nodes on one session and keep the senders busy")
    for p in (echo, load):
        p.add_argument("--hub", required=True)
        p.add_argument("--world", required=True)
    for name in ("--first", "--last", "--nodes"):
        load.add_argument(name, type=int, required=True)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Parse, then run the child."""
    from petswarm.bench.hub import run_child

    args = build_parser().parse_args(argv)
    numbers = {} if args.role == "echo" else {"first": args.first, "last": args.last, "nodes": args.nodes}
    return run_child(args.role, args.hub, args.world, **numbers)


if __name__ == "__main__":
    raise SystemExit(main())
