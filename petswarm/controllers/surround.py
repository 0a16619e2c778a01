"""The surround formation (docs/SURROUND.md): each robot follows its local swarm's centroid and the human.

Pure and vectorised. ``SurroundLaw`` runs the control law of many robots at once (the simulation's path);
``SurroundController`` is one robot's law on its own sensing, in its own frame (the robot process's path),
the same law in plain floats with the same operations in the same order, so it computes the batched law's
numbers bit for bit: what the simulation shows is what a robot runs.

Robot i, with neighbours p_j (robots within the sight S), OBJ_i (robots and obstacle points within the
avoidance range A, the human among them) and the human at p_G, all in its own frame:

    f_i = f_R + f_O + f_G
    g_i = sum_{j in RTS_i} p_j / (N_i + 1)              f_R = M g_i'' + B g_i' + K g_i
    f_O = - sum_{j in OBJ_i} Q / |p_j|^2 * p_j / |p_j|  f_G = F_G * c_i * p_G / |p_G|
    c_i = (1 + cos(theta_G - theta_g)) (1 + cos(theta_v - theta_g)) / 4

How the force becomes a velocity (the paper does not say): the force accelerates a virtual body of mass
``body_mass`` against a drag ``drag`` * v, and the command is the robot's measured velocity advanced one step,
clipped to the acceleration and speed limits. Why not v = f / B_v: with g_i' ~ -v the term B g_i' is fed
back one step late, and the discrete loop v_k = -(B / B_v) v_(k-1) ... diverges once B > B_v, and the
M g_i'' term (~ -M a, which is (v_(k-1) - v_(k-2)) / dt) once M > B_v dt; on an integrating body B g_i'
is the damping of the impedance and M g_i'' an added mass, stable for M < body_mass. Momentum also lets
the swarm keep pace with a walking human with only the drag to overcome.

g_i' and g_i'' are finite differences of g_i over the controller's own steps. g_i jumps when a robot enters
or leaves the sight (N_i changes): that step is not differenced (the last rate is held, the second
difference is zero), else a jump of 0.1 m over 20 ms would read as a 5 m/s approach. The frame is taken
to be fixed: the robot does not turn (the law only commands vx, vy), so differences in its frame are
differences in the world's.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from radio_hub.datasheet import check_keys
from radio_hub.values import lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

MIN_RANGE_M = 0.02
"""Sensed points closer than this are taken to be this far: a point at the centre has no direction, and
the repulsion Q / d^2 must stay finite (robots touch at 0.2 m, walls at 0.1 m, far above it)."""
LAWS = ("paper", "improved", "safe")
"""The surround laws a robot can run (``SurroundConfig.law``)."""
STILL_MPS = 1e-3
"""Below this speed the robot's own heading theta_v is undefined: the velocity factor of c_i is then 1/2."""


@dataclass(frozen=True)
class SurroundConfig:
    """Gains and limits of the surround law. S, A, the robot radius and dt are the paper's; the rest is ours.

    The paper gives none of M, B, K, Q, F_G or the limits. Chosen, with the virtual mass 1 so that forces
    read as accelerations (m/s^2), by simulating the paper's setups (``surround_sim``):
    - K = 8 /s^2 and Q = 0.38 m^3/s^2: Q / K sets the extent the swarm settles to under local forces alone;
      this ratio gives r* = 0.65 m for 20 robots, the paper's figure, from both lattices. Doubling both from
      (4, 0.19) keeps r* and makes contact repulsion (Q / 0.2^2 = 9.5 m/s^2 between robots) dominate F_G and
      the limits: with half of it robots and the human touched in the corridor.
    - B = 6.4 /s: the impedance's damping, 1.1 of critical for K = 8 and the unit mass; at 3 robots touched.
    - M = 0.1: a small added mass (stable below the unit body mass); the second difference is noisy.
    - drag = 0.3 /s: absolute damping, so a lone push does not coast forever, kept low because the rear
      robots (c_i ~ 1) push the whole swarm: at drag 0.6 (F_G 1.5) it trailed the human by 2.8 m at 1 m/s.
    - F_G = 2.5 m/s^2: keeps the swarm centroid within ~0.6 m of the human at 1 m/s; at 3 the rear pushed
      robots into the human.
    - max speed 1.5 m/s (headroom over the human's 1 m/s), max acceleration 4 m/s^2 (a small mecanum base).
    - ``centroid_filter_s``: time constant of a first-order filter on g_i before it is differenced; 0 (off)
      by default: with 3 cm noise a filter of 0.1 s made it worse (its lag under B = 6.4 rings).
    """

    sight_m: float = 1.0
    avoidance_m: float = 0.5
    inertia: float = 0.1
    damping: float = 6.4
    stiffness: float = 8.0
    repulsion: float = 0.38
    surround_force: float = 2.5
    max_speed_mps: float = 1.5
    max_accel_mps2: float = 4.0
    robot_radius_m: float = 0.1
    dt_s: float = 0.02
    body_mass: float = 1.0
    drag: float = 0.3
    centroid_filter_s: float = 0.0
    law: str = "paper"
    """Which law the robots run: ``paper`` (this module, the spec's), ``improved`` (``surround_improved``, beyond
    the paper) or ``safe`` (``surround_safe``: the paper's forces under a safety filter; docs/SURROUND.md). The
    fields below are the improved law's (the safe law reads the few its docstring names); the paper's ignores them."""
    pull_force: float = 1.5
    """Improved law: the pull (m/s^2) toward the human on a robot he left behind (farther than ``pull_radius_m``)."""
    pull_radius_m: float = 0.8
    """Improved law: within this distance of the human no pull acts (the local forces alone shape the swarm)."""
    pull_ramp_m: float = 0.4
    """Improved law: the pull grows linearly from 0 at ``pull_radius_m`` to ``pull_force`` this much further out."""
    centring: float = 2.5
    """Improved law: a spring (/s^2) toward the human on every robot, so the swarm's centre settles on him."""
    lead_s: float = 0.8
    """Improved law: the pull aims at where the human will be this much later (his position plus his velocity
    times it), not where he is."""
    brake_mps2: float = 1.5
    """Improved law: the deceleration a robot counts on to stop; an obstacle point (a wall, the human's body) is
    repelled as if it were nearer by the distance braking from the robot's speed toward it takes."""
    surround_share: float = 1.0
    """Improved law: how much of the paper's surround force f_G (``surround_force`` c_i toward the human) it keeps."""
    human_clearance_m: float = 0.3
    """Improved law: the human's body as the law keeps off it, from his centre (his 0.25 m disc and 5 cm more):
    he is repelled from this surface, on the faster of the robot's closing and his (he may stop, or walk into
    it)."""
    velocity_match: float = 6.0
    """Improved law: the gain (/s) pulling the robot's velocity to the human's (the paper's drag, relative to him)."""
    stop_margin_m: float = 0.05
    """Improved law: the gap a robot keeps in hand when it brakes behind a tracked neighbour or the human's body
    (beyond touching): his IR estimate is a few cm off, and the command acts a control step late."""
    human_margin_m: float = 0.1
    """Improved law: ``stop_margin_m`` for the human's body: he walks into robots in front of him, which a
    neighbour only does when it is pushed."""
    escape_mps2: float = 0.75
    """Improved law: the acceleration a robot counts on to get out of the way of a body coming at it (half of
    ``brake_mps2``: it starts a control step late, at its motors' ramp)."""
    track_lag_s: float = 0.1
    """Improved law: how far a tracked body's IR velocity lags its own (a 20 Hz sweep, the track's filter): in that
    time a neighbour ahead may have braked, so the robot counts on its being that much slower."""
    lane_gain: float = 12.0
    """Improved law: the walking lane (docs/SURROUND.md, item 12): while the human walks, a lateral spring (/s^2) on
    the part of a robot's offset from his line (his tracked position along his tracked velocity) beyond
    ``lane_half_m``, so the swarm walks as a narrow column; 0 turns it off (the lane's other fields then unused). 12,
    the default, with ``lane_ramp_s`` 0.5, ``still_centring`` 1.5, ``safety_tracked`` 1 and ``lane_outer_level_lead``
    0 (docs/SURROUND.md, items 12 and 13): seeds 1-30 in model time, cylinder 30/30 and corridor 25/30 meeting issue
    17's four bounds (without the lane and the three: 20/20 and 3/20 on seeds 1-20)."""
    lane_half_m: float = 0.32
    """Improved law: the walking lane's half-width: the offset from the human's line a robot keeps within."""
    lane_level_m: float = 0.0
    """Improved law: a robot outside the lane within this of the human along his walk (level with him, where his
    body's repulsion holds it out of the lane) is pushed along his walk away from level with him as hard as
    across (0: off)."""
    lane_rate: float = 3.0
    """Improved law: with > 0, the lane is also a rule with the neighbours' stop rules: a robot's speed out of the
    lane's middle, relative to the human's, is at most this (/s) times its room left to the lane's edge (none
    at its edge and beyond: it may not move further out; the spring draws it in). 0: the spring alone. Bound for the
    outer lane (``lane_out_m``), a robot is free of it. (A rule that made a robot beyond the edge come back in at
    this rate fought the human's stop rule for the robots beside him, and dropped the neighbours' rules with it.)"""
    lane_beside_half_m: float = 0.0
    """Improved law: with > ``lane_half_m``, the lane's half-width level with the human (within ``lane_beside_m``
    of him along his walk), narrowing to ``lane_half_m`` over ``lane_beside_ramp_m`` further: robots beside him
    link those ahead of him to those behind (his body keeps them 0.5 m off). 0: the lane is ``lane_half_m``
    everywhere."""
    lane_beside_m: float = 0.6
    """Improved law: how far from level with the human, along his walk, the lane is ``lane_beside_half_m`` wide."""
    lane_beside_ramp_m: float = 0.4
    """Improved law: over how much further along his walk the lane narrows from ``lane_beside_half_m``."""
    lane_level_lead: float = 0.5
    """Improved law: the share of the lead ``lead_s`` a robot level with the human (within ``lane_beside_m`` of him
    along his walk) keeps while the lane is on: with all of it, the robots beside him (the only ones linking those
    ahead of him to those behind, who keep 0.75 m back as he may stop at once) were drawn on ahead of him."""
    lane_outer_level_lead: float = 0.0
    """Improved law: a further share of the lead for a robot level with the walking human (as ``lane_level_lead``)
    that is past halfway to the outer lane (``lane_out_m``): those robots are out of his way and, with the inner
    file ahead of him and the one behind him 0.75 m back (he may stop at once), are what links the swarm across
    him; drawn on ahead with the inner file's lead they left a gap of about the sight S (corridor seed 4, cylinder
    seed 4 torn). 0, the default: none; 1: as the inner lane."""
    lane_out_m: float = 1.0
    """Improved law: with > ``lane_half_m``, a second lane outside the first: a robot further than halfway between
    the two from the human's line (``lane_half_m`` and this) is pushed out to this instead of in, so while he walks
    no robot stays between the two (where a wall's end at a corridor's mouth would meet it). 0: off."""
    lane_speed_mps: float = 0.3
    """Improved law: the lane holds while the human's tracked speed is above this."""
    lane_ramp_s: float = 0.5
    """Improved law: the lane comes in and goes out over this long (he starts walking, he stops)."""
    wake_rate: float = 3.0
    """Improved law: the wake rule (docs/SURROUND.md, item 14): while the lane holds, a robot outside it with a
    neighbour just ahead of it along his walk (within ``wake_reach_m``, overlapping its path) that is nearer his
    line moves across toward that neighbour's offset at least this (/s) times the difference:
    the neighbour hides the way ahead from its forward cone, and where the neighbour went is the only space it
    knows is free. 0: off."""
    wake_reach_m: float = 0.7
    """Improved law: how far ahead of a robot, along the human's walk, a neighbour makes the wake rule."""
    wake_level_m: float = 0.8
    """Improved law: the wake rule leaves alone a robot within this of level with the human along his walk: the
    robots beside him link those ahead of him to those behind."""
    safety_tracked: float = 1.0
    """Improved law: with > 0, the ultrasonic safety stage takes an echo a tracked body explains (a neighbour, the
    human) to move away at least as fast as that body's track says (less ``brake_mps2`` times ``track_lag_s``),
    not only at the ring's own range rate, which an echo new to its cone does not have (taken to stand still:
    a robot between two neighbours stepping into its forward cones was slowed to 0.4 m/s ahead of the walking
    human). 1, the default: on; 0: the ring's rate alone."""
    still_centring: float = 1.5
    """Improved law: more centring spring (/s^2, on top of ``centring``) once the human has stopped (his track
    slower than ``still_speed_mps`` after it was once faster than ``still_walked_mps``), ramped in and out over
    ``still_ramp_s``. The swarm's extent at rest is set by the repulsion (between robots, and from his body out to
    ``avoidance_m`` beyond ``human_clearance_m``) against the springs: with ``centring`` alone it settles at r
    0.70-0.72 m round him, above the paper's r* = 0.65 m (the robots cannot fill the disc his body takes). 1.5, the
    default, takes r at the end to 0.67-0.70 m; 0: off."""
    still_speed_mps: float = 0.3
    """Improved law: the human counts as standing still for ``still_centring`` while his track is slower than this."""
    still_walked_mps: float = 0.6
    """Improved law: ``still_centring`` acts only once the human's track was faster than this (he walked): not
    while the swarm gathers round him before his walk, nor on his track's noise then or his first slow steps."""
    still_ramp_s: float = 2.0
    """Improved law: ``still_centring`` comes in (he stops) and goes out (he walks) over this long."""

    def __post_init__(self) -> None:
        if self.law not in LAWS:
            raise ValueError(f"law must be one of {LAWS}, not {self.law!r}")
        positive = ("sight_m", "avoidance_m", "max_speed_mps", "max_accel_mps2", "robot_radius_m", "dt_s")
        positive += ("body_mass", "stiffness", "pull_ramp_m", "brake_mps2", "escape_mps2", "lane_ramp_s")
        positive += ("lane_beside_ramp_m", "still_ramp_s")
        for name in dataclasses.fields(self):
            if name.name == "law":
                continue
            value = getattr(self, name.name)
            if not isinstance(value, int | float) or isinstance(value, bool) or not math.isfinite(value):
                raise ValueError(f"{name.name} must be a finite number, not {value!r}")
            if name.name in positive and value <= 0:
                raise ValueError(f"{name.name} must be > 0, not {value!r}")
            if value < 0:
                raise ValueError(f"{name.name} must be >= 0, not {value!r}")
        if self.avoidance_m > self.sight_m:
            raise ValueError(f"avoidance_m ({self.avoidance_m}) must not exceed sight_m ({self.sight_m})")
        if self.inertia >= self.body_mass:
            raise ValueError(f"inertia ({self.inertia}) must be below body_mass ({self.body_mass}) to be stable")

    def to_dict(self) -> dict[str, Any]:
        """Plain dict, as accepted by ``from_dict``."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SurroundConfig:
        """Build from a dict of field values (missing ones take the defaults); unknown keys raise ValueError."""
        check_keys(data, (f.name for f in dataclasses.fields(cls)), "surround config")
        return cls(**data)


@dataclass(frozen=True)
class Forces:
    """The three parts of the last step's force, one row per robot (m/s^2 with the unit virtual mass)."""

    centroid: np.ndarray
    """f_R, the impedance toward the local centroid."""
    repulsion: np.ndarray
    """f_O, away from robots and obstacles within A."""
    surround: np.ndarray
    """f_G, toward the human."""


class SurroundLaw:
    """The surround law of ``n`` robots at once, each in its own frame, keeping each one's g_i history.

    Inputs are padded arrays with masks, so robots may see different numbers of things.
    """

    def __init__(self, config: SurroundConfig, n: int) -> None:
        if n < 1:
            raise ValueError(f"n must be >= 1, not {n}")
        self.config = config
        self.n = n
        self._g: np.ndarray | None = None
        self._rate = np.zeros((n, 2))
        self._count = np.zeros(n, dtype=int)
        self._differenced = np.zeros(n, dtype=int)
        zeros = np.zeros((n, 2))
        self.last = Forces(zeros, zeros, zeros)

    def step(
        self,
        neighbours: np.ndarray,
        neighbour_seen: np.ndarray,
        obstacles: np.ndarray,
        obstacle_seen: np.ndarray,
        human: np.ndarray,
        human_seen: np.ndarray,
        velocity: np.ndarray,
        dt: float,
    ) -> np.ndarray:
        """One control step; returns the (n, 2) velocity commands in each robot's frame.

        ``neighbours`` (n, k, 2) with ``neighbour_seen`` (n, k): robots sensed (the law keeps those within
        S); ``obstacles`` (n, m, 2) with ``obstacle_seen`` (n, m): obstacle points (the law keeps those
        within A); ``human`` (n, 2) with ``human_seen`` (n,); ``velocity`` (n, 2) the robot's own.
        """
        if not dt > 0:
            raise ValueError(f"dt must be > 0, not {dt!r}")
        c = self.config
        near = neighbour_seen & (_norm(neighbours) <= c.sight_m)
        g, count = self._centroid(neighbours, near, dt)
        rate, accel = self._derivatives(g, count, dt)
        f_r = c.inertia * accel + c.damping * rate + c.stiffness * g
        f_o = self._repulsion(neighbours, near, obstacles, obstacle_seen)
        f_g = self._surround(g, human, human_seen, velocity)
        self.last = Forces(f_r, f_o, f_g)
        return self._command(f_r + f_o + f_g, velocity, dt)

    def _centroid(self, neighbours: np.ndarray, near: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        count = np.add.reduce(near, axis=1)
        g = np.add.reduce(np.where(near[..., None], neighbours, 0.0), axis=1) / (count + 1)[:, None]
        tau = self.config.centroid_filter_s
        if tau > 0 and self._g is not None:
            # A robot entering or leaving the sight moves g at once: filtering that step would smear the jump
            # over several steps and read it as motion.
            alpha = np.where(count == self._count, dt / (tau + dt), 1.0)[:, None]
            g = self._g + alpha * (g - self._g)
        return g, count

    def _derivatives(self, g: np.ndarray, count: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        if self._g is None:
            rate, accel = np.zeros_like(g), np.zeros_like(g)
        else:
            same = (count == self._count)[:, None]
            fresh = (g - self._g) / dt
            rate = np.where(same, fresh, self._rate)
            accel = np.where(same & (self._differenced[:, None] >= 1), (rate - self._rate) / dt, 0.0)
            self._differenced = np.where(same[:, 0], self._differenced + 1, self._differenced)
        self._g, self._rate, self._count = g, rate, count
        return rate, accel

    def _repulsion(
        self, neighbours: np.ndarray, near: np.ndarray, obstacles: np.ndarray, obstacle_seen: np.ndarray
    ) -> np.ndarray:
        points = np.concatenate([neighbours, obstacles], axis=1)
        seen = np.concatenate([near, obstacle_seen], axis=1)
        distance = _norm(points)
        inside = seen & (distance <= self.config.avoidance_m) & (distance > 0)
        unit = points / np.maximum(distance, 1e-12)[..., None]
        push = np.where(inside, self.config.repulsion / np.maximum(distance, MIN_RANGE_M) ** 2, 0.0)[..., None] * unit
        return -np.add.reduce(push, axis=1)

    def _surround(self, g: np.ndarray, human: np.ndarray, human_seen: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        human_distance = _norm(human)
        toward_human = human / np.maximum(human_distance, 1e-9)[:, None]
        g_unit = g / np.maximum(_norm(g), 1e-9)[:, None]
        speed = _norm(velocity)
        v_unit = velocity / np.maximum(speed, 1e-9)[:, None]
        # cos of a bearing difference is the dot product of unit vectors; an undefined bearing (g_i = 0,
        # or the robot still) gives cos = 0: neither for nor against.
        cos_human = np.add.reduce(toward_human * g_unit, axis=-1)
        cos_motion = np.where(speed > STILL_MPS, np.add.reduce(v_unit * g_unit, axis=-1), 0.0)
        c_i = (1 + cos_human) * (1 + cos_motion) / 4
        active = human_seen & (human_distance > 0)
        return np.where(active[:, None], self.config.surround_force * c_i[:, None] * toward_human, 0.0)

    def _command(self, force: np.ndarray, velocity: np.ndarray, dt: float) -> np.ndarray:
        c = self.config
        accel = (force - c.drag * velocity) / c.body_mass
        accel = _clip_norm(accel, c.max_accel_mps2)
        return _clip_norm(velocity + accel * dt, c.max_speed_mps)


class SurroundController:
    """One robot's surround law on its own sensing, in its own frame (x forward, y left), heading held fixed.

    The law of ``SurroundLaw`` for one robot in plain floats, operation for operation (sums in the same
    order, squares as products, ``max`` for ``np.maximum``), so it gives the batched law's numbers bit for
    bit (``tests/unit/test_surround.py`` holds them equal): numpy's per-call overhead on arrays of two
    values cost a robot about a millisecond per step.
    """

    def __init__(self, config: SurroundConfig | None = None) -> None:
        self.config = config or SurroundConfig()
        self._g: tuple[float, float] | None = None
        self._rate = (0.0, 0.0)
        self._count = 0
        self._differenced = 0
        self._forces = ((0.0, 0.0), (0.0, 0.0), (0.0, 0.0))

    @property
    def last_forces(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(f_R, f_O, f_G) of the last step, each a (2,) array, for logging."""
        f_r, f_o, f_g = self._forces
        return np.array(f_r), np.array(f_o), np.array(f_g)

    def step(
        self,
        neighbours_xy: np.ndarray,
        obstacle_points: np.ndarray,
        human_xy: np.ndarray | None,
        own_velocity: np.ndarray,
        dt: float,
    ) -> np.ndarray:
        """The velocity command (vx, vy) in m/s in the robot's frame.

        ``neighbours_xy`` (k, 2): robots sensed (those beyond S are ignored); ``obstacle_points`` (m, 2):
        ultrasonic hits and the human's body (those beyond A are ignored); ``human_xy``: the human's
        position, or None if not sensed (then no f_G); ``own_velocity`` (2,) in the robot's frame.
        """
        neighbours = _plain_points("neighbours_xy", neighbours_xy)
        obstacles = _plain_points("obstacle_points", obstacle_points)
        velocity = _plain_vector("own_velocity", own_velocity)
        human = None if human_xy is None else _plain_vector("human_xy", human_xy)
        return np.array(self.step_plain(neighbours, obstacles, human, velocity, dt))

    def step_plain(
        self,
        neighbours: Sequence[Sequence[float]],
        obstacles: Sequence[Sequence[float]],
        human: Sequence[float] | None,
        velocity: Sequence[float],
        dt: float,
    ) -> tuple[float, float]:
        """``step`` on points as plain float pairs, unchecked (the pilot's own sensing, finite by making)."""
        distances, near, g, f_r = self._centring(neighbours, dt)
        f_o = self._repulsion(neighbours, distances, near, obstacles)
        f_g = self._surround(g, human, velocity)
        self._forces = (f_r, f_o, f_g)
        force = (f_r[0] + f_o[0] + f_g[0], f_r[1] + f_o[1] + f_g[1])
        return self._command(force, velocity, dt)

    @staticmethod
    def step_all(
        controllers: list[SurroundController],
        terms: np.ndarray,
        neighbours: np.ndarray,
        count: np.ndarray,
        human: np.ndarray,
        human_seen: np.ndarray,
        velocity: np.ndarray,
        dt: np.ndarray,
    ) -> np.ndarray:
        """``step_plain`` of many robots' controllers (of one config, without the centroid filter) at once,
        bit for bit as each alone; returns their commands (n, 2).

        Per robot (row): ``terms`` (n, t, 2) its neighbours (the first ``neighbours``) then its obstacle points,
        ``count`` of them, zeros after; ``human`` (n, 2) where ``human_seen``; ``velocity`` (n, 2); ``dt`` (n,).
        The same elementwise operations as ``step_plain``; its sums, from the first term on, are the running sums
        (``np.add.accumulate``, strictly in order) read at each row's last term: the zeros after never enter."""
        c = controllers[0].config  # every controller's (the caller's word: comparing configs cost more than the law)
        if c.centroid_filter_s > 0:
            raise ValueError("step_all takes controllers without the centroid filter")
        x, y = terms[..., 0], terms[..., 1]
        distance = np.sqrt(x * x + y * y)
        slot = np.arange(terms.shape[1])
        neighbour = slot < neighbours[:, None]
        near = neighbour & (distance <= c.sight_m)
        g = np.stack([_sum_first(np.where(near, x, 0.0), neighbours), _sum_first(np.where(near, y, 0.0), neighbours)])
        g = (g / (np.add.reduce(near, axis=1) + 1)).T
        rate, accel = SurroundController._derivatives_all(controllers, g, np.add.reduce(near, axis=1), dt)
        f_r = c.inertia * accel + c.damping * rate + c.stiffness * g
        inside = (slot < count[:, None]) & (near | ~neighbour) & (distance <= c.avoidance_m) & (distance > 0)
        reach = np.where(distance < MIN_RANGE_M, MIN_RANGE_M, distance)
        magnitude = np.where(inside, c.repulsion / (reach * reach), 0.0)
        scale = np.where(distance < 1e-12, 1e-12, distance)
        f_o = -np.stack([_sum_first(magnitude * (x / scale), count), _sum_first(magnitude * (y / scale), count)]).T
        f_g = _surround_all(c, g, human, human_seen, velocity)
        force = f_r + f_o + f_g
        accel = _clip_all((force - c.drag * velocity) / c.body_mass, c.max_accel_mps2)
        command = _clip_all(velocity + accel * dt[:, None], c.max_speed_mps)
        for ctl, forces in zip(controllers, zip(f_r.tolist(), f_o.tolist(), f_g.tolist(), strict=True), strict=True):
            ctl._forces = tuple(tuple(f) for f in forces)  # type: ignore[assignment]
        return command

    @staticmethod
    def _derivatives_all(
        controllers: list[SurroundController], g: np.ndarray, count: np.ndarray, dt: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``_derivatives`` of every controller, elementwise; each keeps its own g, rate, count and age."""
        old = [ctl._g for ctl in controllers]
        had = np.array([o is not None for o in old])
        old_g = np.array([(0.0, 0.0) if o is None else o for o in old])
        old_rate = np.array([ctl._rate for ctl in controllers])
        same = had & (count == np.array([ctl._count for ctl in controllers]))
        differenced = np.array([ctl._differenced for ctl in controllers])
        step = dt[:, None]
        rate = np.where(same[:, None], (g - old_g) / step, np.where(had[:, None], old_rate, 0.0))
        accel = np.where((same & (differenced >= 1))[:, None], (rate - old_rate) / step, 0.0)
        rows = zip(controllers, g.tolist(), rate.tolist(), count.tolist(), same.tolist(), strict=True)
        for ctl, g_i, rate_i, count_i, same_i in rows:
            ctl._g, ctl._rate, ctl._count = (g_i[0], g_i[1]), (rate_i[0], rate_i[1]), count_i
            ctl._differenced += same_i
        return rate, accel

    def _centring(
        self, neighbours: Sequence[Sequence[float]], dt: float
    ) -> tuple[list[float], list[bool], tuple[float, float], tuple[float, float]]:
        """What both laws start from: each neighbour's distance, whether it is in sight, the centroid g of those
        in sight, and the spring-damper-inertia force f_r on g (raises ValueError unless dt > 0)."""
        if not dt > 0:
            raise ValueError(f"dt must be > 0, not {dt!r}")
        c = self.config
        distances = [math.sqrt(x * x + y * y) for x, y in neighbours]
        near = [d <= c.sight_m for d in distances]
        g, count = self._centroid(neighbours, near, dt)
        rate, accel = self._derivatives(g, count, dt)
        f_r = (
            c.inertia * accel[0] + c.damping * rate[0] + c.stiffness * g[0],
            c.inertia * accel[1] + c.damping * rate[1] + c.stiffness * g[1],
        )
        return distances, near, g, f_r

    def _centroid(
        self, neighbours: Sequence[Sequence[float]], near: list[bool], dt: float
    ) -> tuple[tuple[float, float], int]:
        count = sum(near)
        gx = gy = 0.0
        first = True
        for (x, y), seen in zip(neighbours, near, strict=True):
            if not seen:
                x = y = 0.0
            # numpy's sum starts from the first term (0.0 + -0.0 would lose the sign of a lone -0.0)
            if first:
                gx, gy, first = x, y, False
            else:
                gx += x
                gy += y
        g = (gx / (count + 1), gy / (count + 1))
        tau = self.config.centroid_filter_s
        if tau > 0 and self._g is not None:
            # A robot entering or leaving the sight moves g at once: filtering that step would smear the jump
            # over several steps and read it as motion.
            alpha = dt / (tau + dt) if count == self._count else 1.0
            old = self._g
            g = (old[0] + alpha * (g[0] - old[0]), old[1] + alpha * (g[1] - old[1]))
        return g, count

    def _derivatives(
        self, g: tuple[float, float], count: int, dt: float
    ) -> tuple[tuple[float, float], tuple[float, float]]:
        rate, accel = (0.0, 0.0), (0.0, 0.0)
        old = self._g
        if old is not None and count == self._count:
            last = self._rate
            rate = ((g[0] - old[0]) / dt, (g[1] - old[1]) / dt)
            if self._differenced >= 1:
                accel = ((rate[0] - last[0]) / dt, (rate[1] - last[1]) / dt)
            self._differenced += 1
        elif old is not None:
            rate = self._rate
        self._g, self._rate, self._count = g, rate, count
        return rate, accel

    def _repulsion(
        self,
        neighbours: Sequence[Sequence[float]],
        distances: list[float],
        near: list[bool],
        obstacles: Sequence[Sequence[float]],
    ) -> tuple[float, float]:
        c = self.config
        avoidance, repulsion = c.avoidance_m, c.repulsion
        sx = sy = 0.0
        first = True
        # the neighbours, then the obstacles (seen whatever their distance), summed from the first term on;
        # (plain loops and conditionals for max(): the law runs on every control step of every robot)
        for (x, y), d, seen in zip(neighbours, distances, near, strict=True):
            if seen and d <= avoidance and d > 0:
                reach = MIN_RANGE_M if d < MIN_RANGE_M else d  # max(d, MIN_RANGE_M)
                magnitude = repulsion / (reach * reach)
            else:
                magnitude = 0.0
            scale = 1e-12 if d < 1e-12 else d  # max(d, 1e-12), nan included
            if first:
                sx, sy, first = magnitude * (x / scale), magnitude * (y / scale), False
            else:
                sx += magnitude * (x / scale)
                sy += magnitude * (y / scale)
        for x, y in obstacles:
            d = math.sqrt(x * x + y * y)
            if d <= avoidance and d > 0:
                reach = MIN_RANGE_M if d < MIN_RANGE_M else d
                magnitude = repulsion / (reach * reach)
            else:
                magnitude = 0.0
            scale = 1e-12 if d < 1e-12 else d
            if first:
                sx, sy, first = magnitude * (x / scale), magnitude * (y / scale), False
            else:
                sx += magnitude * (x / scale)
                sy += magnitude * (y / scale)
        return -sx, -sy

    def _surround(
        self, g: tuple[float, float], human: Sequence[float] | None, velocity: Sequence[float]
    ) -> tuple[float, float]:
        if human is None:
            return 0.0, 0.0
        hx, hy = human
        human_distance = math.sqrt(hx * hx + hy * hy)
        if not human_distance > 0:
            return 0.0, 0.0
        reach = max(human_distance, 1e-9)
        tx, ty = hx / reach, hy / reach
        g_norm = max(math.sqrt(g[0] * g[0] + g[1] * g[1]), 1e-9)
        ux, uy = g[0] / g_norm, g[1] / g_norm
        vx, vy = velocity
        speed = math.sqrt(vx * vx + vy * vy)
        # cos of a bearing difference is the dot product of unit vectors; an undefined bearing (g_i = 0,
        # or the robot still) gives cos = 0: neither for nor against.
        cos_human = tx * ux + ty * uy
        if speed > STILL_MPS:
            moving = max(speed, 1e-9)
            cos_motion = vx / moving * ux + vy / moving * uy
        else:
            cos_motion = 0.0
        c_i = (1 + cos_human) * (1 + cos_motion) / 4
        pull = self.config.surround_force * c_i
        return pull * tx, pull * ty

    def _command(self, force: tuple[float, float], velocity: Sequence[float], dt: float) -> tuple[float, float]:
        c = self.config
        vx, vy = velocity
        ax, ay = _plain_clip(
            (force[0] - c.drag * vx) / c.body_mass, (force[1] - c.drag * vy) / c.body_mass, c.max_accel_mps2
        )
        return _plain_clip(vx + ax * dt, vy + ay * dt, c.max_speed_mps)


def _sum_first(values: np.ndarray, count: np.ndarray) -> np.ndarray:
    """Per row of ``values`` (n, t), the sum of its first ``count`` terms in order from the first term on (0.0 for
    none), as ``SurroundController``'s loops sum them, bit for bit and to the sign of zero."""
    if values.shape[1] == 0:
        return np.zeros(len(values))
    running = np.add.accumulate(values, axis=1)
    last = running[np.arange(len(values)), np.maximum(count - 1, 0)]
    return np.where(count > 0, last, 0.0)


def _surround_all(
    c: SurroundConfig, g: np.ndarray, human: np.ndarray, seen: np.ndarray, velocity: np.ndarray
) -> np.ndarray:
    """``SurroundController._surround`` of many robots (n, 2), elementwise in its order (a row's x and y go
    through one operation where the single robot does the same to each)."""
    human_distance = _norm(human)
    toward = human / np.maximum(human_distance, 1e-9)[:, None]
    unit = g / np.maximum(_norm(g), 1e-9)[:, None]
    speed = _norm(velocity)
    moving = velocity / np.maximum(speed, 1e-9)[:, None]
    cos_human = toward[:, 0] * unit[:, 0] + toward[:, 1] * unit[:, 1]
    cos_motion = np.where(speed > STILL_MPS, moving[:, 0] * unit[:, 0] + moving[:, 1] * unit[:, 1], 0.0)
    pull = c.surround_force * ((1 + cos_human) * (1 + cos_motion) / 4)
    active = seen & (human_distance > 0)
    return np.where(active[:, None], pull[:, None] * toward, 0.0)


def _clip_all(v: np.ndarray, limit: float) -> np.ndarray:
    """``_plain_clip`` of each row of ``v`` (n, 2); ``min(1.0, r)`` as Python picks it: 1.0 unless r < 1.0, so a
    nan norm (a half-nan force) scales by 1.0 and keeps the finite half, where ``np.minimum`` gives nan."""
    ratio = limit / np.maximum(_norm(v), 1e-12)
    return v * np.where(ratio < 1.0, ratio, 1.0)[:, None]


def _plain_clip(x: float, y: float, limit: float) -> tuple[float, float]:
    """``_clip_norm`` of one vector."""
    scale = min(1.0, limit / max(math.sqrt(x * x + y * y), 1e-12))
    return x * scale, y * scale


def _plain_points(name: str, value: np.ndarray) -> Sequence[Sequence[float]]:
    """``_points`` as a list of [x, y] pairs."""
    rows = value.tolist() if isinstance(value, np.ndarray) else np.asarray(value, dtype=float).tolist()
    if not rows:
        return []
    if not all(len(row) == 2 if isinstance(row, list) else False for row in rows):
        raise ValueError(f"{name} must have shape (k, 2), not {np.shape(value)}")
    if not all(math.isfinite(x) and math.isfinite(y) for x, y in rows):
        raise ValueError(f"{name} must be finite")
    return [[float(x), float(y)] for x, y in rows]


def _plain_vector(name: str, value: np.ndarray) -> list[float]:
    """``_vector`` as a list [x, y]."""
    array = value if isinstance(value, np.ndarray) else np.asarray(value, dtype=float)
    xy = array.tolist()
    if array.shape != (2,) or not (math.isfinite(xy[0]) and math.isfinite(xy[1])):
        raise ValueError(f"{name} must be a finite (2,) vector, not {value!r}")
    return [float(xy[0]), float(xy[1])]


def extent(positions: np.ndarray) -> float:
    """The swarm's extent r = sqrt(mean |p_i - g|^2) about its centre g."""
    p = _points("positions", positions)
    if len(p) == 0:
        raise ValueError("positions must hold at least one robot")
    return float(np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1))))


def connected(positions: np.ndarray, sight: float) -> bool:
    """Whether the graph linking robots closer than ``sight`` is connected (one robot, or none, is)."""
    p = _points("positions", positions)
    if len(p) <= 1:
        return True
    linked = _pair_distances(p) < sight
    reached = np.zeros(len(p), dtype=bool)
    reached[0] = True
    while True:
        grown = reached | linked[reached].any(axis=0)
        if grown.sum() == reached.sum():
            return bool(reached.all())
        reached = grown


def min_separation(positions: np.ndarray) -> float:
    """The smallest centre-to-centre distance between two robots (inf for fewer than two)."""
    p = _points("positions", positions)
    if len(p) < 2:
        return float("inf")
    d = _pair_distances(p)
    np.fill_diagonal(d, np.inf)
    return float(d.min())


@dataclass(frozen=True)
class Obstacles:
    """Static (or momentary) obstacles: circles (c, 3) as x, y, radius and segments (s, 4) as x1, y1, x2, y2."""

    circles: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))
    segments: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 4)))

    def __post_init__(self) -> None:
        for name, width in (("circles", 3), ("segments", 4)):
            value = np.asarray(getattr(self, name), dtype=float).reshape(-1, width)
            if not np.isfinite(value).all():
                raise ValueError(f"{name} must be finite")
            object.__setattr__(self, name, value)
        if (self.circles[:, 2] <= 0).any():
            raise ValueError("circles: every radius must be > 0")

    @property
    def count(self) -> int:
        """Number of obstacles (circles, then segments)."""
        return len(self.circles) + len(self.segments)

    def nearest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For each point and obstacle: the offset (n, m, 2) to the obstacle's nearest surface point, and the
        signed distance (n, m) to that surface (negative inside a circle)."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        to_centre = self.circles[None, :, :2] - p[:, None, :]
        centre_distance = np.linalg.norm(to_centre, axis=-1)
        radius = self.circles[None, :, 2]
        circle_offset = to_centre * ((centre_distance - radius) / np.maximum(centre_distance, 1e-12))[..., None]
        a, b = self.segments[None, :, :2], self.segments[None, :, 2:]
        along = b - a
        length2 = np.maximum(np.sum(along**2, axis=-1), 1e-12)
        t = np.clip(np.sum((p[:, None, :] - a) * along, axis=-1) / length2, 0.0, 1.0)
        segment_offset = a + t[..., None] * along - p[:, None, :]
        offsets = np.concatenate([circle_offset, segment_offset], axis=1)
        distances = np.concatenate([centre_distance - radius, np.linalg.norm(segment_offset, axis=-1)], axis=1)
        return offsets, distances


@dataclass(frozen=True)
class CollisionCount:
    """Bodies overlapping at one instant: robot pairs, and robot-obstacle pairs."""

    robot_robot: int
    robot_obstacle: int

    @property
    def total(self) -> int:
        """All overlapping pairs."""
        return self.robot_robot + self.robot_obstacle


def collisions(positions: np.ndarray, radius: float, obstacles: Obstacles | None = None) -> CollisionCount:
    """Pairs overlapping now: robots (discs of ``radius``) closer than 2 radius, and robots reaching into an
    obstacle (the human is passed as a circle obstacle to count him)."""
    p = _points("positions", positions)
    if not radius > 0:
        raise ValueError(f"radius must be > 0, not {radius!r}")
    d = _pair_distances(p)
    robot_robot = int(np.sum(np.triu(d < 2 * radius, k=1)))
    robot_obstacle = 0
    if obstacles is not None and obstacles.count:
        robot_obstacle = int(np.sum(obstacles.nearest(p)[1] < radius))
    return CollisionCount(robot_robot, robot_obstacle)


def _pair_distances(p: np.ndarray) -> np.ndarray:
    return np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)


def _norm(v: np.ndarray) -> np.ndarray:
    """Euclidean norm along the last axis, as ``np.linalg.norm(v, axis=-1)`` computes it (sqrt of the
    summed squares), without its Python overhead: the robot's law calls it on tiny arrays at every step."""
    return np.sqrt(np.add.reduce(v * v, axis=-1))


def _clip_norm(v: np.ndarray, limit: float) -> np.ndarray:
    norm = np.sqrt(np.add.reduce(v * v, axis=-1, keepdims=True))
    return v * np.minimum(1.0, limit / np.maximum(norm, 1e-12))


def _points(name: str, value: np.ndarray) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.size == 0:
        return np.zeros((0, 2))
    if array.ndim != 2 or array.shape[1] != 2:
        raise ValueError(f"{name} must have shape (k, 2), not {array.shape}")
    if np.count_nonzero(np.isfinite(array)) != array.size:
        raise ValueError(f"{name} must be finite")
    return array


def _vector(name: str, value: np.ndarray) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.shape != (2,) or np.count_nonzero(np.isfinite(array)) != 2:
        raise ValueError(f"{name} must be a finite (2,) vector, not {value!r}")
    return array


def nearest_per_sector(
    points: Sequence[Sequence[float]], reach: float, sectors: int
) -> dict[int, tuple[float, float, float]]:
    """Of the points (x, y) within ``reach`` (and not at the origin), the nearest in each of ``sectors`` equal
    sectors round the robot, by sector: (x, y, distance). A remembered echo is an arc of points a few degrees
    apart; one a sector keeps the constraints few."""
    nearest: dict[int, tuple[float, float, float]] = {}
    for x, y in points:
        d = math.sqrt(x * x + y * y)
        if not (0 < d <= reach):
            continue
        sector = int((math.atan2(y, x) + math.pi) / (2 * math.pi) * sectors) % sectors
        if sector not in nearest or d < nearest[sector][2]:
            nearest[sector] = (x, y, d)
    return nearest
