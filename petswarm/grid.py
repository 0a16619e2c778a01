"""Instants on a periodic grid: pure arithmetic, shared by the robot's runtimes (on the loop's clock) and its
sans-IO cores (handed ``now``), so both set a periodic timer's instants the same way to the last bit.
"""

from __future__ import annotations


def next_on_grid(last: float, period: float, after: float) -> float:
    """The first instant later than ``after`` on the grid ``last``, ``last + period``, ...: summed a period at a
    time, as a periodic timer that had gone on would have set each of its instants (a product could round
    differently, and model time compares instants exactly). A pure function: sans-IO cores use it too."""
    at = last + period
    while at <= after:
        at = at + period
    return at
