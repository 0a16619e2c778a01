"""Formation geometry and the master's placement (swarm paper section 3.5-3.6, Table 3). Pure functions.

A formation is a list of *slots*: each member's reference location in the master's frame (x forward, the
direction the swarm drives; y left). Member numbers are the swarm's (0 = the master at the origin, then the
joining order). Slaves always trail the master: in following mode the user is ahead of the master, so the
master is the robot closest to the user; in leading mode the user is behind the whole formation and the
master, at its front, is the farthest. A driving-mode change comes with the user's turn-about (the papers'
trajectory experiment), so the direction of travel reverses by pi (``mode_change``).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from petswarm.controllers.motion import Vec

STANDARD_DISTANCE_M = 1.0
"""The papers' standard user-robot distance."""
WEDGE_ARM_RAD = math.radians(45)
"""Angle of each wedge arm from the backward axis. The paper's figure is an image; 45 degrees puts the two
robots of a rank sqrt(2) spacings apart and a rank 0.71 spacing behind the one before, so the wedge is as
deep as it is wide and no two robots are nearer than the spacing."""


class Shape(enum.StrEnum):
    """Formation shapes the user can ask for."""

    LINE = "line"
    COLUMN = "column"
    WEDGE = "wedge"


class Mode(enum.StrEnum):
    """Driving mode of the swarm (and of a single robot)."""

    FOLLOWING = "following"
    LEADING = "leading"

    @property
    def user_side(self) -> UserSide:
        """Where the user is, seen along the direction of travel."""
        return UserSide.AHEAD if self is Mode.FOLLOWING else UserSide.BEHIND


class UserSide(enum.StrEnum):
    """The user's side of the formation along the direction of travel."""

    AHEAD = "ahead"
    BEHIND = "behind"


@dataclass(frozen=True)
class ModeChange:
    """The outcome of Table 3: who is master and every member's slot in the new master's frame.

    ``mirrored`` is True when the slots were mirrored to the other side of the master (No change column):
    the slaves must drive round to the master's other side. Neighbour pairs are kept by member number in
    both columns (``neighbours``); only the reference locations move.
    """

    new_master: int
    slots_by_member: dict[int, Vec]
    mirrored: bool


def slots(shape: Shape | str, members: int, spacing: float) -> list[Vec]:
    """Reference offsets in the master's frame for members 0..members-1 (member 0, the master, at (0, 0)).

    column: one behind the other. line: side by side, alternately left and right of the master, so the
    master stays in the middle. wedge: a V opening backward, odd members on the left arm, even on the right.
    """
    shape = Shape(shape)
    if members < 1:
        raise ValueError(f"members must be at least 1, got {members!r}")
    if not spacing > 0:
        raise ValueError(f"spacing must be positive, got {spacing!r}")
    out: list[Vec] = [(0.0, 0.0)]
    for member in range(1, members):
        rank, side = (member + 1) // 2, (1.0 if member % 2 else -1.0)
        if shape is Shape.COLUMN:
            out.append((-member * spacing, 0.0))
        elif shape is Shape.LINE:
            out.append((0.0, side * rank * spacing))
        else:
            arm = rank * spacing
            out.append((-arm * math.cos(WEDGE_ARM_RAD), side * arm * math.sin(WEDGE_ARM_RAD)))
    return out


def neighbours(shape: Shape | str, member: int) -> list[int]:
    """The members whose relative location ``member`` keeps (besides the master's): one, toward the master.

    column: the one ahead; wedge: the one ahead on its own arm; line: the one beside it, toward the master.
    The master keeps none. Members next to the master have the master itself as neighbour.
    """
    shape = Shape(shape)
    if member < 0:
        raise ValueError(f"member must not be negative, got {member!r}")
    if member == 0:
        return []
    if shape is Shape.COLUMN:
        return [member - 1]
    return [max(member - 2, 0)]


def _as_mapping(slot_list: Sequence[Vec] | Mapping[int, Vec]) -> dict[int, Vec]:
    if isinstance(slot_list, Mapping):
        return dict(slot_list)
    return dict(enumerate(slot_list))


def depth_toward_user(slot_list: Sequence[Vec] | Mapping[int, Vec], user_side: UserSide | str) -> float:
    """How far the formation reaches from the master's origin toward the user (m, never negative)."""
    side = UserSide(user_side)
    xs = [x for x, _ in _as_mapping(slot_list).values()]
    if not xs:
        raise ValueError("slots must not be empty")
    reach = max(xs) if side is UserSide.AHEAD else -min(xs)
    return max(reach, 0.0)


def master_target_distance(
    mode: Mode | str,
    slot_list: Sequence[Vec] | Mapping[int, Vec],
    master: int = 0,
    standard_m: float = STANDARD_DISTANCE_M,
) -> float:
    """The master's user distance: the standard 1 m plus the formation's depth between the master and the user,
    so the robot nearest the user keeps about the standard distance (in following mode usually the master)."""
    by_member = _as_mapping(slot_list)
    if master not in by_member:
        raise ValueError(f"master {master!r} has no slot")
    mx, my = by_member[master]
    shifted = {k: (x - mx, y - my) for k, (x, y) in by_member.items()}
    return standard_m + depth_toward_user(shifted, Mode(mode).user_side)


def hierarchy_levels(distance_to_user: Mapping[int, float]) -> dict[int, int]:
    """Hierarchy levels 1, 2, ... from the robot farthest from the user to the closest (ties: lower member first).

    Level 1 is the highest in the hierarchy: the leading-mode master, moved first.
    """
    order = sorted(distance_to_user, key=lambda k: (-distance_to_user[k], k))
    return {member: level for level, member in enumerate(order, start=1)}


def choose_master(mode: Mode | str, distance_to_user: Mapping[int, float]) -> int:
    """Following: the robot closest to the user; leading: the farthest, level 1 (ties: the lower member)."""
    if not distance_to_user:
        raise ValueError("distance_to_user must not be empty")
    if Mode(mode) is Mode.FOLLOWING:
        return min(distance_to_user, key=lambda k: (distance_to_user[k], k))
    levels = hierarchy_levels(distance_to_user)
    return min(levels, key=levels.__getitem__)


def mode_change(
    old_mode: Mode | str,
    new_mode: Mode | str,
    change_master: bool,
    members: Sequence[int],
    distances: Mapping[int, float],
    slot_list: Sequence[Vec] | Mapping[int, Vec],
    master: int = 0,
) -> ModeChange:
    """Table 3: the master and the slots after a driving-mode change that comes with the user's turn-about.

    Change: the master becomes the closest robot (-> following) or the highest in the hierarchy (-> leading);
    every robot keeps its place, its slot re-expressed in the new master's frame turned by pi. No change: the
    master stays, and the slots are mirrored to its other side (x -> -x in the new frame), so the formation
    again trails the master along the new direction of travel. ``slot_list`` is in the old master's frame,
    ``master`` names the old master, ``distances`` are each member's distances to the user.
    """
    old, new = Mode(old_mode), Mode(new_mode)
    by_member = _as_mapping(slot_list)
    missing = [k for k in members if k not in by_member or k not in distances]
    if missing:
        raise ValueError(f"members {missing} lack a slot or a distance")
    if master not in members:
        raise ValueError(f"master {master!r} is not among the members")
    current = {k: by_member[k] for k in members}
    if old is new:
        return ModeChange(master, current, mirrored=False)
    if change_master:
        new_master = choose_master(new, {k: distances[k] for k in members})
        return ModeChange(new_master, kept_slots(current, new_master), mirrored=False)
    mx, my = current[master]
    # turned by pi (-dx, -dy), then mirrored across the master's lateral axis: (dx, -dy)
    return ModeChange(master, {k: (x - mx, my - y) for k, (x, y) in current.items()}, mirrored=True)


def kept_slots(slot_list: Sequence[Vec] | Mapping[int, Vec], new_master: int) -> dict[int, Vec]:
    """Table 3's Change column: every robot keeps its place, its slot re-expressed in the frame of
    ``new_master`` after the turn-about (the old frame turned by pi about the new master:
    (dx, dy) -> (-dx, -dy)). Keys are whatever names the robots (member numbers or addresses)."""
    by_member = _as_mapping(slot_list)
    if new_master not in by_member:
        raise ValueError(f"new master {new_master!r} has no slot")
    nx, ny = by_member[new_master]
    return {k: (nx - x, ny - y) for k, (x, y) in by_member.items()}


def handover_chain(kept: Mapping[int, Vec], new_master: int) -> tuple[int, ...]:
    """The swarm's new member order after a handover: the new master, then the others by their distance
    from it (closest first, ties in the old order), as organizing numbers members closest first. A column
    whose last robot takes over comes out reversed, so the shape's own slot list still describes it."""
    if new_master not in kept:
        raise ValueError(f"new master {new_master!r} has no slot")
    order = list(kept)
    others = sorted((k for k in order if k != new_master), key=lambda k: (math.hypot(*kept[k]), order.index(k)))
    return (new_master, *others)
