"""The improved surround law's obstacle memory: what the ultrasonic ring has heard, kept in the odometry frame.

Beyond the paper (docs/SURROUND.md, "The improved law", item 7). A ring of eight 30 degree cones, 45 degrees
apart, hears only each cone's nearest echo, and nothing in the 15 degree gaps between cones. A thin wall's end
a robot slides past crosses such a gap, or a neighbour steps into its cone and hides it: 4 of the 5
robot-obstacle contacts of the improved law on corridor seeds 1 and 2 were a robot meeting a wall's end it had
heard with 8 cm or more to go (a replay of its ring from the world's truth). So the robot remembers.

An echo at distance R (from the robot's centre) on the cone with axis a says: some obstacle point lies at R,
somewhere within a +-15 degrees. The memory keeps that arc as ``ARC_POINTS`` points, in the robot's frame (its
heading never turns, so that frame is the odometry frame moved along), each carried back by the robot's own
odometry every step. A remembered point stays until:

- a cone whose beam holds it hears nothing, or hears its nearest echo farther off than the point: the point is
  not there (free space carved by the beam), whatever the ring hears from a neighbour nearer than it;
- the same cone hears a new echo at the point's distance (the new arc replaces it);
- ``MEMORY_S`` has passed, or it has fallen behind by more than ``REACH_M``.

Echoes a tracked beacon explains (a neighbour's body, the human's) carve the beam up to them but are not kept:
bodies move, and the law has their tracks. The law then makes the robot pass every remembered point or stop
short of it (``ImprovedSurroundController``'s wall rule): a point in a blind gap, or behind a neighbour, is
still one it will not drive into.
"""

from __future__ import annotations

import math

ARC_POINTS = 5
"""Points per remembered echo, spread evenly over its cone's 30 degrees (7.5 degrees apart: at 0.4 m, 5 cm)."""
HALF_BEAM_RAD = math.radians(15.0)
"""Half a transducer's cone (the hub's HC-SR04-like 30 degrees; the robot's datasheet knowledge)."""
CARVE_HALF_BEAM_RAD = math.radians(13.0)
"""A point this close to a cone's axis is in its beam for carving by a farther echo (2 degrees inside the edge:
the AHRS and the odometry drift a little)."""
REPLACE_HALF_BEAM_RAD = math.radians(15.5)
"""A point this close to a cone's axis, at or beyond the distance that cone hears a wall now, is replaced by the
fresh arc: the arcs' own edge points sit on the edge. Replaced only inside 13 degrees, an arc's edge point off a
wall beside the robot stays where no beam carves it, up to 8 cm nearer than the wall (worked out for a wall
0.1 m off: it would hold a robot moving along it to under 0.4 m/s)."""
MEMORY_S = 0.6
"""How long a remembered point lasts without a beam crossing it: long enough for a wall's end to cross a blind
gap beside a robot passing it (at 0.5 m/s, 0.3 m); 2 s with ``REACH_M`` 0.7 m held the corridor's swarm back at
the mouth (its centre 0.54-0.72 m from the human at the median on seeds 1 and 2, one run torn)."""
REACH_M = 0.45
"""Echoes and points farther than this from the robot's centre are not kept. The robots that met a wall's end
came at it at 0.3-0.7 m/s (braking at 1.2 m/s^2 takes 0.04-0.2 m, plus the body and the margin); an arc farther
off is 23 cm wide or more (0.7 m held robots back: see ``MEMORY_S``)."""
SLACK_M = 0.04
"""A cone's echo counts as farther than a point (carving it) only beyond this: ranging noise (1 cm), the
odometry's 3 % over a step or two, the arc's chord."""


class EchoMemory:
    """Remembered obstacle points (see the module's docstring), in plain floats: a pilot steps it every sample."""

    def __init__(self) -> None:
        self.points: list[tuple[float, float, float]] = []
        """(x, y, age in s) in the robot's frame."""

    def step(
        self,
        ranges: list[float],
        cos: list[float],
        sin: list[float],
        explained: list[bool],
        velocity: tuple[float, float],
        dt: float,
        robot_radius_m: float,
    ) -> list[tuple[float, float]]:
        """Take in one ring reading (``ranges`` from the skin, nan for none; the cones' axes as ``cos``/``sin``;
        ``explained``: the echo came off a tracked beacon) after the robot moved at ``velocity`` for ``dt``;
        return the remembered points (x, y) now."""
        shift_x, shift_y = velocity[0] * dt, velocity[1] * dt
        reach2 = REACH_M * REACH_M
        moved = []
        for x, y, age in self.points:
            x, y, age = x - shift_x, y - shift_y, age + dt
            if age <= MEMORY_S and x * x + y * y <= reach2:
                moved.append((x, y, age))
        heard = [robot_radius_m + r if math.isfinite(r) else math.inf for r in ranges]
        cos_carve, cos_replace = math.cos(CARVE_HALF_BEAM_RAD), math.cos(REPLACE_HALF_BEAM_RAD)
        kept = []
        for x, y, age in moved:
            d = math.sqrt(x * x + y * y)
            if not _carved(x, y, d, heard, cos, sin, explained, cos_carve, cos_replace):
                kept.append((x, y, age))
        # what the law keeps off: every point remembered from an earlier step that no beam has crossed since (in a
        # blind gap, or behind a neighbour); what the cones hear now, the safety stage and the repulsion see.
        # (A stop rule on the echoes heard now too, on their axes, held the swarm back at the corridor's mouth:
        # seed 1, centre 0.53 m from the human at the median, 5 contacts.)
        out = [(x, y) for x, y, _ in kept]
        for k, distance in enumerate(heard):
            if explained[k] or distance > REACH_M:
                continue
            kept.extend(_arc(cos[k], sin[k], distance))
        self.points = kept
        return out


def _carved(
    x: float,
    y: float,
    d: float,
    heard: list[float],
    cos: list[float],
    sin: list[float],
    explained: list[bool],
    cos_carve: float,
    cos_replace: float,
) -> bool:
    """Whether a cone's beam holding the point (x, y) at distance d shows it is not there: nothing heard, or the
    nearest echo beyond it; or the point lies where that cone hears a wall now (its fresh arc replaces it)."""
    for distance, c, s, body in zip(heard, cos, sin, explained, strict=True):
        along = x * c + y * s
        if along < cos_replace * d:
            continue
        if not body and d - SLACK_M <= distance <= REACH_M:
            return True
        if along >= cos_carve * d and distance > d + SLACK_M:
            return True
    return False


def _arc(c: float, s: float, distance: float) -> list[tuple[float, float, float]]:
    """The arc of an echo at ``distance`` on the cone with axis (c, s): ``ARC_POINTS`` points across its beam."""
    points = []
    for k in range(ARC_POINTS):
        offset = HALF_BEAM_RAD * (2 * k / (ARC_POINTS - 1) - 1)
        co, so = math.cos(offset), math.sin(offset)
        points.append(((c * co - s * so) * distance, (s * co + c * so) * distance, 0.0))
    return points
