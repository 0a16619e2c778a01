"""The decisions of network formation (paper section 3.4): Tables 1 and 2, the PAN choice, reply slots.

Pure functions, unit-tested; the formation procedures call them.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from petswarm.messages import Refusal

SWARM_PANS = range(0x2000, 0xFFFE)
"""Swarm PAN IDs are drawn from here; the waiting PAN and the broadcast PAN lie outside it."""


def may_join(connected_user: int, rssi_dbm: float, min_rssi_dbm: float) -> Refusal | None:
    """Table 1: None when the robot can join, else why not. Connection is checked before the region."""
    if connected_user:
        return Refusal.CONNECTED_TO_USER
    if rssi_dbm < min_rssi_dbm:
        return Refusal.OUTSIDE_REGION
    return None


def select_members(available: Mapping[int, float], required: int) -> list[int]:
    """Table 2: all available robots when they are not more than required, else the closest ones.

    ``available`` maps a robot's short address to its signal strength as the master judges it (higher is
    closer); ties go to the lower address so the choice is reproducible.
    """
    ranked = sorted(available, key=lambda addr: (-available[addr], addr))
    return ranked[: max(required, 0)]


def choose_pan(rng: np.random.Generator, pans_in_use: Iterable[int]) -> int:
    """A swarm PAN ID that no PAN seen on the channel uses."""
    used = set(pans_in_use)
    while True:
        pan = int(rng.integers(SWARM_PANS.start, SWARM_PANS.stop))
        if pan not in used:
            return pan


def reply_delay_s(short_addr: int, slot_ms: int, pending: tuple[int, ...] = (), slots: int = 8) -> float:
    """The improved protocol's answer slot, so that answers to one broadcast request do not all start in
    the same instant: the robot's place in the request's ``pending`` list, else its address modulo
    ``slots``. 0 when the slot length is 0 (the paper's protocol: answer at once)."""
    if slot_ms <= 0:
        return 0.0
    index = pending.index(short_addr) if short_addr in pending else short_addr
    return index % slots * slot_ms / 1000.0
