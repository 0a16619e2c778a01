"""The improved surround law's free-space reasoning: a robot moves fast only into space it has evidence is free.

Beyond the paper (docs/SURROUND.md, "The improved law", item 10): an experiment, off by default
(``SurroundConfig.free_space_brake_mps2 = 0``). The echo memory (``surround_memory``) keeps
what the ring has heard; a robot in a packed swarm often never hears a wall's end at all (a neighbour nearer in
every cone toward it, or the end in a blind gap between cones), and a rule on what was heard cannot keep it off
that end. This turns the question round: which of the space ahead does the robot know to be free?

Evidence that a point (in the robot's frame) holds no obstacle:
- its own body;
- a cone's beam holding it (within ``BEAM_HALF_RAD`` of the axis) that hears nothing, or its nearest echo
  farther off: now, or in one of the ring's readings kept for ``memory_s`` (their origins moved along by the
  odometry, as the echo memory's points);
- a blind gap between two cones, nearer than the nearer of the two cones' echoes divided by ``gap_share`` (a
  wall's end hiding in a gap belongs to a wall that usually crosses one of the cones beside it);
- a tracked body's path: the capsule its track swept over the last ``SWEEP_S`` (a neighbour's body, less
  ``BODY_SLACK_M`` for its IR estimate's error; the human's body likewise).

The law then takes the space the robot's body would sweep along its command: points on ``LINES`` lines parallel to
the command, inside its radius; the first point on each line without evidence bounds the distance the robot may
travel (up to touching it, less ``MARGIN_M``), and the robot's speed along its command to what stops within
that, braking at ``brake`` after ``LATE_S`` at its speed. It acts only on a robot that heard a wall (an echo no
tracked body explains) within ``near_m`` in the last ``memory_s``, and (``ImprovedSurroundController``) only off
the walking human's lane. Counting on the robot's real braking (its motors ramp at 2 m/s^2) it would stop short of
each point it tries (pushes aside); the corridor's flow needed the 3 m/s^2 it was measured at, so it is a slowdown.
Measured (docs/RESULTS.md): a robot in a file behind a neighbour never has evidence for the sliver of its path
beside that neighbour, so near the walls every file slows, and the swarm falls behind the human.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

BEAM_HALF_RAD = math.radians(13.0)
"""A point this close to a cone's axis is in its beam (2 degrees inside the cone's 15: the AHRS and the odometry
drift a little)."""
STEP_M = 0.04
"""The spacing of the points tried along each line."""
LINES = (0.0, 0.05, -0.05, 0.09, -0.09)
"""The lines tried, as offsets across the command (m): a point within the robot's radius of its path is touched."""
MARGIN_M = 0.03
"""The gap kept in hand short of an unknown point (odometry drift, ranging noise)."""
LATE_S = 0.06
"""The command acts a control step and up to a world tick after the echoes it was made from."""
SWEEP_S = 0.6
"""How far back a tracked body's path counts as swept (its track's velocity times this)."""
BODY_SLACK_M = 0.02
"""A tracked body's capsule is its radius less this (the IR estimate's error)."""
KEEP_EVERY = 3
"""One ring reading in this many is kept in the memory (a 25 Hz ring, so one each 0.12 s)."""
SLACK_M = 0.03
"""A point counts as short of a cone's echo only this much nearer (ranging noise, the odometry, the arc)."""


class FreeSpace:
    """What the robot knows is free (see the module's docstring), in plain floats: a pilot steps it every sample."""

    def __init__(
        self, memory_s: float = 0.5, brake_mps2: float = 3.0, near_m: float = 0.0, gap_share: float = 0.0
    ) -> None:
        self.gap_share = gap_share
        """A point in a blind gap is known free nearer than the nearer neighbouring cone's echo over this (0: any)."""
        self.memory_s = memory_s
        self.brake_mps2 = brake_mps2
        self.near_m = near_m
        self.wall_age = math.inf
        """Time since the ring last heard an echo no tracked body explains within ``near_m`` (the rule acts within
        ``memory_s`` of it; always when ``near_m`` is 0)."""
        self.position = (0.0, 0.0)
        """The robot's odometry position (its frame never turns): kept readings' origins are against it."""
        self.readings: list[tuple[float, float, float, list[float]]] = []
        """(origin x, origin y, age, heard per cone) of the kept ring readings, from the robot's centre (inf: none)."""
        self._cos: list[float] = []
        self._sin: list[float] = []
        self._heard: list[float] = []
        self._capsules: list[tuple[float, float, float, float, float]] = []
        self._steps = 0

    def step(
        self,
        ranges: Sequence[float],
        cos: Sequence[float],
        sin: Sequence[float],
        velocity: Sequence[float],
        dt: float,
        robot_radius_m: float,
        bodies: Sequence[tuple[float, float, float, float, float]],
        explained: Sequence[bool] = (),
    ) -> None:
        """Take in one ring reading (``ranges`` from the skin, nan for none; the cones' axes as ``cos``/``sin``)
        after the robot moved at ``velocity`` for ``dt``, and the tracked bodies now as ``(x, y, vx, vy, radius)``
        in the robot's frame; ``explained``, per echo, whether a tracked body explains it."""
        self.wall_age += dt
        for r, body in zip(ranges, explained, strict=False):
            if not body and math.isfinite(r) and robot_radius_m + r <= self.near_m:
                self.wall_age = 0.0
        px, py = self.position[0] + velocity[0] * dt, self.position[1] + velocity[1] * dt
        self.position = (px, py)
        self._cos, self._sin = list(cos), list(sin)
        self._heard = [robot_radius_m + r if math.isfinite(r) else math.inf for r in ranges]
        kept = [(ox, oy, age + dt, heard) for ox, oy, age, heard in self.readings if age + dt <= self.memory_s]
        if self._steps % KEEP_EVERY == 0:
            kept.append((px, py, 0.0, self._heard))
        self._steps += 1
        self.readings = kept
        capsules = []
        for x, y, vx, vy, radius in bodies:
            capsules.append((x, y, x - vx * SWEEP_S, y - vy * SWEEP_S, max(0.0, radius - BODY_SLACK_M)))
        self._capsules = capsules

    def known_free(self, x: float, y: float, robot_radius_m: float) -> bool:
        """Whether the point (x, y) (robot's frame) is known to hold no obstacle."""
        d2 = x * x + y * y
        if d2 <= robot_radius_m * robot_radius_m:
            return True
        d = math.sqrt(d2)
        if _in_beams(x, y, d, self._heard, self._cos, self._sin, self.gap_share):
            return True
        for ax, ay, bx, by, radius in self._capsules:
            if _segment_distance2(x, y, ax, ay, bx, by) <= radius * radius:
                return True
        px, py = self.position
        for ox, oy, _, heard in reversed(self.readings):
            rx, ry = x + px - ox, y + py - oy
            if _in_beams(rx, ry, math.sqrt(rx * rx + ry * ry), heard, self._cos, self._sin, None):
                return True
        return False

    def rule(self, command: Sequence[float], robot_radius_m: float) -> tuple[float, float, float] | None:
        """``(nx, ny, limit)``: the robot's speed along its command is at most ``limit`` (it stops short of the
        first point without evidence in its path); None when the path is known free as far as it needs."""
        if self.near_m > 0 and self.wall_age > self.memory_s:
            return None
        cx, cy = command
        speed = math.sqrt(cx * cx + cy * cy)
        if not speed > 0:
            return None
        ux, uy = cx / speed, cy / speed
        a = self.brake_mps2
        need = speed * LATE_S + speed * speed / (2 * a) + MARGIN_M
        travel = math.inf
        for offset in LINES:
            reach = math.sqrt(max(0.0, robot_radius_m * robot_radius_m - offset * offset))
            s = robot_radius_m + STEP_M / 2
            while s - reach <= need and s - reach < travel:
                x, y = ux * s - uy * offset, uy * s + ux * offset
                if not self.known_free(x, y, robot_radius_m):
                    travel = min(travel, s - reach)
                    break
                s += STEP_M
        if travel > need:
            return None
        gap = max(0.0, travel - MARGIN_M)
        limit = max(0.0, math.sqrt(a * a * LATE_S * LATE_S + 2 * a * gap) - a * LATE_S)
        return ux, uy, limit


def _in_beams(
    x: float,
    y: float,
    d: float,
    heard: Sequence[float],
    cos: Sequence[float],
    sin: Sequence[float],
    gap_share: float | None,
) -> bool:
    """Whether a beam holding (x, y) at distance d hears nothing nearer than it (or, with a ``gap_share``, it lies in
    a blind gap nearer than the two cones beside it hear, over that share; any point in a gap with a share of 0)."""
    if not d > 0:
        return True
    cos_beam = math.cos(BEAM_HALF_RAD)
    best = -2.0
    second = -2.0
    k_best = k_second = -1
    for k, (c, s) in enumerate(zip(cos, sin, strict=True)):
        along = (x * c + y * s) / d
        if along >= cos_beam:
            return heard[k] > d + SLACK_M
        if along > best:
            second, k_second = best, k_best
            best, k_best = along, k
        elif along > second:
            second, k_second = along, k
    if gap_share is None or k_second < 0:
        return False
    return gap_share <= 0 or d < min(heard[k_best], heard[k_second]) / gap_share


def _segment_distance2(x: float, y: float, ax: float, ay: float, bx: float, by: float) -> float:
    """The squared distance from (x, y) to the segment from (ax, ay) to (bx, by)."""
    ex, ey = bx - ax, by - ay
    length2 = ex * ex + ey * ey
    t = 0.0 if length2 <= 0 else min(1.0, max(0.0, ((x - ax) * ex + (y - ay) * ey) / length2))
    gx, gy = x - ax - t * ex, y - ay - t * ey
    return gx * gx + gy * gy
