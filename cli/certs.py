"""``petswarm certs``: its command line (the work is ``petswarm.lab.certs``)."""

from __future__ import annotations

import argparse

from cli.text import plain
from petswarm.lab import certs
from petswarm.lab.arguments import bounded


def add_certs(sub: argparse._SubParsersAction) -> None:
    """The ``certs`` subcommand."""
    p = sub.add_parser(
        "certs",
        help="make a CA and TLS certificates for a hub and its nodes on several hosts (needs openssl)",
        description=plain(certs.__doc__ or ""),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", required=True, help="directory for the PEM files (created 0700)")
    p.add_argument(
        "--hub-host",
        required=True,
        help="names or IP addresses clients dial the hub by, comma-separated (e.g. 10.0.0.1,hub.lab)",
    )
    p.add_argument("--robots", type=bounded(int, 0, 65533), default=4, help="robot-1..robot-N (default 4)")
    p.add_argument("--users", type=bounded(int, 0, 65533), default=1, help="user-1..user-N (default 1)")
