"""Argument types shared by the subcommands (their parsers live in ``cli/``): each gives a clear message on bad
input."""

from __future__ import annotations

import argparse
import json
import math
import os
from collections.abc import Callable
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from petswarm.controllers.surround import SurroundConfig

CLOCKS = ("wall", "model", "lockstep")
"""The clocks a run takes (``petswarm run --clock``, an experiment's ``[run] clock``; docs/DESIGN.md "Time")."""


def int_auto(text: str) -> int:
    """An integer in decimal or with a 0x / 0o / 0b prefix (PAN IDs are usually written in hex)."""
    try:
        return int(text, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer (decimal or 0x...)") from None


def bounded(kind: Callable[[str], float], low: float, high: float) -> Callable[[str], float]:
    """A number of ``kind`` in [low, high]."""

    def parse(text: str) -> float:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {'an integer' if kind is int else 'a number'}") from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"{value} is outside {low:g}..{high:g}")
        return value

    return parse


def position(text: str) -> tuple[float, float]:
    """``x,y`` in metres."""
    try:
        x, y = (float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a position 'x,y' in metres") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise argparse.ArgumentTypeError(f"{text!r}: a position must be finite")
    return (x, y)


MAX_SEED = (1 << 64) - 1
"""The largest seed: every seed travels in msgpack (the hub's stats, a run's manifest), which stops at 2^64 - 1."""


def seed(text: str) -> int:
    """A non-negative integer seed, at most ``MAX_SEED``."""
    value = int_auto(text)
    if not 0 <= value <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"seed must be in 0..2^64-1, got {text[:40]}")
    return value


ROSTER_MAX = 100_000
"""Node ids a hub's ``--roster`` takes at most (as many as a lockstep hub's ``--expect``)."""


def node_ids(text: str) -> tuple[str, ...]:
    """Comma-separated node ids (``robot-1,robot-2,user-1``), each a node name, ``ROSTER_MAX`` at most."""
    from radio_hub.interface import check_name

    ids = tuple(dict.fromkeys(part.strip() for part in text.split(",") if part.strip()))
    if len(ids) > ROSTER_MAX:
        raise argparse.ArgumentTypeError(f"at most {ROSTER_MAX} node ids, got {len(ids)}")
    try:
        return tuple(check_name("node", node_id) for node_id in ids)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)[:200]) from None


def link_key_file(text: str) -> str:
    """A file holding a 128-bit 802.15.4 network key (32 hex digits), made absolute for child processes."""
    from radio_hub.interface import read_key_file

    try:
        read_key_file(text)
    except (OSError, ValueError) as err:
        raise argparse.ArgumentTypeError(f"{text}: {getattr(err, 'strerror', None) or err}") from None
    return os.path.abspath(text)


def world_name(text: str) -> str:
    """A world name: it becomes a chunk of every key (``radio_hub.interface.Keys``)."""
    from radio_hub.interface import Keys

    try:
        return Keys(text).world
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def robot_id(text: str) -> int:
    """A robot id 1..65533, or ``auto`` (0) to claim a free one at the hub."""
    if text == "auto":
        return 0
    value = int_auto(text)
    if not 1 <= value <= 0xFFFD:
        raise argparse.ArgumentTypeError(f"robot id {value} is outside 1..65533 (it is the 16-bit short address)")
    return value


def surround_config(text: str) -> SurroundConfig:
    """A JSON object of surround law settings (``SurroundConfig`` fields; the others keep their defaults)."""
    from petswarm.controllers.surround import SurroundConfig

    try:
        data = json.loads(text)
        return SurroundConfig.from_dict(data)
    except (json.JSONDecodeError, ValueError, TypeError) as err:
        raise argparse.ArgumentTypeError(f"surround config {text!r}: {err}") from None


def readable_file(text: str) -> str:
    """A path to a file this process can read (certificates, keys, config files), made absolute so that it
    still holds for child processes started elsewhere."""
    if not os.path.isfile(text) or not os.access(text, os.R_OK):
        raise argparse.ArgumentTypeError(f"{text!r} is not a readable file")
    return os.path.abspath(text)
