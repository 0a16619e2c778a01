"""From a parsed command line to a command's typed options: the petswarm function a command calls takes a
dataclass (``RunOptions``, ``IrOptions``, ``ExploreOptions``...), so a notebook calls it without argv."""

from __future__ import annotations

import argparse
from dataclasses import fields
from typing import TypeVar

T = TypeVar("T")


def options_of(cls: type[T], args: argparse.Namespace) -> T:
    """The typed options ``cls`` (a dataclass) holding what ``args`` says of each of its fields."""
    return cls(**{f.name: getattr(args, f.name) for f in fields(cls) if hasattr(args, f.name)})  # type: ignore[arg-type]
