"""The decisions of network formation (paper section 3.4): Tables 1 and 2, the PAN choice, reply slots,
and what a master does on hearing another master of its own swarm (the project's rule: the paper has none).

Pure functions, unit-tested; the formation procedures call them.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Mapping
from enum import Enum
from typing import TYPE_CHECKING

from petswarm.managers.messages import Refusal
from radio_hub.values import lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

WAITING_PAN = 0x1000
"""The PAN every waiting robot starts on (``petswarm.robot.DEFAULT_PAN``): here, so that a run's orchestrator
knows it without loading the robot middleware."""
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


class Rival(Enum):
    """What a master does with a Roster of its own session that another robot sent."""

    IGNORE = "ignore"
    """Not a rival: a former master's late roster, or a robot outside this swarm."""
    FOLLOW = "follow"
    """The robot this master tried to hand its role to took it (the acceptance was lost): follow that handover."""
    YIELD = "yield"
    """A rival master that outranks this one and counts it: follow it as a handover learned from its roster."""
    LEAVE = "leave"
    """A rival master that outranks this one and does not count it: give up the role and the swarm."""
    KEEP = "keep"
    """A rival master this one outranks: keep the role; the rival's own rule makes it yield."""


def rival_master(
    me: int, sender: int, members: Collection[int], former_masters: Collection[int], handed_to: int | None, listed: bool
) -> Rival:
    """A master (``me``) hears a Roster of its own session from ``sender``; ``members`` are its members,
    ``former_masters`` the masters it knows handed over, ``handed_to`` the robot of its unaccepted handover
    (None when there is none), ``listed`` whether the roster counts ``me``.

    The target of an unaccepted handover wins whatever its address: it took the role, and every member that
    heard its rosters already follows it. Otherwise two masters of one swarm can only have come from two
    handovers in a row, and the spec has no rule: the lower short address keeps the role. Both ends decide
    from the two addresses alone (a Roster carries no term or epoch, and anything else, such as which one
    holds the user, only one side knows), so exactly one of them yields: never neither (two masters go on),
    never both (no master: the members fall back to waiting). Lower, as Table 2's ties go to the lower address.
    """
    if sender == me:
        return Rival.IGNORE
    if sender == handed_to:
        return Rival.FOLLOW
    if sender in former_masters or sender not in members:
        return Rival.IGNORE
    if me < sender:
        return Rival.KEEP
    return Rival.YIELD if listed else Rival.LEAVE
