"""The world: ground-truth poses of every body, kinematics from motor commands, obstacles, and the
robots' own-body sensors (ultrasonic ranges, AHRS yaw, wheel odometry).

Pure and vectorised: the hub's shell calls ``step`` at a fixed tick with the model time, and asks for
sensor readings with a numpy Generator it seeds. Nothing here knows about radios or zenoh.

Robots are holonomic (mecanum) bases driven by a motor command (vx, vy, omega) in their own frame
(x forward, y left, omega counter-clockwise). The drive follows the command within speed and
acceleration limits, as a motor controller with a ramp does. A motor controller also has a watchdog: a
command older than ``command_timeout_s`` is taken as zero, so a robot whose process died or froze
stops rather than driving on forever. Users are moved by their own process, which sets their pose.

Bodies are discs. When a disc would overlap another body or an obstacle it is pushed back out (bodies
do not pass through each other), and the contact is counted once when it begins: the collision counter
is the figure the experiments report, the push-back only keeps the geometry sane afterwards.
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from radio_hub.config import build_config, check_keys

KINDS = ("robot", "user")


MAX_COORDINATE_M = 1e6
"""How far from the origin a body may be put (a forged pose of 1e300 m must not turn distances into inf)."""
MAX_RATE = 1e3
"""The largest speed (m/s) or turn rate (rad/s) a motor command or a placed body may carry: a forged command of
1.5e308 m/s is finite, but turning it into the world's frame overflowed to inf and made the body nan for good."""


@dataclass
class WorldConfig:
    """Constants of the world and of the robots' bodies and own sensors (choices documented per field)."""

    tick_s: float = 0.02
    """Kinematics step: 50 Hz, the surround paper's time step, fine enough for 1.5 m/s (3 cm per tick)."""
    robot_radius_m: float = 0.15
    """A Pet-Bot is a small mecanum base about 30 cm across."""
    user_radius_m: float = 0.25
    """A person seen from above, shoulders included, as a disc."""
    max_speed_mps: float = 1.5
    """Faster than a brisk walk (1.3 m/s), so a robot can catch up with its user."""
    max_omega_rps: float = 2.5
    max_accel_mps2: float = 2.0
    """A ramp a small mecanum base manages without wheel slip."""
    max_alpha_rps2: float = 8.0
    command_timeout_s: float = 0.5
    """Motor watchdog: a robot that has not commanded for this long is stopped."""
    yaw_noise_deg: float = 1.0
    """AHRS yaw error (standard deviation): a MEMS AHRS with magnetometer indoors is good to about a degree."""
    odometry_noise: float = 0.03
    """Wheel odometry error as a fraction of each measured velocity (mecanum wheels slip a few percent)."""
    ultrasonic_angles_deg: tuple[float, ...] = (0.0, 45.0, 90.0, 135.0, 180.0, -135.0, -90.0, -45.0)
    """Eight sensors round the body: a holonomic base can move sideways and backwards, so it looks there too."""
    ultrasonic_range_m: float = 3.0
    ultrasonic_half_beam_deg: float = 15.0
    """An HC-SR04-like transducer sees a cone of about 30 degrees; the nearest echo in it is reported."""
    ultrasonic_noise_m: float = 0.01

    def validate(self) -> WorldConfig:
        """Raise ValueError naming the first field out of range."""
        positive = (
            "tick_s",
            "robot_radius_m",
            "user_radius_m",
            "max_speed_mps",
            "max_omega_rps",
            "max_accel_mps2",
            "max_alpha_rps2",
            "command_timeout_s",
            "ultrasonic_range_m",
        )
        for name in positive:
            if not getattr(self, name) > 0:
                raise ValueError(f"world.{name} must be > 0, got {getattr(self, name)}")
        for name in ("yaw_noise_deg", "odometry_noise", "ultrasonic_noise_m", "ultrasonic_half_beam_deg"):
            if getattr(self, name) < 0:
                raise ValueError(f"world.{name} must be >= 0, got {getattr(self, name)}")
        if self.tick_s > 0.1:
            raise ValueError(f"world.tick_s must be at most 0.1 s, got {self.tick_s}")
        self.ultrasonic_angles_deg = tuple(float(a) for a in self.ultrasonic_angles_deg)
        return self

    def to_dict(self) -> dict[str, Any]:
        """Plain values, for stats and run records."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> WorldConfig:
        """From a config table; unknown keys and bad values are errors naming the key."""
        return build_config(cls, data, "world.").validate()


@dataclass(frozen=True)
class Obstacle:
    """A circle (x, y, r), a wall (segment x0,y0 - x1,y1) or a rectangle (corners x0,y0 and x1,y1)."""

    kind: str
    x: float = 0.0
    y: float = 0.0
    r: float = 0.0
    x0: float = 0.0
    y0: float = 0.0
    x1: float = 0.0
    y1: float = 0.0

    def segments(self) -> list[tuple[float, float, float, float]]:
        """The walls and rectangle edges as segments (circles have none)."""
        if self.kind == "wall":
            return [(self.x0, self.y0, self.x1, self.y1)]
        if self.kind == "rect":
            a, b, c, d = self.x0, self.y0, self.x1, self.y1
            return [(a, b, c, b), (c, b, c, d), (c, d, a, d), (a, d, a, b)]
        return []

    def to_dict(self) -> dict[str, Any]:
        """The fields of its kind, as a scenario file writes them."""
        keys = {"circle": ("x", "y", "r"), "wall": ("x0", "y0", "x1", "y1"), "rect": ("x0", "y0", "x1", "y1")}
        return {"kind": self.kind, **{k: getattr(self, k) for k in keys[self.kind]}}


def parse_obstacle(spec: dict[str, Any], where: str = "obstacle") -> Obstacle:
    """An obstacle from a scenario table (``where`` names it in errors); ValueError naming what is wrong."""
    needs = {"circle": ("x", "y", "r"), "wall": ("x0", "y0", "x1", "y1"), "rect": ("x0", "y0", "x1", "y1")}
    kind = spec.get("kind") if isinstance(spec, dict) else None
    check_keys(spec, ("kind", *needs.get(kind, ("x", "y", "r", "x0", "y0", "x1", "y1"))), where)
    if kind not in needs:
        raise ValueError(f"{where}: obstacle kind must be circle, wall or rect, not {kind!r}")
    missing = [k for k in needs[kind] if k not in spec]
    if missing:
        raise ValueError(f"{where}: a {kind} obstacle takes {', '.join(needs[kind])}; missing {', '.join(missing)}")
    values = {k: float(spec[k]) for k in needs[kind]}
    if kind == "circle" and values["r"] <= 0:
        raise ValueError(f"a circle's r must be > 0, got {values['r']}")
    if kind == "rect":
        values = {
            "x0": min(values["x0"], values["x1"]),
            "x1": max(values["x0"], values["x1"]),
            "y0": min(values["y0"], values["y1"]),
            "y1": max(values["y0"], values["y1"]),
        }
    return Obstacle(kind, **values)


@dataclass
class Body:
    """One body's truth: pose, velocity in the world frame, and its last motor command.

    Once the world has stepped, ``pose``, ``velocity`` and ``command`` are views of the world's rows (``_Rows``):
    they move with every tick, and a reference kept across a body's coming or going goes stale (read them
    again from ``World.bodies``; copy what must stay as it was)."""

    body_id: str
    kind: str
    radius: float
    pose: np.ndarray
    """x, y, yaw (rad)."""
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """vx, vy (world frame), omega."""
    command: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """vx, vy (body frame), omega, as last commanded."""
    command_t: float = -math.inf


@dataclass(frozen=True)
class OwnSensors:
    """What a robot's own body senses: ultrasonic ranges (nan = no echo), AHRS yaw, wheel odometry."""

    ranges_m: np.ndarray
    yaw_rad: float
    odometry: np.ndarray
    """vx, vy (body frame), omega, as the wheels measured them."""


_POSE, _VELOCITY, _COMMAND = (operator.attrgetter(name) for name in ("pose", "velocity", "command"))
_STATE = operator.attrgetter("pose", "velocity", "command")
_COMMAND_T = operator.attrgetter("command_t")


class _Rows:
    """Every body's pose, velocity and command as (bodies, 3) arrays, a row per body in ``World.bodies`` order,
    and each body's ``pose``, ``velocity`` and ``command`` a view of its row: a change made through either is
    the other's, so the world's array computations take them without gathering them body by body (that was a
    third of a tick). Made again when a body comes, goes or is given another array (``current``)."""

    def __init__(self, bodies: list[Body]) -> None:
        n = len(bodies)
        self.bodies = bodies
        self.ids = tuple(b.body_id for b in bodies)
        self.index = {body_id: k for k, body_id in enumerate(self.ids)}
        self.radius = np.array([b.radius for b in bodies], dtype=float)
        """Radii as the bodies had them (a body's radius is fixed from ``World.add`` on)."""
        self.robots = np.array([k for k, b in enumerate(bodies) if b.kind == "robot"], dtype=np.intp)
        self.robot_bodies = [b for b in bodies if b.kind == "robot"]
        self.pose, self.velocity, self.command = (
            np.array([get(b) for b in bodies], dtype=float).reshape(n, 3) for get in (_POSE, _VELOCITY, _COMMAND)
        )
        for k, body in enumerate(bodies):
            body.pose, body.velocity, body.command = self.pose[k], self.velocity[k], self.command[k]
        self._views = list(map(_STATE, bodies))

    def current(self, bodies: dict[str, Body]) -> bool:
        """Whether these rows are still ``bodies``': the same bodies in the same order, each with its views
        (compared as lists, which take the identical elements as equal without asking them)."""
        try:
            return list(bodies.values()) == self.bodies and list(map(_STATE, self.bodies)) == self._views
        except ValueError:  # another body or array, compared by value (numpy's == is no truth value): not ours
            return False

    def at(self, body_ids: list[str]) -> list[int]:
        """The rows of ``body_ids`` (KeyError for one that is not a body)."""
        index = self.index
        return [index[b] for b in body_ids]


class World:
    """All bodies and obstacles of one world."""

    def __init__(self, config: WorldConfig | None = None, obstacles: list[Obstacle] | None = None) -> None:
        """Start empty; add bodies as nodes attach."""
        self.config = (config or WorldConfig()).validate()
        self.obstacles: list[Obstacle] = list(obstacles or [])
        self.bodies: dict[str, Body] = {}
        self.collisions = 0
        self.collision_log: list[dict[str, Any]] = []
        self._contacts: set[tuple[str, str]] = set()
        self.t = 0.0
        self._segments = _segment_array(self.obstacles)
        self._circles = np.array([(o.x, o.y, o.r) for o in self.obstacles if o.kind == "circle"]).reshape(-1, 3)
        self._ultrasonic_rad = np.array([math.radians(a) for a in self.config.ultrasonic_angles_deg], dtype=float)
        half = math.radians(self.config.ultrasonic_half_beam_deg)
        self._ultrasonic_spread = np.array((-half, 0.0, half) if half > 0 else (0.0,))
        self._cos_half_beam = math.cos(half)
        self._not_self_of: tuple[tuple[Any, ...], np.ndarray] = ((), np.zeros((0, 0), dtype=bool))
        self._rows_of: _Rows | None = None
        self._reaches_of: tuple[Any, np.ndarray, np.ndarray] = ((None, None, None), np.zeros(0), np.zeros(0))

    def _rows(self) -> _Rows:
        """The bodies' state as arrays (``_Rows``), made again only when the bodies changed."""
        rows = self._rows_of
        if rows is None or not rows.current(self.bodies):
            rows = self._rows_of = _Rows(list(self.bodies.values()))
        return rows

    def set_obstacles(self, obstacles: list[Obstacle]) -> None:
        """Replace the obstacles (a scenario loaded at run time)."""
        self.obstacles = list(obstacles)
        self._segments = _segment_array(self.obstacles)
        self._circles = np.array([(o.x, o.y, o.r) for o in self.obstacles if o.kind == "circle"]).reshape(-1, 3)

    def add(self, body_id: str, kind: str, x: float, y: float, yaw: float) -> Body:
        """Place a body (again): a re-attached node keeps no velocity."""
        if kind not in KINDS:
            raise ValueError(f"body kind must be one of {KINDS}, not {kind!r}")
        if not all(math.isfinite(v) for v in (x, y, yaw)) or max(abs(x), abs(y)) > MAX_COORDINATE_M:
            raise ValueError(f"a pose must be finite numbers within {MAX_COORDINATE_M:g} m")
        radius = self.config.robot_radius_m if kind == "robot" else self.config.user_radius_m
        body = Body(body_id, kind, radius, np.array([x, y, _wrap(yaw)], dtype=float))
        self.bodies[body_id] = body
        return body

    def remove(self, body_id: str) -> None:
        """A body that left (its node detached)."""
        self.bodies.pop(body_id, None)
        self._contacts = {c for c in self._contacts if body_id not in c}

    def command(self, body_id: str, vx: float, vy: float, omega: float, t: float) -> None:
        """A robot's motor command in its own frame; raises KeyError/ValueError on a bad one."""
        body = self.bodies[body_id]
        if body.kind != "robot":
            raise ValueError(f"{body_id} is a {body.kind}: only robots take motor commands")
        if not (abs(vx) <= MAX_RATE and abs(vy) <= MAX_RATE and abs(omega) <= MAX_RATE):  # nan fails too
            raise ValueError(f"a motor command must be finite numbers within {MAX_RATE:g} (m/s, rad/s)")
        body.command[:] = (vx, vy, omega)  # in place: the body's row (``_Rows``) stays its array
        body.command_t = t

    def place(
        self, body_id: str, x: float, y: float, yaw: float, vx: float = 0.0, vy: float = 0.0, omega: float = 0.0
    ) -> None:
        """Set a body's pose and world velocity outright (a user walking, or a test teleporting a robot)."""
        if not all(math.isfinite(v) for v in (x, y, yaw, vx, vy, omega)) or max(abs(x), abs(y)) > MAX_COORDINATE_M:
            raise ValueError(f"a pose must be finite numbers within {MAX_COORDINATE_M:g} m")
        if max(abs(vx), abs(vy), abs(omega)) > MAX_RATE:
            raise ValueError(f"a placed body's velocity must be within {MAX_RATE:g} (m/s, rad/s)")
        body = self.bodies[body_id]
        body.pose[:] = (x, y, _wrap(yaw))  # in place: the body's rows (``_Rows``) stay its arrays
        body.velocity[:] = (vx, vy, omega)

    def step(self, t: float) -> None:
        """Advance the robots to model time ``t`` (seconds), then settle contacts."""
        dt = t - self.t
        self.t = t
        if dt <= 0:
            return
        cfg = self.config
        rows = self._rows()
        robots = rows.robot_bodies
        if robots:
            # every robot at once, element by element the arithmetic of one
            at = rows.robots
            pose, velocity = rows.pose[at], rows.velocity[at]
            fresh = t - np.fromiter(map(_COMMAND_T, robots), float, len(robots)) <= cfg.command_timeout_s
            wanted = np.where(fresh[:, None], rows.command[at], 0.0)
            c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
            target = np.empty_like(wanted)
            target[:, 0] = c * wanted[:, 0] - s * wanted[:, 1]
            target[:, 1] = s * wanted[:, 0] + c * wanted[:, 1]
            target[:, :2] = _clip_norms(target[:, :2], cfg.max_speed_mps)
            # np.clip's values, from the two ufuncs it is made of (without its checks, microseconds a call)
            target[:, 2] = np.minimum(np.maximum(wanted[:, 2], -cfg.max_omega_rps), cfg.max_omega_rps)
            change = target - velocity
            change[:, :2] = _clip_norms(change[:, :2], cfg.max_accel_mps2 * dt)
            change[:, 2] = np.minimum(np.maximum(change[:, 2], -cfg.max_alpha_rps2 * dt), cfg.max_alpha_rps2 * dt)
            velocity = velocity + change
            pose = pose + velocity * dt
            pose[:, 2] = (pose[:, 2] + math.pi) % (2 * math.pi) - math.pi
            rows.velocity[at], rows.pose[at] = velocity, pose  # the robots' own arrays are views of these rows
        self._settle_contacts()

    @property
    def contacts(self) -> list[tuple[str, str]]:
        """The pairs in contact after the last step, sorted: two bodies (ids in order), or a body and
        ``obstacle-K`` (K its index in ``obstacles``). A contact is counted in ``collisions`` when its pair
        first appears here."""
        return sorted(self._contacts)

    def _settle_contacts(self) -> None:
        if not self._may_touch():
            contacts: set[tuple[str, str]] = set()
        else:
            contacts = self._settled_contacts()
        for pair in sorted(contacts - self._contacts):
            self.collisions += 1
            self.collision_log.append({"t": round(self.t, 4), "a": pair[0], "b": pair[1]})
        self._contacts = contacts

    def _may_touch(self) -> bool:
        """Whether any two bodies, or a body and an obstacle, are within a hair of touching (one array
        computation; when none is, settling would move nothing and find no contact)."""
        if not self.bodies:
            return False
        rows = self._rows()
        p, radius = rows.pose[:, :2], rows.radius
        slack = 1e-6
        reach, circle_reach = self._reaches(rows, slack)
        gap = p[:, None, :] - p[None, :, :]
        if (np.hypot(gap[..., 0], gap[..., 1]) < reach).any():
            return True
        circles = self._circles
        if len(circles):
            gap = p[:, None, :] - circles[None, :, :2]
            if (np.hypot(gap[..., 0], gap[..., 1]) < circle_reach).any():
                return True
        segments = self._segments
        if len(segments):
            a, e = segments[:, :2], segments[:, 2:] - segments[:, :2]
            length2 = np.einsum("ij,ij->i", e, e)
            with np.errstate(divide="ignore", invalid="ignore"):
                u = np.where(length2 > 0, np.einsum("bsj,sj->bs", p[:, None, :] - a[None], e) / length2, 0.0)
            closest = a[None] + np.clip(u, 0.0, 1.0)[..., None] * e[None]
            gap = p[:, None, :] - closest
            if (np.hypot(gap[..., 0], gap[..., 1]) < radius[:, None] + slack).any():
                return True
        for o in self.obstacles:  # a centre inside a rectangle is pushed out whatever its distance to the sides
            if o.kind == "rect" and ((o.x0 < p[:, 0]) & (p[:, 0] < o.x1) & (o.y0 < p[:, 1]) & (p[:, 1] < o.y1)).any():
                return True
        return False

    def _reaches(self, rows: _Rows, slack: float) -> tuple[np.ndarray, np.ndarray]:
        """The distances within which two bodies (bodies, bodies), or a body and an obstacle circle (bodies,
        circles), may touch: radii plus ``slack``, kept while the bodies and obstacles stay; a body and itself
        never (-inf, as np.fill_diagonal's False did)."""
        made_for = self._reaches_of[0]  # (by identity: an array's == is no truth value)
        if not (made_for[0] is rows and made_for[1] is self._circles and made_for[2] == slack):
            radius = rows.radius
            reach = radius[:, None] + radius[None, :] + slack
            np.fill_diagonal(reach, -np.inf)
            self._reaches_of = (
                (rows, self._circles, slack),
                reach,
                radius[:, None] + self._circles[None, :, 2] + slack,
            )
        return self._reaches_of[1], self._reaches_of[2]

    def _settled_contacts(self) -> set[tuple[str, str]]:
        """Push overlapping bodies apart and out of obstacles, pair by pair; the contacts found."""
        contacts: set[tuple[str, str]] = set()
        bodies = list(self.bodies.values())
        for i, a in enumerate(bodies):
            for b in bodies[i + 1 :]:
                # a pair further apart along x or y than its radii cannot overlap: np.hypot is within an ulp, so
                # never below the larger leg (a float at most the exact norm), and the overlap is then <= 0;
                # the legs are the very differences the gap below holds (poses move as pairs are pushed apart)
                reach = a.radius + b.radius
                gx, gy = a.pose[0] - b.pose[0], a.pose[1] - b.pose[1]
                if gx >= reach or -gx >= reach or gy >= reach or -gy >= reach:
                    continue
                gap = a.pose[:2] - b.pose[:2]
                dist = float(np.hypot(*gap))
                overlap = reach - dist
                if overlap > 0:
                    contacts.add((a.body_id, b.body_id) if a.body_id < b.body_id else (b.body_id, a.body_id))
                    _push_apart(a, b, gap, dist, overlap)
            for k, push in self._obstacle_pushes(a):
                contacts.add((a.body_id, f"obstacle-{k}"))
                if a.kind == "robot":
                    a.pose[:2] += push
        return contacts

    def _obstacle_pushes(self, body: Body) -> list[tuple[int, np.ndarray]]:
        """(obstacle index, push-out vector) for every obstacle the body overlaps."""
        pushes = []
        p = body.pose[:2]
        for k, obstacle in enumerate(self.obstacles):
            if obstacle.kind == "circle":
                reach = body.radius + obstacle.r
                gx, gy = p[0] - obstacle.x, p[1] - obstacle.y
                if gx >= reach or -gx >= reach or gy >= reach or -gy >= reach:  # as for a pair of bodies
                    continue
                gap = p - (obstacle.x, obstacle.y)
                dist = float(np.hypot(*gap))
                depth = reach - dist
                if depth > 0:
                    pushes.append((k, _unit(gap) * depth))
                continue
            if obstacle.kind == "rect" and obstacle.x0 < p[0] < obstacle.x1 and obstacle.y0 < p[1] < obstacle.y1:
                pushes.append((k, _out_of_rect(p, obstacle, body.radius)))
                continue
            for seg in obstacle.segments():
                closest = _closest_on_segment(p, seg)
                gap = p - closest
                dist = float(np.hypot(*gap))
                if dist < body.radius:
                    pushes.append((k, _unit(gap) * (body.radius - dist)))
                    break
        return pushes

    # -- sensors ---------------------------------------------------------------------------------

    def sense(self, body_id: str, rng: np.random.Generator) -> OwnSensors:
        """A robot's ultrasonic ranges, AHRS yaw and wheel odometry, with their noise."""
        return self.sense_many([body_id], rng)[0]

    def sense_many(self, body_ids: list[str], rng: np.random.Generator) -> list[OwnSensors]:
        """``sense`` for several robots: one ray computation for all, and the noise drawn as ``sense`` called
        for each in turn draws it (per body: its echoes' ranges, the yaw, the three odometry values)."""
        if not body_ids:
            return []
        ranges, yaws, odometry = self.sense_arrays(body_ids, rng)
        return [OwnSensors(ranges[k], yaws[k], odometry[k]) for k in range(len(body_ids))]

    def sense_arrays(self, body_ids: list[str], rng: np.random.Generator) -> tuple[np.ndarray, list[float], np.ndarray]:
        """``sense_many`` as arrays for all the robots at once: ranges (bodies, sensors), yaws, odometry (bodies, 3)
        (what the hub sends, converted once for all rather than per robot)."""
        cfg = self.config
        n = len(body_ids)
        if not n:
            return np.zeros((0, len(self._ultrasonic_rad))), [], np.zeros((0, 3))
        ranges = self.ultrasonic_many(body_ids)
        rows = self._rows()
        at = rows.at(body_ids)
        pose, velocity = rows.pose[at], rows.velocity[at]
        # one draw of standard normals for all, cut as the draws body by body would have been
        seen = ~np.isnan(ranges)
        echoes = np.add.reduce(seen, axis=1, dtype=np.intp)  # np.count_nonzero along an axis: its Python path
        ends = np.cumsum(echoes + 4)
        starts = ends - (echoes + 4)
        z = rng.standard_normal(int(ends[-1]))
        at_echo = starts[:, None] + np.cumsum(seen, axis=1) - 1
        ranges[seen] = np.maximum(0.02, ranges[seen] + (0.0 + cfg.ultrasonic_noise_m * z[at_echo[seen]]))
        yaw_noise = 0.0 + math.radians(cfg.yaw_noise_deg) * z[starts + echoes]
        yaw = np.mod(pose[:, 2] + yaw_noise + math.pi, 2 * math.pi) - math.pi
        odometry_noise = 0.0 + cfg.odometry_noise * z[(starts + echoes + 1)[:, None] + np.arange(3)]
        c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
        vx, vy, omega = velocity.T
        odometry = np.empty((n, 3))
        odometry[:, 0], odometry[:, 1], odometry[:, 2] = c * vx + s * vy, -s * vx + c * vy, omega
        odometry *= 1.0 + odometry_noise
        return ranges, yaw.tolist(), odometry

    def ultrasonic(self, body_id: str) -> np.ndarray:
        """Noise-free range of the nearest echo in each sensor's cone (nan when nothing within range)."""
        return self.ultrasonic_many([body_id])[0]

    def ultrasonic_many(self, body_ids: list[str]) -> np.ndarray:
        """``ultrasonic`` of several bodies, shape (bodies, sensors): every ray of every body against every
        circle (obstacles and the other bodies) and segment in one array computation.

        An obstacle echoes from its nearest point anywhere inside a sensor's cone, measured from the body's
        skin, as an HC-SR04-like transducer hears it: a wall's end or a cylinder's near side between the rays
        too (before, three rays per 30 degree cone missed a wall's end 8 degrees off the axis at 0.5 m, and
        robots drove into it). For a convex shape (a disc, a segment) that point is the shape's own nearest
        point when its bearing is within the half beam, else where one of the cone's edges meets the shape:
        so each sensor takes the nearer of its rays (edges and axis) and of those nearest points.

        Bodies (robots, users) still echo only where the three rays meet them: the exact cone would change
        every run with bodies near each other (all the scenarios without obstacles too), and the surround law
        takes its neighbours from IR, dropping their echoes."""
        cfg = self.config
        n = len(body_ids)
        rows = self._rows()
        at = rows.at(body_ids)
        poses = rows.pose[at].reshape(n, 3)
        skin = rows.radius[at]
        origin = poses[:, :2]
        # ray directions (bodies, sensors, rays): heading + sensor angle + spread, as one sensor's cone
        directions = (poses[:, 2, None] + self._ultrasonic_rad)[:, :, None] + self._ultrasonic_spread
        unit = _cos_sin(directions)  # (n, S, K, 2)
        best = np.full(directions.shape, np.inf)
        axis_angle = poses[:, 2, None] + self._ultrasonic_rad  # (n, S)
        axis = _cos_sin(axis_angle)  # (n, S, 2)
        cone = np.full(axis_angle.shape, np.inf)  # (n, S): shapes' nearest points inside the cone
        circles = np.vstack([self._circles, self._bodies_xyr(rows)])
        if len(circles):
            not_self = self._not_self(body_ids, rows.ids, len(circles))
            rel = circles[None, :, :2] - origin[:, None, :]  # (n, M, 2)
            # one matrix-vector product per ray (as rel @ d for a single ray)
            along = np.matmul(rel[:, None, None], unit[..., None])[..., 0]  # (n, S, K, M)
            perp2 = (rel[..., 0] * rel[..., 0] + rel[..., 1] * rel[..., 1])[:, None, None, :] - along**2
            r2 = circles[:, 2] ** 2
            best = np.minimum(best, _ray_hits(along, perp2, r2, not_self))
            # the obstacle circles' near sides between the rays (the bodies keep the three rays: see the docstring)
            fixed = rel[:, : len(self._circles)]
            centre = np.hypot(fixed[..., 0], fixed[..., 1])  # (n, C)
            nearest = np.maximum(centre - self._circles[:, 2], 0.0)
            cone = np.minimum(cone, self._inside_cone(fixed, centre, nearest, axis))
        segments = self._segments
        if len(segments):
            e = segments[:, 2:] - segments[:, :2]  # (G, 2)
            dx, dy = unit[..., 0, None], unit[..., 1, None]  # (n, S, K, 1)
            denom = dx * e[:, 1] - dy * e[:, 0]  # (n, S, K, G)
            ok = np.abs(denom) > 1e-12
            w = segments[None, :, :2] - origin[:, None, :]  # (n, G, 2)
            w0, w1 = w[:, None, None, :, 0], w[:, None, None, :, 1]
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (w0 * e[:, 1] - w1 * e[:, 0]) / denom
                u = (w0 * dy - w1 * dx) / denom
            hit = ok & (t > 0) & (u >= 0) & (u <= 1)
            best = np.minimum(best, np.where(hit, t, np.inf).min(axis=-1))
            length2 = np.einsum("ij,ij->i", e, e)
            with np.errstate(divide="ignore", invalid="ignore"):
                u = np.where(length2 > 0, -np.einsum("ngj,gj->ng", w, e) / length2, 0.0)
            closest = w + np.clip(u, 0.0, 1.0)[..., None] * e  # (n, G, 2), from the origin
            distance = np.hypot(closest[..., 0], closest[..., 1])
            cone = np.minimum(cone, self._inside_cone(closest, distance, distance, axis))
        reach = np.minimum(best.min(axis=-1), cone) - skin[:, None]
        return np.where(reach <= cfg.ultrasonic_range_m, reach, np.nan)

    @staticmethod
    def _bodies_xyr(rows: _Rows) -> np.ndarray:
        """(bodies, 3): every body's x, y and radius, as circles."""
        xyr = np.empty((len(rows.ids), 3))
        xyr[:, :2] = rows.pose[:, :2]
        xyr[:, 2] = rows.radius
        return xyr

    def _not_self(self, body_ids: list[str], everyone: tuple[str, ...], count: int) -> np.ndarray:
        """(sensing bodies, circles): False where the circle is the sensing body itself (no echo off oneself);
        the same bodies sense at every tick, so the last answer is kept."""
        key = (tuple(body_ids), everyone, len(self._circles), count)
        if self._not_self_of[0] != key:
            not_self = np.ones((len(body_ids), count), dtype=bool)
            index = {body_id: len(self._circles) + k for k, body_id in enumerate(everyone)}
            not_self[np.arange(len(body_ids)), [index[b] for b in body_ids]] = False
            not_self.flags.writeable = False
            self._not_self_of = (key, not_self)
        return self._not_self_of[1]

    def _inside_cone(self, point: np.ndarray, distance: np.ndarray, echo: np.ndarray, axis: np.ndarray) -> np.ndarray:
        """(n, S): the least ``echo`` (n, M) over the shapes whose nearest ``point`` (n, M, 2), at ``distance``
        (n, M) from the sensor, lies within the half beam of each sensor's ``axis`` (n, S, 2); inf if none."""
        along = np.einsum("nmj,nsj->nsm", point, axis)
        inside = along >= self._cos_half_beam * distance[:, None, :]
        return np.where(inside, echo[:, None, :], np.inf).min(axis=-1, initial=np.inf)

    def poses(self) -> dict[str, tuple[float, float, float]]:
        """Every body's pose (x, y, yaw) as plain floats, by id (for the IR light and the radio ranges)."""
        rows = self._rows()
        return dict(zip(rows.ids, map(tuple, rows.pose.tolist()), strict=True))

    def truth_rows(self) -> list[list[float]]:
        """Every body's pose and velocity (x, y, yaw, vx, vy, omega), each ``round(value, 4)`` as records and
        viewers take them, in the order of ``bodies``."""
        if not self.bodies:
            return []
        rows = self._rows()
        return round_places(np.hstack([rows.pose, rows.velocity]), 4)

    def snapshot(self) -> list[dict[str, Any]]:
        """Every body's truth as plain values (for the world publication and records)."""
        bodies = list(self.bodies.values())
        return [
            {
                "id": b.body_id,
                "kind": b.kind,
                "x": x,
                "y": y,
                "yaw": yaw,
                "vx": vx,
                "vy": vy,
                "omega": omega,
                "radius": b.radius,
            }
            for b, (x, y, yaw, vx, vy, omega) in zip(bodies, self.truth_rows(), strict=True)
        ]


def round_places(values: np.ndarray, places: int) -> list[list[float]]:
    """``round(v, places)`` of every value of a 2-D array, bit for bit, as nested lists of Python floats.

    Python's ``round`` converts through a decimal string, about a microsecond a value (the world log rounds
    126 every tick). Here: k, the integer nearest ``v * 10**places``, then ``k / 10**places``, which IEEE
    division rounds to the double nearest the decimal k * 10**-places, which is what ``round`` returns. The
    product is off the exact one by half an ulp, so k is sure unless it lies within a few ulps of a half (or
    is too large for the units to count); those few, and nan and inf, take ``round`` itself."""
    scale = 10.0**places
    scaled = values * scale
    k = np.rint(scaled)
    rows = (k / scale).tolist()
    size = np.abs(scaled)
    largest = size.max() if size.size else 0.0
    if largest < 2.0**50 and (not size.size or np.abs(np.abs(scaled - k) - 0.5).min() > largest * 2.0**-48):
        # every value sure at once, the largest's margin standing for all (nan and inf fail the first test, so
        # they take the way below, as does a line with a value within a few ulps of a half)
        return rows
    with np.errstate(invalid="ignore"):  # inf - inf: not sure
        sure = (np.abs(np.abs(scaled - k) - 0.5) > size * 2.0**-48) & (size < 2.0**50)
    if not sure.all():
        exact = values.tolist()
        for i, j in zip(*np.nonzero(~sure), strict=True):
            rows[i][j] = round(exact[i][j], places)
    return rows


def _segment_array(obstacles: list[Obstacle]) -> np.ndarray:
    return np.array([seg for o in obstacles for seg in o.segments()], dtype=float).reshape(-1, 4)


def _closest_on_segment(p: np.ndarray, seg: tuple[float, float, float, float]) -> np.ndarray:
    a, b = np.array(seg[:2]), np.array(seg[2:])
    e = b - a
    length2 = float(e @ e)
    u = 0.0 if length2 == 0 else float(np.clip((p - a) @ e / length2, 0.0, 1.0))
    return a + u * e


def _out_of_rect(p: np.ndarray, rect: Obstacle, radius: float) -> np.ndarray:
    # a centre inside the rectangle leaves through the nearest side
    gaps = [p[0] - rect.x0, rect.x1 - p[0], p[1] - rect.y0, rect.y1 - p[1]]
    side = int(np.argmin(gaps))
    push = gaps[side] + radius
    return np.array([(-push, 0.0), (push, 0.0), (0.0, -push), (0.0, push)][side])


def _push_apart(a: Body, b: Body, gap: np.ndarray, dist: float, overlap: float) -> None:
    direction = _unit(gap) if dist > 1e-9 else np.array([1.0, 0.0])
    # a user is moved by their own process; only robots yield
    share_a = 0.0 if a.kind != "robot" else (0.5 if b.kind == "robot" else 1.0)
    share_b = 0.0 if b.kind != "robot" else (0.5 if a.kind == "robot" else 1.0)
    a.pose[:2] += direction * overlap * share_a
    b.pose[:2] -= direction * overlap * share_b


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.hypot(*v))
    return v / n if n > 1e-12 else np.array([1.0, 0.0])


def _ray_hits(along: np.ndarray, perp2: np.ndarray, r2: np.ndarray, not_self: np.ndarray) -> np.ndarray:
    """(n, S, K): each ray's nearest hit among the circles (inf: none), from the distances ``along`` each ray
    to the circles' feet and the squared distances ``perp2`` of their centres from it, (n, S, K, M), and the
    circles' squared radii ``r2``. The values of ``where(hit, max(along - sqrt(r2 - perp2), 0), inf)``, in
    place in ``perp2``: a ray hits where r2 - perp2 >= 0 (as perp2 <= r2: a float difference is never 0 for
    two different floats), ahead of it, and not its own body; elsewhere the root is of 0, not nan, and unused."""
    gap = np.subtract(r2, perp2, out=perp2)
    hit = gap >= 0
    hit &= along > 0
    hit &= not_self[:, None, None, :]
    np.maximum(gap, 0.0, out=gap)
    t = np.subtract(along, np.sqrt(gap, out=gap), out=gap)
    np.maximum(t, 0.0, out=t)
    np.copyto(t, np.inf, where=~hit)
    return t.min(axis=-1)


def _cos_sin(angles: np.ndarray) -> np.ndarray:
    """cos and sin of every angle along a new last axis (``np.stack`` of the two, without its cost)."""
    out = np.empty((*angles.shape, 2))
    # each computed into an array of its own, as np.stack's were: a strided output may take another loop
    out[..., 0], out[..., 1] = np.cos(angles), np.sin(angles)
    return out


def _clip_norms(v: np.ndarray, limit: float) -> np.ndarray:
    """Every row of an (n, 2) array scaled down to the norm ``limit`` where it is longer (as v (limit / |v|))."""
    n = np.hypot(v[:, 0], v[:, 1])
    if not limit > 0:
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where((n > limit)[:, None], v * (limit / n)[:, None], v)
    # the same values without np.errstate (microseconds a use, four a tick): limit / max(n, limit) is limit / n
    # where a row is longer and exactly 1 elsewhere (v times 1 is v), and never a division by zero (an infinite
    # row, which no body has, is nan either way, here with numpy's warning)
    scale = np.where(n > limit, limit / np.maximum(n, limit), 1.0)
    return v * scale[:, None]


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi
