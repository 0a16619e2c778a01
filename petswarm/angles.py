"""Angles: one wrapping rule for every heading the robots, the user's path and the controllers compute. Pure."""

from __future__ import annotations

import math


def wrap(angle: float) -> float:
    """An angle into [-pi, pi)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi
