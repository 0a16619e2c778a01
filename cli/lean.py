"""What a robot process leaves out: OpenSSL (issue 13, a robot process's peak RSS at most 50 MB).

A robot speaks plain TCP to its hub through zenoh (which brings its own TLS, unused) and hashes nothing,
yet ``asyncio`` imports ``ssl`` when it can, and ``secrets`` (the radio's instance id) imports ``hmac`` and
with it ``_hashlib``: both map OpenSSL's libcrypto, about 4.7 MB of every robot process's resident memory.
Marking both modules absent before anything imports them keeps them out; asyncio then runs without TLS
support and ``hashlib`` falls back on Python's own hashes, which is all a robot uses.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

OPENSSL_MODULES = ("ssl", "_hashlib")
"""The standard library's OpenSSL bindings."""

LEAN_COMMANDS = ("robot",)
"""The ``petswarm`` commands that run without OpenSSL."""


def leave_out_openssl(argv: Sequence[str]) -> bool:
    """When ``argv`` (``sys.argv[1:]``) runs a robot, mark OpenSSL's modules absent; True when it did.

    Must run before ``asyncio`` is imported; a module imported already stays."""
    if not argv or argv[0] not in LEAN_COMMANDS:
        return False
    for name in OPENSSL_MODULES:
        sys.modules.setdefault(name, None)  # type: ignore[assignment]  # None makes its import fail
    return True
