"""The safe surround law: the paper's attraction as a nominal command, under a safety filter on what the robot senses.

Two parts (docs/SURROUND.md, "The safe law"):

1. **Nominal.** The paper's forces (``SurroundController``): the impedance toward the local centroid
   f_R = M g'' + B g' + K g, the repulsion f_O = -sum Q p / |p|^3 from neighbours, echoes and the human's surface
   within A, the surround force f_G = F_G c_i p_G / |p_G|; with the paper's drag on ground speed replaced by a
   match to the human's tracked velocity, f_M = D (v_G - v) (v_G = 0 while he is not tracked), and a centring
   spring f_C = C p_G that puts the swarm's centre on him. The unit body's next velocity under the sum, clipped to
   the robot's acceleration and speed, is the nominal command u_nom.
2. **Safety filter.** The command is the velocity u nearest u_nom under one barrier constraint per sensed body:

       n . (u - w_eff) <= s(h),     s(h) = sqrt(a^2 tau^2 + 2 a h) - a tau,     h = d - d_touch - m

   for each tracked neighbour and the human within reach (n the unit vector to it, d its centre distance,
   d_touch the bodies' touching distance, w_eff its tracked velocity less what it may have lost braking since its
   track last saw it, a tau), and for each obstacle point (the echoes heard now that no tracked beacon explains,
   and the echo memory's points, which a blind gap or a neighbour hides now; w_eff = 0, d_touch the robot's
   radius). s(h) is the fastest closing from which the robot, still closing for the latency tau and then braking
   at a, stops within h: the constraint set is forward invariant as long as each body keeps its velocity or
   brakes no harder than a (the braking barrier of safety barrier certificates, Wang, Ames and Egerstedt 2017),
   and m holds the sensing error. The small QP (2 unknowns, a few dozen half-planes) is solved exactly: u_nom when
   it keeps every constraint, else the nearest of its projections on each boundary and each pair's corner that
   keeps them all. When none does (a robot between the walking human and a slower robot ahead), obstacles and the
   human stay hard and the neighbours' constraints are all eased by the least common slack that leaves a velocity.

The human's allowance a tau counts along his walk only (|cos| of the angle between his velocity and the line to
the robot): a walker brakes along his walk, and the full allowance made every robot level with him back off.

Every number is the robot's own sensing (IR beacon tracks, the ultrasonic ring, the odometry): no ground truth.
The robot's own ultrasonic safety stage still has the last word (``surround_pilot``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from petswarm.controllers.surround import SurroundConfig, SurroundController, nearest_per_sector

SECTORS = 16
"""Obstacle points make constraints only for the nearest point in each of these sectors (22.5 degrees) round the
robot: an echo's remembered arc is several points a few degrees apart, and each sector's nearest binds first."""
TIGHT = 1e-9
"""A constraint whose slack at the solution is within this is active (and a candidate within it is allowed)."""

EASE_MAX_MPS = 3.0
"""The most the neighbours' constraints are eased by when no velocity keeps them all with the hard ones (m/s: twice
the top speed, more than any two robots' closing)."""
EASE_STEPS = 10
"""Halvings of that range: the slack to 3 mm/s."""

Constraint = tuple[float, float, float]
"""(nx, ny, limit): the command u must keep nx ux + ny uy <= limit."""


class SafeSurroundController(SurroundController):
    """One robot's safe surround law, in its own frame, in plain floats (see the module's docstring).

    ``active`` holds, after each step, the constraints the filter's answer lies on: (kind, x, y) with kind
    ``neighbour``, ``human`` or ``obstacle`` and (x, y) the body's centre or the obstacle point, robot frame."""

    def __init__(self, config: SurroundConfig | None = None, person_radius_m: float = 0.25) -> None:
        super().__init__(config)
        self.person_radius_m = person_radius_m
        self.active: list[tuple[str, float, float]] = []
        self.nominal: tuple[float, float] = (0.0, 0.0)
        """The last step's nominal command (before the filter)."""

    def step_plain(  # type: ignore[override]  # the safe law takes the tracks' velocities and the remembered points
        self,
        neighbours: Sequence[Sequence[float]],
        obstacles: Sequence[Sequence[float]],
        human: Sequence[float] | None,
        velocity: Sequence[float],
        dt: float,
        human_velocity: Sequence[float] | None = None,
        neighbour_velocities: Sequence[Sequence[float]] | None = None,
        walls: Sequence[Sequence[float]] = (),
    ) -> tuple[float, float]:
        """The velocity command. ``neighbours`` (tracked centres) with ``neighbour_velocities`` (their tracks'; None:
        taken to stand still); ``obstacles``: echo points no beacon explains, and last the human's surface point when
        he is seen (as ``surround_sensing.sense_lists`` gives them); ``human`` his tracked centre and
        ``human_velocity`` his track's velocity (None: unknown); ``velocity`` the robot's own (odometry);
        ``walls``: the echo memory's points (``surround_memory.EchoMemory``)."""
        c = self.config
        distances, near, g, f_r = self._centring(neighbours, dt)
        f_o = self._repulsion(neighbours, distances, near, obstacles)
        f_g = self._surround(g, human, velocity)
        vx, vy = velocity
        hvx, hvy = human_velocity if (human is not None and human_velocity is not None) else (0.0, 0.0)
        ax = f_r[0] + f_o[0] + f_g[0] + c.velocity_match * (hvx - vx)
        ay = f_r[1] + f_o[1] + f_g[1] + c.velocity_match * (hvy - vy)
        if human is not None:
            ax, ay = ax + c.centring * human[0], ay + c.centring * human[1]
        ax, ay = _clip(ax, ay, c.max_accel_mps2)
        nominal = _clip(vx + ax * dt, vy + ay * dt, c.max_speed_mps)
        self.nominal = nominal
        moving = neighbour_velocities if neighbour_velocities is not None else [(0.0, 0.0)] * len(neighbours)
        soft: list[Constraint] = []
        soft_at: list[tuple[str, float, float]] = []
        touching = 2 * c.robot_radius_m
        for (x, y), (ux, uy) in zip(neighbours, moving, strict=True):
            row = self._body(x, y, ux, uy, touching, False)
            if row is not None:
                soft.append(row)
                soft_at.append(("neighbour", x, y))
        hard: list[Constraint] = []
        hard_at: list[tuple[str, float, float]] = []
        if human is not None:
            row = self._body(human[0], human[1], hvx, hvy, c.robot_radius_m + self.person_radius_m, True)
            if row is not None:
                hard.append(row)
                hard_at.append(("human", human[0], human[1]))
        echoes = obstacles if human is None else obstacles[:-1]  # his surface point: his own constraint above
        for x, y, row in self._points([*echoes, *walls]):
            hard.append(row)
            hard_at.append(("obstacle", x, y))
        command = _nearest(nominal, [*soft, *hard])
        if soft and _excess(command, [*soft, *hard]) > TIGHT:
            # no velocity keeps them all: the obstacles and he come first, and the neighbours' constraints are
            # eased all by one slack, the least that leaves a velocity (each neighbour runs the same filter and
            # gives way in turn)
            command = _eased(nominal, soft, hard)
        command = _clip(command[0], command[1], c.max_speed_mps)
        self.active = [
            at
            for row, at in zip([*soft, *hard], [*soft_at, *hard_at], strict=True)
            if row[0] * command[0] + row[1] * command[1] - row[2] > -1e-6
        ]
        return command

    def _body(self, x: float, y: float, ux: float, uy: float, touching: float, walker: bool) -> Constraint | None:
        """The barrier constraint for a tracked body at (x, y) moving at (ux, uy), touching at centre distance
        ``touching``; None beyond reach (the avoidance range past touching) or on the robot's own centre."""
        c = self.config
        d = math.sqrt(x * x + y * y)
        if not (0 < d <= touching + c.avoidance_m):
            return None
        nx, ny = x / d, y / d
        h = d - touching - c.stop_margin_m
        lost = c.brake_mps2 * c.track_lag_s
        away = ux * nx + uy * ny
        if walker:
            # he may stop at any step (a person stops within a stride): none of his speed away counts
            away = min(away, 0.0)
        elif away > 0:
            # braking since its track saw it takes off its speed away, down to standing (not past: it brakes)
            away = max(away - lost, 0.0)
        return nx, ny, away + self._stoppable(h)

    def _points(self, points: Sequence[Sequence[float]]) -> list[tuple[float, float, Constraint]]:
        """The barrier constraint of the nearest obstacle point in each ``SECTORS`` sector within reach."""
        c = self.config
        reach = c.robot_radius_m + c.avoidance_m
        nearest = nearest_per_sector(points, reach, SECTORS)
        out = []
        for sector in sorted(nearest):
            x, y, d = nearest[sector]
            h = d - c.robot_radius_m - c.stop_margin_m
            out.append((x, y, (x / d, y / d, self._stoppable(h))))
        return out

    def _stoppable(self, h: float) -> float:
        """s(h): the fastest closing speed from which the robot, closing for the latency ``track_lag_s`` and then
        braking at ``brake_mps2``, stops within ``h`` (0 at or inside the margin; negative h: it must back off)."""
        c = self.config
        a, late = c.brake_mps2, c.track_lag_s
        if h <= 0:
            return h / late  # inside the margin: back out of it within the latency
        return math.sqrt(a * a * late * late + 2 * a * h) - a * late


def _along_share(ux: float, uy: float, nx: float, ny: float) -> float:
    """|cos| of the angle between a walker's velocity (ux, uy) and the unit (nx, ny); 0 while he stands."""
    speed = math.sqrt(ux * ux + uy * uy)
    if speed <= 1e-9:
        return 0.0
    return abs(ux * nx + uy * ny) / speed


def _excess(v: tuple[float, float], rows: list[Constraint]) -> float:
    """How far ``v`` breaks the worst of ``rows``; <= 0 when it keeps them all."""
    worst = -math.inf
    for nx, ny, limit in rows:
        e = nx * v[0] + ny * v[1] - limit
        if e > worst:
            worst = e
    return worst if rows else 0.0


def _nearest(v: tuple[float, float], rows: list[Constraint]) -> tuple[float, float]:
    """The velocity nearest ``v`` keeping every half-plane of ``rows`` (exact in 2-D: ``v`` itself, else the best
    of its projections on each boundary and each pair's corner), or, when none keeps them all, the candidate that
    breaks the worst one least."""
    if _excess(v, rows) <= TIGHT:
        return v
    candidates = []
    for nx, ny, limit in rows:
        over = nx * v[0] + ny * v[1] - limit
        if over > 0:
            candidates.append((v[0] - over * nx, v[1] - over * ny))
    best, best_d = None, math.inf
    for cand in candidates:
        if _excess(cand, rows) <= TIGHT:
            d = (cand[0] - v[0]) ** 2 + (cand[1] - v[1]) ** 2
            if d < best_d:
                best, best_d = cand, d
    if best is not None:
        return best
    corners = []
    for k, (ax, ay, a) in enumerate(rows):
        for bx, by, b in rows[k + 1 :]:
            det = ax * by - ay * bx
            if abs(det) > 1e-9:
                corners.append(((a * by - ay * b) / det, (ax * b - a * bx) / det))
    for cand in corners:
        if _excess(cand, rows) <= TIGHT:
            d = (cand[0] - v[0]) ** 2 + (cand[1] - v[1]) ** 2
            if d < best_d:
                best, best_d = cand, d
    if best is not None:
        return best
    everything = candidates + corners
    if not everything:
        return v
    return min(everything, key=lambda cand: _excess(cand, rows))


def _eased(v: tuple[float, float], soft: list[Constraint], hard: list[Constraint]) -> tuple[float, float]:
    """The velocity nearest ``v`` keeping ``hard`` and every ``soft`` limit raised by the least common slack that
    leaves one (to ``EASE_STEPS`` halvings of the slack's range; ``hard`` alone when even that fails)."""
    low, high = 0.0, EASE_MAX_MPS
    best = _nearest(v, hard)
    if _excess(best, hard) > TIGHT:  # he and the obstacles alone leave no velocity: the one breaking them least
        return best
    for _ in range(EASE_STEPS):
        mid = (low + high) / 2
        eased = [(nx, ny, limit + mid) for nx, ny, limit in soft]
        u = _nearest(v, [*eased, *hard])
        if _excess(u, [*eased, *hard]) <= TIGHT:
            best, high = u, mid
        else:
            low = mid
    return best


def _clip(x: float, y: float, limit: float) -> tuple[float, float]:
    """(x, y) shortened to ``limit`` if longer."""
    scale = min(1.0, limit / max(math.sqrt(x * x + y * y), 1e-12))
    return x * scale, y * scale
