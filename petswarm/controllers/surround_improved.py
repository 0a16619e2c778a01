"""The improved surround law: beyond the paper, a swarm that keeps its human inside it while he walks.

The paper's law (``surround.SurroundController``) moves the swarm only through the surround force of its rear
robots (c_i ~ 1 where the local centroid lies toward the human; a robot between its local swarm and the human
has c_i = 0) against a drag on ground speed. Measured in petswarm (docs/RESULTS.md), a swarm under it trails a
walking human as a tail (2 m behind him at the median) and stalls at a corridor's mouth. This law keeps the
paper's impedance toward the local centroid and its surround force, and changes the rest, each from the same
sensing (the tracked IR beacons of the human and the neighbours, the echoes, the odometry):

    f_i = f_R + f_O' + s f_G + f_P + f_M                                         (f_R, f_G the paper's;
                                                                                 s = ``surround_share``)
    f_P = (C |q| + F_P clip((|q| - rho) / w, 0, 1)) q / |q|,   q = p_G + T v_G   (centring, and a pull on
                                                                                 robots left behind)
    f_M = D (v_G - v_i)                                                          (move with the human)
    f_O' = - sum Q / d_eff^2 p / |p|,   d_eff = |p| - closing^2 / (2 a_b)        (repulsion on braking distance)

- f_M, the velocity match: the paper's drag measured against the human's velocity v_G (his beacon's track)
  instead of the ground. Under the paper's law the swarm needs a standing lag for its rear to push it along;
  with f_M every robot, front ones included, moves at his pace.
- f_P: a soft spring C toward the human on every robot, so the swarm's centre settles on him (what keeps him
  inside, not at its front edge), and beyond rho a pull growing to F_P on robots he has left behind (held by
  an obstacle, at the tail of a file through a gap). It aims T seconds ahead of him (q = p_G + T v_G):
  obstacles and the stop rules only ever hold robots back, so the swarm aims a little ahead to end round him.
- f_O': the paper's repulsion, but a point the robot is closing on counts as nearer by the distance braking
  takes (closing speed: its own toward an obstacle point, the human's body included, as he may stop at any
  step; relative to a neighbour's tracked velocity for a neighbour). The paper's Q / d^2 ignores speed, and
  a robot closing at 0.4 m/s on a slower neighbour or on the back of a human who stops touched it.

Without the human's beacon (not seen yet, or lost) f_P is zero and f_M falls back to the paper's drag. The
force becomes a velocity as in the paper's law (unit virtual mass, clipped acceleration and speed), and then:

- the stop rule: the velocity nearest that command whose speed toward each tracked body (neighbour, human)
  still stops short of it if both brake now (``_stoppable``); a body coming at the robot is got out of the way
  of. Forces only balance, so the pull and f_M pushed a robot at the tail of a file on into a slower one ahead;
  a velocity bound does not. When no velocity keeps every rule, the human's comes first;
- the wall rule, within the stop rule: every wall point the robot's echo memory holds (``surround_memory``: heard
  earlier, now in a blind gap between two cones or behind a neighbour) is passed by at the robot's radius and
  ``WALL_MARGIN_M``, or stopped short of (``_wall_rules``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from petswarm.controllers.surround import MIN_RANGE_M, SurroundConfig, SurroundController, nearest_per_sector

WALL_MARGIN_M = 0.04
"""The wall rule's gap kept in hand beyond touching: a remembered point is an arc's, up to its chord off the
wall's end (7.5 degrees apart at 0.45 m, 6 cm; 2 cm at the 0.15 m where it binds), and the odometry drifts.
0.07 until 2026-11-24: with the rule passing a point it is aimed at (``_wall_rules``), the robots beside the
human 0.45 m off his line in a 1.2 m corridor (5 cm from its wall) keep a way past its end at 0.04."""
WALL_LATE_S = 0.06
"""The wall rule's lateness: a command acts a control step (40 ms) and up to a world tick (20 ms) after the
echoes it was made from, in which the robot still closes at its old speed."""
WALL_BRAKE_MPS2 = 1.2
"""The deceleration the wall rule counts on: below the bodies' ``brake_mps2`` (1.5), as the robot's own stop
rules and the neighbours' escapes pull the command other ways too. With 5 cm, no lateness and 1.5 m/s^2, the
corridor's seeds 1 and 2 had 2 robot-obstacle contacts each; with these values 1 (of any kind) each (both
before the rule let a robot pass a point by, with the margin at 7 cm, on 2026-11-23)."""
LANE_SLACK_M = 1.0
"""How much wider the walking lane's rule is while the lane is ramped in or out (share 0), narrowing to
``lane_half_m`` at share 1."""
WALL_SECTORS = 16
"""Sectors (22.5 degrees) round the robot in each of which only the nearest wall point makes a stop rule."""


class ImprovedSurroundController(SurroundController):
    """One robot's improved surround law, in its own frame, in plain floats (see the module's docstring)."""

    def __init__(self, config: SurroundConfig | None = None) -> None:
        super().__init__(config)
        self._human_velocity: tuple[float, float] | None = None
        self._lane_share = 0.0
        self._still_share = 0.0
        self._walked = False

    def step_plain(
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
        """The velocity command; as the paper's ``step_plain``, with the human's own velocity ``human_velocity``
        (his tracked beacon's, in this robot's frame; None when unknown), the neighbours' own velocities
        ``neighbour_velocities`` (their tracks', in the order of ``neighbours``; None: taken to be still) and the
        obstacle points the robot must pass or stop short of, ``walls`` (``surround_memory.EchoMemory``'s:
        heard earlier, now in a blind gap or behind a neighbour)."""
        distances, near, g, f_r = self._centring(neighbours, dt)
        c = self.config
        moving = neighbour_velocities if neighbour_velocities is not None else [(0.0, 0.0)] * len(neighbours)
        f_o = self._braking_repulsion(neighbours, moving, distances, near, obstacles, velocity)
        f_h = self._human_repulsion(human, human_velocity, velocity)
        f_o = (f_o[0] + f_h[0], f_o[1] + f_h[1])
        f_p = self._pull(self._aim(human, human_velocity), self._still(human_velocity, dt))
        if c.surround_share > 0:
            f_g = self._surround(g, human, velocity)
            f_p = (f_p[0] + c.surround_share * f_g[0], f_p[1] + c.surround_share * f_g[1])
        if c.lane_gain > 0:
            f_l = self._lane(human, human_velocity, dt)
            f_p = (f_p[0] + f_l[0], f_p[1] + f_l[1])
        self._forces = (f_r, f_o, f_p)
        force = (f_r[0] + f_o[0] + f_p[0], f_r[1] + f_o[1] + f_p[1])
        command = self._matched_command(force, velocity, human if human is None else human_velocity, dt)
        return self._stoppable(command, neighbours, moving, human, human_velocity, walls)

    def _stoppable(
        self,
        command: tuple[float, float],
        neighbours: Sequence[Sequence[float]],
        moving: Sequence[Sequence[float]],
        human: Sequence[float] | None,
        human_velocity: Sequence[float] | None,
        walls: Sequence[Sequence[float]] = (),
    ) -> tuple[float, float]:
        """The command with its speed toward each tracked body and wall point cut to what still stops short of it.

        Toward a neighbour (or the human) at centre distance d, moving away from it at w along the line, the
        robot's speed u along the line is held to u^2 <= w^2 + 2 a g, g = d - d_stop (d_stop the bodies'
        touching distance plus ``stop_margin_m``): if both brake at a now, this one stops behind. w is the
        track's, less a t_lag (the track lags the body by about ``track_lag_s``, in which it may have braked).
        A body coming at the robot (w < 0: the human walking into a robot in front of him) is taken to keep
        coming: u <= w + sqrt(2 a g), so the robot gets out of its way. The forces (the pull, the velocity
        match) push a robot at the tail of a file on into a slower one ahead whatever the repulsion; this
        rule has the last word, before the ultrasonic safety stage, which sees only through eight cones."""
        c = self.config
        touching = 2 * c.robot_radius_m
        rules = [self._stop_rule(x, y, ux, uy, touching) for (x, y), (ux, uy) in zip(neighbours, moving, strict=True)]
        if c.lane_gain > 0 and c.lane_rate > 0:  # with the neighbours' rules: dropped with them when none keeps all
            rules.append(self._lane_rule(human, human_velocity))
        if c.lane_gain > 0 and c.wake_rate > 0:  # likewise
            rules.append(self._wake_rule(neighbours, human, human_velocity))
        his = None
        if human is not None:
            hvx, hvy = human_velocity if human_velocity is not None else (0.0, 0.0)
            his = self._stop_rule(
                human[0], human[1], hvx, hvy, c.human_clearance_m + c.robot_radius_m, c.human_margin_m, walker=True
            )
        fixed = self._wall_rules(walls, command)
        kept = [rule for rule in (*rules, *fixed, his) if rule is not None]
        vx, vy = _nearest_allowed(command, kept)
        if his is not None and _excess((vx, vy), [his]) > 1e-9:
            # no velocity keeps every rule (a robot held between the walking human and slower robots ahead):
            # his rule comes first, and the robots ahead yield in turn to one coming at them
            vx, vy = _nearest_allowed(command, [his, *fixed])
            if _excess((vx, vy), [his]) > 1e-9:
                vx, vy = _nearest_allowed(command, [his])
        return _clip(vx, vy, c.max_speed_mps)

    def _wall_rules(
        self, walls: Sequence[Sequence[float]], command: tuple[float, float]
    ) -> list[tuple[float, float, float]]:
        """``(nx, ny, limit)`` per wall point within reach: pass it or stop short of it (a wall stays put).

        A command whose line passes the point further off than the robot's radius and ``WALL_MARGIN_M`` never
        touches it: the rule keeps it on that side of the point (the tangent from the robot's centre to the
        disc of that radius round the point, on the command's side). A command aimed within that disc is turned to
        that tangent when that changes it less than the stop would, and otherwise held to the speed toward the
        point that still stops short of it (``_late_stop``). A speed limit alone pushed a
        robot moving along a wall 0.1 m off it (its points 60 degrees off its path) off the wall and slowed it
        (0.93 of 1 m/s in the unit test; with the arcs of that time, 4 of 10 corridor medians went over 0.5 m).
        Of the points in each of ``WALL_SECTORS`` sectors round the robot only the nearest counts (a remembered
        echo is an arc of points a few degrees apart), which keeps the exact nearest-velocity search small."""
        c = self.config
        reach = c.robot_radius_m + c.avoidance_m
        nearest = nearest_per_sector(walls, reach, WALL_SECTORS)
        rules = []
        clear = c.robot_radius_m + WALL_MARGIN_M
        cx, cy = command
        speed = math.sqrt(cx * cx + cy * cy)
        for x, y, d in nearest.values():
            ux, uy = x / d, y / d
            stop = (ux, uy, _late_stop(max(0.0, d - clear)))
            if clear < d and speed > 0:
                # the tangent's angle off the point's bearing; the command's side of the point
                sine = clear / d
                cosine = math.sqrt(1 - sine * sine)
                side = 1.0 if ux * cy - uy * cx >= 0 else -1.0
                # the unit normal of the tangent on that side, pointing to the point's side
                tangent = (ux * sine - side * -uy * cosine, uy * sine - side * ux * cosine, 0.0)
                aimed_outside = (cx * ux + cy * uy) < cosine * speed
                # aimed inside the disc but nearer passing than stopping: it passes (a robot sliding along a
                # corridor's wall, its command a few degrees into an end point, braked to a stop there)
                if aimed_outside or _excess(command, [tangent]) < _excess(command, [stop]):
                    rules.append(tangent)
                    continue
            rules.append(stop)
        return rules

    def _stop_rule(
        self,
        x: float,
        y: float,
        ux: float,
        uy: float,
        touching: float,
        margin: float | None = None,
        walker: bool = False,
    ) -> tuple[float, float, float] | None:
        """``(nx, ny, limit)``: the robot's speed toward a body at (x, y) moving at (ux, uy), touching it at centre
        distance ``touching`` (and ``margin`` more, ``stop_margin_m`` if None), is at most ``limit`` along the
        unit (nx, ny) (see ``_stoppable``); None when the body is beyond the avoidance range (or on the robot's
        own centre). ``walker``: the body is the human, whose braking since his track last saw him slows him
        along his walk only (a neighbour, pushed about, may have slowed any way)."""
        c = self.config
        d = math.sqrt(x * x + y * y)
        if not (0 < d <= touching + c.avoidance_m):
            return None
        nx, ny = x / d, y / d
        gap = max(0.0, d - touching - (c.stop_margin_m if margin is None else margin))
        # its speed away from this robot, less what it may have lost since its track last saw it: for the human,
        # only what his braking takes off his speed along this line. Counted in full, it made every robot level
        # with him walking (his speed across the line 0) back off at 0.15 m/s inside his margin, out into the
        # wall beside a corridor's mouth (docs/SURROUND.md, item 14)
        lost = c.brake_mps2 * c.track_lag_s
        if walker:
            lost *= _along_share(ux, uy, nx, ny)
        away = ux * nx + uy * ny - lost
        if away > 0:
            return nx, ny, math.sqrt(away * away + 2 * c.brake_mps2 * gap)
        # it comes at the robot: the robot must be getting away by the time the gap is gone, from a start a
        # control step late and at its motors' ramp, so it counts on less than its braking
        return nx, ny, away + math.sqrt(2 * c.escape_mps2 * gap)

    def _braking_repulsion(
        self,
        neighbours: Sequence[Sequence[float]],
        moving: Sequence[Sequence[float]],
        distances: list[float],
        near: list[bool],
        obstacles: Sequence[Sequence[float]],
        velocity: Sequence[float],
    ) -> tuple[float, float]:
        """f_O: the paper's Q / d^2 from neighbours within A, and from obstacle points at the distance left once
        the robot has braked: d - v_toward^2 / (2 brake), v_toward its own speed toward the point. A robot
        closing on a wall's end, or on the back of a human who may stop at any step, is pushed off early
        enough to stop; sliding past sideways costs nothing."""
        c = self.config
        sx = sy = 0.0
        vx, vy = velocity
        for (x, y), (ux, uy), d, seen in zip(neighbours, moving, distances, near, strict=True):
            if not (seen and d > 0):
                continue
            closing = max(0.0, ((vx - ux) * x + (vy - uy) * y) / d)
            left = d - closing * closing / (2 * c.brake_mps2)
            if left <= c.avoidance_m:
                reach = max(left, MIN_RANGE_M)
                magnitude = c.repulsion / (reach * reach)
                sx, sy = sx + magnitude * x / d, sy + magnitude * y / d
        for x, y in obstacles:
            d = math.sqrt(x * x + y * y)
            if not d > 0:
                continue
            toward = max(0.0, (vx * x + vy * y) / d)
            left = d - toward * toward / (2 * c.brake_mps2)
            if left <= c.avoidance_m:
                reach = max(left, MIN_RANGE_M)
                magnitude = c.repulsion / (reach * reach)
                sx, sy = sx + magnitude * x / d, sy + magnitude * y / d
        return -sx, -sy

    def _human_repulsion(
        self, human: Sequence[float] | None, human_velocity: Sequence[float] | None, velocity: Sequence[float]
    ) -> tuple[float, float]:
        """Q / d_eff^2 away from the human's body (``human_clearance_m`` from his centre), d_eff his surface's
        distance less the braking distance of the faster closing: the robot's own speed toward him (he may
        stop), or the speed he comes at it (he walks into a robot held in front of him)."""
        if human is None:
            return 0.0, 0.0
        c = self.config
        hx, hy = human
        centre = math.sqrt(hx * hx + hy * hy)
        if not centre > 0:
            return 0.0, 0.0
        ux, uy = hx / centre, hy / centre
        vx, vy = velocity
        closing = vx * ux + vy * uy
        if human_velocity is not None:
            closing = max(closing, closing - (human_velocity[0] * ux + human_velocity[1] * uy))
        closing = max(0.0, closing)
        left = centre - c.human_clearance_m - closing * closing / (2 * c.brake_mps2)
        if left > c.avoidance_m:
            return 0.0, 0.0
        reach = max(left, MIN_RANGE_M)
        magnitude = c.repulsion / (reach * reach)
        return -magnitude * ux, -magnitude * uy

    def _lane(
        self, human: Sequence[float] | None, human_velocity: Sequence[float] | None, dt: float
    ) -> tuple[float, float]:
        """The walking lane's force: while the human walks (his track faster than ``lane_speed_mps``), a spring
        ``lane_gain`` across his line (through his tracked position along his tracked velocity) on the part of the
        robot's offset beyond ``lane_half_m``; it comes in and goes out over ``lane_ramp_s``. Beyond the paper:
        a swarm walking as a column no wider than the lane never heads for a wall's end at a corridor's mouth."""
        c = self.config
        line = _his_line(human, human_velocity)
        walking = line is not None and line[0] > c.lane_speed_mps
        step = dt / c.lane_ramp_s
        self._lane_share = min(1.0, self._lane_share + step) if walking else max(0.0, self._lane_share - step)
        if self._lane_share <= 0 or c.lane_gain <= 0 or line is None:
            return 0.0, 0.0
        assert human is not None and human_velocity is not None
        speed, nx, ny, across = line
        half = self._lane_half(human, human_velocity, speed)
        beyond = max(0.0, abs(across) - half)
        if self._bound_out(abs(across), half):
            beyond = min(0.0, abs(across) - c.lane_out_m)  # the outer lane: pushed out to it (beyond < 0)
        if beyond == 0:
            return 0.0, 0.0
        strength = c.lane_gain * self._lane_share * beyond
        magnitude = -strength if across >= 0 else strength
        fx, fy = magnitude * nx, magnitude * ny
        ux, uy = human_velocity[0] / speed, human_velocity[1] / speed
        ahead = -(human[0] * ux + human[1] * uy)  # how far the robot is ahead of him along his walk
        if abs(ahead) < c.lane_level_m:  # level with him: on ahead or back behind him
            push = strength if ahead > 0 else -strength
            fx, fy = fx + push * ux, fy + push * uy
        return fx, fy

    def _lane_half(self, human: Sequence[float], human_velocity: Sequence[float], speed: float) -> float:
        """The walking lane's half-width where the robot is along the human's walk: ``lane_beside_half_m`` level
        with him, narrowing to ``lane_half_m`` ahead and behind (``lane_beside_m``, ``lane_beside_ramp_m``)."""
        c = self.config
        if c.lane_beside_half_m <= c.lane_half_m:
            return c.lane_half_m
        along = abs(human[0] * human_velocity[0] + human[1] * human_velocity[1]) / speed
        share = min(1.0, max(0.0, (along - c.lane_beside_m) / c.lane_beside_ramp_m))
        return c.lane_beside_half_m + share * (c.lane_half_m - c.lane_beside_half_m)

    def _lane_rule(
        self, human: Sequence[float] | None, human_velocity: Sequence[float] | None
    ) -> tuple[float, float, float] | None:
        """``(nx, ny, limit)``: the robot's speed out of the walking lane's middle (n pointing away from his line)
        at most his own that way plus ``lane_rate`` times its room to the lane's edge; the lane widens by
        ``LANE_SLACK_M`` as it is ramped out (``_lane_share``). None when the lane is off."""
        c = self.config
        share = self._lane_share
        line = _his_line(human, human_velocity)
        if share <= 0 or line is None:
            return None
        assert human is not None and human_velocity is not None
        speed, nx, ny, across = line
        if across < 0:
            nx, ny, across = -nx, -ny, -across
        half = self._lane_half(human, human_velocity, speed)
        if self._bound_out(across, half):
            return None  # bound for the outer lane
        half += (1.0 - share) * LANE_SLACK_M
        his = human_velocity[0] * nx + human_velocity[1] * ny
        return nx, ny, his + c.lane_rate * max(0.0, half - across)

    def _wake_rule(
        self,
        neighbours: Sequence[Sequence[float]],
        human: Sequence[float] | None,
        human_velocity: Sequence[float] | None,
    ) -> tuple[float, float, float] | None:
        """``(nx, ny, limit)``: a robot outside the walking lane, more than ``wake_level_m`` from level with him, with
        a neighbour ahead of it along his walk (within ``wake_reach_m``, less than a robot's width across) that is
        nearer his line, moves across toward that neighbour's offset at ``wake_rate`` times the difference (n
        pointing away from his line). None when no such neighbour, when he walks slower than
        ``lane_speed_mps``, or when the lane is off; from the lane's first step in, it holds in full (the lane's own
        rule is widened while it ramps in; this one asks only for a move into a neighbour's path).

        Why: such a robot's forward cone hears the neighbour, not what is beyond it (the ring reports each cone's
        nearest echo), and a wall's end just outside the neighbour's path then reaches its 15-30 degree blind gap
        unheard. The corridor's stragglers 0.52 m off his line, held out by a neighbour inside them, met the end
        that way. Where the neighbour ahead went is the one space it knows is free."""
        c = self.config
        line = _his_line(human, human_velocity)
        if self._lane_share <= 0 or line is None or line[0] < c.lane_speed_mps:
            return None
        assert human is not None and human_velocity is not None
        speed, nx, ny, across = line
        ux, uy = human_velocity[0] / speed, human_velocity[1] / speed
        half = self._lane_half(human, human_velocity, speed)
        if abs(across) <= half or self._bound_out(abs(across), half):
            return None
        if abs(human[0] * ux + human[1] * uy) < c.wake_level_m:
            return None  # beside him
        width = 2 * c.robot_radius_m
        along_across = ((x * ux + y * uy, x * nx + y * ny) for x, y in neighbours)
        ahead = [(a, s) for a, s in along_across if 0 < a < c.wake_reach_m and abs(s) < width]
        if not ahead:
            return None
        theirs = across + min(ahead)[1]  # the nearest one's offset from his line
        if theirs * across <= 0 or abs(theirs) >= abs(across):
            return None
        sign = 1.0 if across > 0 else -1.0
        # his own speed across his line: nil but for rounding, kept as in the lane's rule (the two share one form,
        # and dropping it moves the last bit, and so every run's digest)
        his = (human_velocity[0] * nx + human_velocity[1] * ny) * sign
        return sign * nx, sign * ny, his + c.wake_rate * (abs(theirs) - abs(across))

    def _aim(self, human: Sequence[float] | None, human_velocity: Sequence[float] | None) -> Sequence[float] | None:
        """Where the pull aims: the human, led by ``lead_s`` of his velocity when it is known (less of it for a
        robot level with him while the walking lane holds)."""
        lead = self.config.lead_s
        if human is None or human_velocity is None or lead <= 0:
            return human
        c = self.config
        if (c.lane_level_lead < 1.0 or c.lane_outer_level_lead < 1.0) and self._lane_share > 0:
            speed = math.sqrt(human_velocity[0] ** 2 + human_velocity[1] ** 2)
            if speed > 0 and abs(human[0] * human_velocity[0] + human[1] * human_velocity[1]) < c.lane_beside_m * speed:
                level = c.lane_level_lead
                if c.lane_outer_level_lead < 1.0 and self._in_outer_lane(human, human_velocity, speed):
                    level *= c.lane_outer_level_lead
                lead *= 1.0 - self._lane_share * (1.0 - level)
        return human[0] + lead * human_velocity[0], human[1] + lead * human_velocity[1]

    def _in_outer_lane(self, human: Sequence[float], human_velocity: Sequence[float], speed: float) -> bool:
        """Whether the robot is past halfway to the walking lane's outer lane (``lane_out_m``) from his line."""
        across = abs(human[0] * human_velocity[1] - human[1] * human_velocity[0]) / speed
        half = self._lane_half(human, human_velocity, speed)
        return self._bound_out(across, half)

    def _bound_out(self, across: float, half: float) -> bool:
        """Whether a robot ``across`` m off his line is past halfway from the inner lane (``half``) to the outer one
        (``lane_out_m``): pushed out to the outer lane, not drawn in."""
        out = self.config.lane_out_m
        return out > half and across > (half + out) / 2

    def _still(self, human_velocity: Sequence[float] | None, dt: float) -> float:
        """The extra centring once the human has stopped: ``still_centring`` times a share ramped toward 1 over
        ``still_ramp_s`` while his track is slower than ``still_speed_mps`` after it was once faster than
        ``still_walked_mps`` (he walked), toward 0 while faster (or unknown). Not before he first walks: the swarm
        gathered tighter round him then walked off with more robots in the walking lane's inner file (corridor
        seeds 1-10: 3/10 meeting all four bounds against 8/10, 5 seeds torn)."""
        c = self.config
        if c.still_centring <= 0:
            return 0.0
        still = False
        if human_velocity is not None:
            speed = math.sqrt(human_velocity[0] ** 2 + human_velocity[1] ** 2)
            self._walked = self._walked or speed > c.still_walked_mps
            still = self._walked and speed < c.still_speed_mps
        step = dt / c.still_ramp_s
        self._still_share = min(1.0, self._still_share + step) if still else max(0.0, self._still_share - step)
        return c.still_centring * self._still_share

    def _pull(self, human: Sequence[float] | None, still: float = 0.0) -> tuple[float, float]:
        """f_P: toward the human, growing from 0 at ``pull_radius_m`` to ``pull_force`` ``pull_ramp_m`` further;
        its centring spring stiffer by ``still`` (``_still``) while he stands still."""
        if human is None:
            return 0.0, 0.0
        c = self.config
        hx, hy = human
        distance = math.sqrt(hx * hx + hy * hy)
        if not distance > 0:
            return 0.0, 0.0
        strength = c.centring * distance
        if still > 0:
            strength += still * distance
        if distance > c.pull_radius_m:
            strength += c.pull_force * min(1.0, (distance - c.pull_radius_m) / c.pull_ramp_m)
        return strength * hx / distance, strength * hy / distance

    def _matched_command(
        self,
        force: tuple[float, float],
        velocity: Sequence[float],
        human_velocity: Sequence[float] | None,
        dt: float,
    ) -> tuple[float, float]:
        """The unit body's next velocity under ``force`` and f_M (or the paper's drag without the human)."""
        c = self.config
        vx, vy = velocity
        if human_velocity is None:
            mx, my = -c.drag * vx, -c.drag * vy
        else:
            mx, my = c.velocity_match * (human_velocity[0] - vx), c.velocity_match * (human_velocity[1] - vy)
        ax, ay = _clip(force[0] + mx, force[1] + my, c.max_accel_mps2)
        return _clip(vx + ax * dt, vy + ay * dt, c.max_speed_mps)


def _along_share(ux: float, uy: float, nx: float, ny: float) -> float:
    """How much of a walker's change of speed along his walk (velocity (ux, uy)) since his track last saw him shows
    along the unit (nx, ny): |cos| of the angle between the two, as he may have slowed or sped up; 0 for a walker
    standing still (or whose velocity is unknown: taken as standing, as when he is first seen among the robots)."""
    speed = math.hypot(ux, uy)
    if speed <= 1e-9:
        return 0.0
    return abs(ux * nx + uy * ny) / speed


def _late_stop(gap: float) -> float:
    """The fastest speed u toward a wall point ``gap`` beyond the margin that still stops short of it when the
    robot closes at u for ``WALL_LATE_S`` before braking at ``WALL_BRAKE_MPS2``: u T + u^2 / (2 a) = gap."""
    a, late = WALL_BRAKE_MPS2, WALL_LATE_S
    return max(0.0, math.sqrt(a * a * late * late + 2 * a * gap) - a * late)


def _nearest_allowed(v: tuple[float, float], rules: list[tuple[float, float, float]]) -> tuple[float, float]:
    """The velocity nearest ``v`` with ``nx vx + ny vy <= limit`` for every rule ``(nx, ny, limit)``, or, when no
    velocity keeps them all (a robot held between a human coming at it and a slower robot ahead), the candidate
    that breaks them least. A 2-D projection onto a few half-planes, solved by trying the candidates: ``v``, its
    projection onto each boundary and each pair of boundaries' corner."""

    def excess(c: tuple[float, float]) -> float:
        return _excess(c, rules)

    if excess(v) <= 0:  # the common case: nothing to stop for
        return v
    candidates = [
        (v[0] - (nx * v[0] + ny * v[1] - limit) * nx, v[1] - (nx * v[0] + ny * v[1] - limit) * ny)
        for nx, ny, limit in rules
    ]
    for k, (ax, ay, a) in enumerate(rules):
        for bx, by, b in rules[k + 1 :]:
            det = ax * by - ay * bx
            if abs(det) > 1e-9:
                candidates.append(((a * by - ay * b) / det, (ax * b - a * bx) / det))
    allowed = [c for c in candidates if excess(c) <= 1e-9]
    if allowed:
        return min(allowed, key=lambda c: (c[0] - v[0]) ** 2 + (c[1] - v[1]) ** 2)
    return min(candidates, key=excess)


def _excess(v: tuple[float, float], rules: list[tuple[float, float, float]]) -> float:
    """How far the velocity ``v`` breaks the worst of ``rules`` (``nx vx + ny vy <= limit``); <= 0 if none."""
    return max((nx * v[0] + ny * v[1] - limit for nx, ny, limit in rules), default=0.0)


def _clip(x: float, y: float, limit: float) -> tuple[float, float]:
    """The vector (x, y) shortened to ``limit`` if longer."""
    scale = min(1.0, limit / max(math.sqrt(x * x + y * y), 1e-12))
    return x * scale, y * scale


def _his_line(
    human: Sequence[float] | None, human_velocity: Sequence[float] | None
) -> tuple[float, float, float, float] | None:
    """The walking lane's frame (robot frame, from his track): his speed, the unit normal (nx, ny) to his line
    (his tracked position along his tracked velocity) and the robot's offset from that line along it; None when he
    or his velocity is unknown, or he stands still."""
    if human is None or human_velocity is None:
        return None
    speed = math.sqrt(human_velocity[0] ** 2 + human_velocity[1] ** 2)
    if not speed > 0:
        return None
    nx, ny = -human_velocity[1] / speed, human_velocity[0] / speed
    return speed, nx, ny, -(human[0] * nx + human[1] * ny)
