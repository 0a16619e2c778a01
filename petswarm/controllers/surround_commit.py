"""The improved surround law's flank commitment: a robot off the walking human's lane that hears a wall ahead
decides once to go OUT round it or IN behind him, and holds that choice.

Beyond the paper (docs/SURROUND.md, "The improved law", item 11; an experiment, off by default). At the
corridor's mouth the contacts left were robots of the swarm's flanks grazing a wall's end they heard too late or
never (a neighbour nearer in every cone toward it, or the end in a blind gap between cones): slowing them there
costs the flow the centre-to-human bound needs (items 8 and 10). A robot that hears the end early, from a cone no
neighbour masks, instead commits to a side of it while there is time to move sideways:

- the wall point is an echo no tracked beacon explains, within ``commit_reach_m``, ahead of the robot along the
  human's walk and to the same side of his line as the robot, which is more than ``commit_band_m`` across it;
- OUT if the robot is further across his line than the point, IN otherwise: keep the robot's centre at least its
  radius and ``commit_margin_m`` beyond (OUT) or inside (IN) the line along his walk through the point;
- the choice is kept in the odometry frame (the robot never turns, so the point is carried back by its own
  odometry), refined by nearer echoes of the same side ahead (a nearer echo's arc is narrower), and dropped
  ``commit_hold_s`` after the wall was last heard or once the robot is past the point along his walk.

While it is not yet on its side, a lateral spring ``commit_gain`` pushes it there, and (with
``commit_brake_mps2`` > 0) its speed along his walk is held to what stops short of the point's crossing line.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

WALKING_MPS = 0.3
"""The human walks (his track's speed) above this: only then has he a lane and a direction to commit along."""
HUMAN_CLEAR_M = 0.3
"""A wall point nearer his line than this is across his way, not beside it: no side to take."""
PUSH_CAP_M = 0.3
"""The lateral spring grows with the robot's shortfall up to this much of it."""
RELEASE_M = 0.15
"""The commitment is dropped once the robot is this far past the point along his walk (beyond its radius)."""
LATE_S = 0.06
"""As the wall rule's: a command acts a control step and up to a world tick after the echoes it was made from."""

HALF_BEAM_SINE = math.sin(math.radians(15.0))
"""An echo's point lies within 15 degrees of its cone's axis: up to its range times this across it."""

OUT = 1
IN = -1


class Commitment:
    """One robot's flank commitment (see the module's docstring), in plain floats: a pilot steps it every sample."""

    def __init__(
        self,
        gain: float,
        reach_m: float,
        band_m: float,
        margin_m: float,
        hold_s: float,
        brake_mps2: float,
        from_m: float = 0.0,
        follow_mps: float = 0.0,
        lateral_mps: float = 0.0,
        room: bool = False,
        arc_share: float = 0.0,
    ) -> None:
        self.gain = gain
        self.reach_m = reach_m
        self.band_m = band_m
        self.margin_m = margin_m
        self.hold_s = hold_s
        self.brake_mps2 = brake_mps2
        self.from_m = from_m
        self.follow_mps = follow_mps
        self.lateral_mps = lateral_mps
        self.room = room
        self.arc_share = arc_share
        self.spread = 0.0
        """How far across his walk the wall point may lie off the one kept (the echo's arc: its range times the
        sine of the half beam, times ``arc_share``): the side is cleared by that much more."""
        self.mode = 0
        """OUT, IN, or 0: no commitment."""
        self.point = (0.0, 0.0)
        """The wall point committed to, in the robot's frame (carried by its odometry)."""
        self.walk = (1.0, 0.0)
        """The human's walking direction when committed (unit)."""
        self.side = 1.0
        """Which side of his line the point is on: +1 along the left normal of ``walk``, -1 the right."""
        self.quiet_s = 0.0
        """Time since the wall was last heard."""
        self.radius_m = 0.1
        self.decisions = 0
        """How many commitments this robot made (for tests and replays)."""
        self._last = (0, 0.0, math.inf)
        """The last commitment dropped: its mode, its side, and the time since (a new wall on that side soon
        after takes the same choice: no dithering between OUT and IN at the wall's end)."""

    def step(
        self,
        points: Sequence[Sequence[float]],
        explained: Sequence[bool],
        human: Sequence[float] | None,
        human_velocity: Sequence[float] | None,
        velocity: Sequence[float],
        dt: float,
        radius_m: float,
        neighbours: Sequence[Sequence[float]] = (),
        neighbour_velocities: Sequence[Sequence[float]] = (),
    ) -> None:
        """Take in one ring reading (echo points from the robot's centre, nan for none; ``explained``: a tracked
        beacon explains it) after the robot moved at ``velocity`` for ``dt``, with the human's track and the
        neighbours' (for ``follow_mps``: a robot whose way ahead a neighbour hides takes the side that neighbour
        swerves to)."""
        self.radius_m = radius_m
        if self.mode:
            self.point = (self.point[0] - velocity[0] * dt, self.point[1] - velocity[1] * dt)
            self.quiet_s += dt
        else:
            self._last = (self._last[0], self._last[1], self._last[2] + dt)
        walk = _walking(human_velocity)
        if walk is not None and human is not None:
            found = self._heard(points, explained, human, walk)
            if found is not None:
                self._take(found, human, walk, neighbours)
            elif not self.mode and self.follow_mps > 0:
                self._follow(neighbours, neighbour_velocities, human, human_velocity, walk)
        if self.mode:
            ex, ey = self.walk
            past = -(self.point[0] * ex + self.point[1] * ey)
            if self.quiet_s > self.hold_s or past > radius_m + RELEASE_M:
                self._last = (self.mode, self.side, 0.0)
                self.mode = 0

    def _heard(
        self,
        points: Sequence[Sequence[float]],
        explained: Sequence[bool],
        human: Sequence[float],
        walk: tuple[float, float],
    ) -> tuple[float, float, float] | None:
        """The nearest wall echo ahead of the robot and beside the human's lane on the robot's side: (x, y, its
        lateral offset from his line), or None."""
        ex, ey = walk
        nx, ny = -ey, ex
        mine = -(human[0] * nx + human[1] * ny)  # the robot's offset across his line
        if abs(mine) <= self.band_m:
            return None
        best = None
        for (x, y), body in zip(points, explained, strict=True):
            if body or not math.isfinite(x):
                continue
            d = math.sqrt(x * x + y * y)
            if d > self.reach_m or x * ex + y * ey <= self.radius_m + self.margin_m:
                continue
            across = (x - human[0]) * nx + (y - human[1]) * ny
            if abs(across) < HUMAN_CLEAR_M or across * mine <= 0:
                continue
            if best is None or d < best[3]:
                best = (x, y, across, d)
        return None if best is None else best[:3]

    def _take(
        self,
        found: tuple[float, float, float],
        human: Sequence[float],
        walk: tuple[float, float],
        neighbours: Sequence[Sequence[float]] = (),
    ) -> None:
        """Commit to a side of the wall point ``found``, or refine the point already committed to."""
        x, y, across = found
        side = 1.0 if across > 0 else -1.0
        if self.mode and side == self.side:
            px, py = self.point
            if x * x + y * y < px * px + py * py:
                self.point = (x, y)
                self.spread = self.arc_share * math.sqrt(x * x + y * y) * HALF_BEAM_SINE
            self.quiet_s = 0.0
            return
        if self.mode or x * x + y * y < self.from_m * self.from_m:
            # a wall on the other side: the choice made stands until it lapses; a wall first heard this near
            # is the echo memory's and the wall rule's (and often a neighbour's echo its track misplaced)
            return
        ex, ey = walk
        nx, ny = -ey, ex
        mine = -(human[0] * nx + human[1] * ny)
        last_mode, last_side, since = self._last
        if last_mode and last_side == side and since <= self.hold_s:
            self.mode = last_mode
        else:
            self.mode = OUT if abs(mine) > abs(across) else IN
            if self.room and self._blocked(self.mode, side, neighbours, walk):
                self.mode = -self.mode
        self.point, self.walk, self.side, self.quiet_s = (x, y), walk, side, 0.0
        self.spread = self.arc_share * math.sqrt(x * x + y * y) * HALF_BEAM_SINE
        self.decisions += 1

    def _follow(
        self,
        neighbours: Sequence[Sequence[float]],
        moving: Sequence[Sequence[float]],
        human: Sequence[float],
        human_velocity: Sequence[float] | None,
        walk: tuple[float, float],
    ) -> None:
        """Commit by a neighbour's swerve: the neighbour just ahead in the robot's file (the one that hides the way
        ahead from its ring) moving across the human's walk faster than ``follow_mps`` (relative to him) toward his
        line makes the robot commit IN, away from it OUT, to a wall point as far across as the robot and beyond
        that neighbour: the robot moves its radius and margin that way, as the neighbour does."""
        ex, ey = walk
        nx, ny = -ey, ex
        mine = -(human[0] * nx + human[1] * ny)
        if abs(mine) <= self.band_m or human_velocity is None:
            return
        side = 1.0 if mine > 0 else -1.0
        his = human_velocity[0] * nx + human_velocity[1] * ny
        for (x, y), (vx, vy) in zip(neighbours, moving, strict=True):
            along, across = x * ex + y * ey, x * nx + y * ny
            if not (0 < along <= 2 * self.radius_m + 0.3 and abs(across) < 2 * self.radius_m):
                continue
            outward = (vx * nx + vy * ny - his) * side
            if abs(outward) < self.follow_mps:
                continue
            self.mode = OUT if outward > 0 else IN
            self.side, self.walk, self.quiet_s = side, walk, 0.0
            # the point: level with the robot across his walk, a little beyond the neighbour along it
            reach = along + 2 * self.radius_m + RELEASE_M
            self.point = (reach * ex, reach * ey)
            self.spread = 0.0
            self.decisions += 1
            return

    def _blocked(
        self, mode: int, side: float, neighbours: Sequence[Sequence[float]], walk: tuple[float, float]
    ) -> bool:
        """Whether a neighbour stands in the way the robot would move across to take ``mode`` (level with it along
        his walk, within two diameters across on that side): the other side has the room then."""
        ex, ey = walk
        nx, ny = -ey, ex
        way = side * mode  # across his line: + away from it
        for x, y in neighbours:
            along, across = x * ex + y * ey, (x * nx + y * ny) * way
            if abs(along) < 2 * self.radius_m + 0.1 and 0 < across < 4 * self.radius_m:
                return True
        return False

    def lateral_rule(self) -> tuple[float, float, float] | None:
        """``(nx, ny, limit)``: while the robot is not on its side, it moves across toward it at least
        ``lateral_mps`` (less as it nears it): ``-dir . v <= -u`` (None: no such rule)."""
        short = self.shortfall()
        if self.lateral_mps <= 0 or short <= 0:
            return None
        ex, ey = self.walk
        sign = self.side * self.mode
        u = min(self.lateral_mps, short / 0.3)
        return ey * sign, -ex * sign, -u

    def shortfall(self) -> float:
        """How far (m) the robot still has to move across to be on its committed side; <= 0 once it is."""
        if not self.mode:
            return 0.0
        ex, ey = self.walk
        nx, ny = -ey, ex
        out = -(self.point[0] * nx + self.point[1] * ny) * self.side  # the robot's offset beyond the point
        clear = self.radius_m + self.margin_m + self.spread
        return clear - out if self.mode == OUT else clear + out

    def force(self) -> tuple[float, float]:
        """The lateral spring toward the committed side (zero once there)."""
        short = self.shortfall()
        if short <= 0 or self.gain <= 0:
            return 0.0, 0.0
        ex, ey = self.walk
        sign = self.side * self.mode
        strength = self.gain * min(short, PUSH_CAP_M)
        return -ey * sign * strength, ex * sign * strength

    def rule(self) -> tuple[float, float, float] | None:
        """``(nx, ny, limit)``: while the robot is not on its side, its speed along his walk stops short of the
        line across it through the point (None: no such limit)."""
        if self.brake_mps2 <= 0 or self.shortfall() <= 0:
            return None
        ex, ey = self.walk
        ahead = self.point[0] * ex + self.point[1] * ey - self.radius_m - self.margin_m
        if ahead < -self.radius_m:  # already level with the point: sideways is the way out
            return None
        a = self.brake_mps2
        gap = max(0.0, ahead)
        return ex, ey, max(0.0, math.sqrt(a * a * LATE_S * LATE_S + 2 * a * gap) - a * LATE_S)


def _walking(human_velocity: Sequence[float] | None) -> tuple[float, float] | None:
    """The human's walking direction (unit), or None when he is not seen walking."""
    if human_velocity is None:
        return None
    speed = math.sqrt(human_velocity[0] ** 2 + human_velocity[1] ** 2)
    if speed < WALKING_MPS:
        return None
    return human_velocity[0] / speed, human_velocity[1] / speed
