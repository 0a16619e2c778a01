"""The swarm paper's measured figures (Kim, Kim & Kang, Sensors 2017, section 4) beside a bench's own.

Only the figures issue 19 names, as the issue reads them off the paper: the minimum organizing time for 1-5
slaves (Fig. 22, "about 0.6-0.8 s", taken as rising evenly from 0.6 s with one slave to 0.8 s with five),
the 90th percentiles of the reaction times (Figs. 20-21) and the IR errors with equations (1)-(3) (Table 4).
A bench prints each beside its own figure with the ratio (bench / paper), puts them in its JSON and draws
them on its plot; under the testbed's profile a ratio within ``TOLERANCE`` of 1 is marked as matching.
"""

from __future__ import annotations

import math
from typing import Any

TOLERANCE = 0.2
"""The issue's goal: every figure within 20 % of the paper's."""
ORGANIZE_MIN_S = {1: 0.60, 2: 0.65, 3: 0.70, 4: 0.75, 5: 0.80}
"""Fig. 22: the fastest organization (no retry) by number of slaves."""
REACTION_P90_S = {"master_s": 1.1, "slave_s": 1.2, "slave_minus_master_s": 0.24}
"""Figs. 20-21: 90th percentile of the master's and the slaves' reaction, and of slave minus master."""
TESTBED_PROFILE = "kim2017"
"""The profile that emulates the paper's testbed: only under it is a figure far from the paper's a finding."""
IR_RMSE = {"distance_cm": 7.898, "direction_deg": 5.8}
"""Table 4: RMSE of distance and direction with equations (1)-(3) (the ``paper`` estimator)."""


def row(figure: str, paper: float, bench: float | None) -> dict[str, Any]:
    """One figure: the paper's value, the bench's, their ratio and whether it is within the tolerance."""
    ratio = bench / paper if bench is not None and not math.isnan(bench) else math.nan
    return {
        "figure": figure,
        "paper": paper,
        "bench": bench,
        "ratio": round(ratio, 3),
        "within_20pct": abs(ratio - 1) <= TOLERANCE,
    }


def lines(rows: list[dict[str, Any]], profile: str) -> list[str]:
    """The comparison as a table, each figure marked ``ok`` or ``off`` (within 20 % or not) under the testbed's
    profile; under another (``ideal``, the default) the ratios are shown unmarked: the bench then leaves out the
    testbed's delays, so a figure far from the paper's is expected, not a failure."""
    judged = profile == TESTBED_PROFILE
    if judged:
        out = [f"the paper's figures beside this bench's (profile {profile}; within 20 %: ok)"]
    else:
        out = [
            f"the paper's figures beside this bench's, for reference: profile {profile} does not emulate the paper's "
            f"testbed (--profile {TESTBED_PROFILE} does), so the ratios are not judged"
        ]
    out.append(f"{'figure':<44}{'paper':>9}{'bench':>9}{'ratio':>8}")
    for r in rows:
        bench = "-" if r["bench"] is None else f"{r['bench']:.3f}"
        mark = ("ok" if r["within_20pct"] else "off") if judged else ""
        out.append(f"{r['figure']:<44}{r['paper']:>9.3f}{bench:>9}{r['ratio']:>8.2f}  {mark}".rstrip())
    return out
