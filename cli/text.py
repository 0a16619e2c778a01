"""Help text as a terminal shows it: the docstrings the commands reuse are written for Sphinx-like readers,
whose ``literal`` markup means nothing on a terminal."""

from __future__ import annotations

import re

_LITERAL = re.compile(r"``([^`]+)``")


def plain(text: str) -> str:
    """``text`` with its RST double-backtick literals as the bare words."""
    return _LITERAL.sub(r"\1", text)
