"""What a surround robot senses, in its own frame: neighbours and the human from IR beacons, obstacles from
ultrasonic echoes. Pure: readings in, points out (the robot process's ``surround_driver`` is the shell).

- Every beacon the IR module demodulates (one sweep of 12 readings per source) goes through the IR
  estimator (``ir_estimator.estimate_many``) to a distance and bearing, hence a point (x forward, y left).
  The human's beacon (his node id) gives the human G; every other beacon is a neighbour robot.
- The human is an obstacle too (the spec: keep him out of collisions): his obstacle point is the surface
  of his body facing the robot, his estimated centre brought ``person_radius_m`` closer, as the
  simulation (``surround_sim``) senses him.
- An ultrasonic echo at range r (measured from the robot's skin) on the sensor at angle a is the point
  (robot_radius + r) (cos a, sin a) from the robot's centre: where the echo came from.
- Echoes also come off neighbours and the human, who are already in the law (a neighbour as its centre,
  the human as his surface point). Counting them again would double their repulsion, and only when they
  happen to sit in one of the eight cones, so an echo that lies within a beacon's body (its radius plus
  ``echo_match_m``) is dropped as explained by that beacon. What is left is walls and other obstacles.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

from petswarm.managers.ir_estimator import estimate_many
from radio_hub.datasheet import PERSON_BEACON_POWER, RECEIVERS, IrConfig
from radio_hub.values import lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)


@dataclass(frozen=True)
class SensingConfig:
    """The robot's knowledge of bodies around it, used to read its sensors.

    - ``robot_radius_m`` 0.1: the surround paper's robots (a neighbour's body is taken to be as big as one's own).
    - ``person_radius_m`` 0.25: a person seen from above, shoulders included (the world's default user disc);
      a smaller guess would let robots brush him, a larger one only keeps them a little further off.
    - ``echo_match_m`` 0.1: slack on a beacon's body when deciding an echo came off it: the IR estimate's
      distance error (about 1-3 % out to 1 m, a few cm) and the cone's 15 degree half width (an echo from
      the side of a robot 0.3 m away reads up to ~4 cm off its surface), with margin.
    """

    robot_radius_m: float = 0.1
    person_radius_m: float = 0.25
    echo_match_m: float = 0.1

    def __post_init__(self) -> None:
        for name in ("robot_radius_m", "person_radius_m", "echo_match_m"):
            value = getattr(self, name)
            if not isinstance(value, int | float) or not np.isfinite(value) or value < 0:
                raise ValueError(f"{name} must be a finite number >= 0, not {value!r}")


@dataclass(frozen=True)
class SurroundSensing:
    """One control step's view, in the robot's frame: neighbour centres (k, 2), obstacle points (m, 2) (echoes
    not explained by a beacon, and the human's body), and the human's centre (None when his beacon is unseen)."""

    neighbours: np.ndarray
    obstacles: np.ndarray
    human: np.ndarray | None
    echoes_dropped: int = 0
    """Echoes taken to come off a neighbour or the human."""


def beacon_points(
    beacons: dict[str, np.ndarray],
    ir: IrConfig,
    method: str = "lsq",
    person: str | None = None,
    gains: dict[str, float] | None = None,
) -> dict[str, np.ndarray]:
    """Each visible beacon's estimated position (2,) in the robot's frame; sources without signal are left out.
    ``person``: the node id of the human's beacon, ``PERSON_BEACON_POWER`` times as bright as a robot's
    module, so its distance comes from the correspondingly brighter calibration. ``gains``: the gain each
    beacon's channel was read at (its AGC's; missing ones 1): a reading at gain g is the light of a source
    g times as bright, so each gain has its own calibration."""
    if not beacons:
        return {}
    names = list(beacons)
    gains = gains or {}
    readings = np.array([np.asarray(beacons[n], dtype=float) for n in names], dtype=float)
    seen, xy = beacon_fixes(names, readings, [gains.get(n, 1.0) for n in names], ir, method, person)
    return dict(zip(seen, xy, strict=True))


def beacon_fixes(
    names: list[str],
    readings: np.ndarray,
    gains: list[float],
    ir: IrConfig,
    method: str = "lsq",
    person: str | None = None,
) -> tuple[list[str], np.ndarray]:
    """``beacon_points`` of one sweep as arrays: ``readings`` (k, 12) of the beacons ``names`` read at
    ``gains``, all through one estimate (each with its own calibration); returns the names of those with a
    signal, in the order given, and their positions (m, 2)."""
    if not names:
        return [], np.zeros((0, 2))
    brightness = [(PERSON_BEACON_POWER if n == person else 1.0) * g for n, g in zip(names, gains, strict=True)]
    found = estimate_many(readings, ir, method, brightness)
    xy = np.empty((len(names), 2))
    np.multiply(np.cos(found.bearing_rad), found.distance_m, out=xy[:, 0])
    np.multiply(np.sin(found.bearing_rad), found.distance_m, out=xy[:, 1])
    valid = found.valid
    if np.count_nonzero(valid) == len(names):
        return list(names), xy
    return [n for n, v in zip(names, valid.tolist(), strict=True) if v], xy[valid]


def _brightness(job: SweepJob) -> list[float]:
    """``beacon_fixes``'s brightness of each of a sweep's beacons: its gain (1.0 g, which ``estimate_many`` reads as
    the very number g is), the human's times his beacon's power (a sweep naming him twice: the general way)."""
    if job.person not in job.names:
        return list(job.gains)
    if job.names.count(job.person) > 1:
        return [
            (PERSON_BEACON_POWER if n == job.person else 1.0) * g for n, g in zip(job.names, job.gains, strict=True)
        ]
    brightness = list(job.gains)
    at = job.names.index(job.person)
    brightness[at] = PERSON_BEACON_POWER * brightness[at]
    return brightness


_IN_ORDER = slice(None)
"""``BeaconTracker._same_beacons``: the fixes are in the tracks' order already (every row, as it is)."""


class SweepJob(NamedTuple):
    """One robot's sweep to turn into fixes (``beacon_fixes``'s arguments, less the calibration and method).
    (A named tuple: twenty are made per 25 Hz round of a model run, where a frozen dataclass's setup showed.)"""

    names: list[str]
    readings: np.ndarray
    gains: list[float]
    person: str | None


def beacon_fixes_batch(jobs: list[SweepJob], ir: IrConfig, method: str = "lsq") -> list[tuple[list[str], np.ndarray]]:
    """``beacon_fixes`` of many robots' sweeps through one estimate: each result is, bit for bit, what
    ``beacon_fixes`` gives for that sweep alone, so a model-time run that batches its robots' sweeps and a
    lockstep run where each robot estimates its own give one digest.

    Why that holds: the estimator works row by row (elementwise ufuncs, per-row reductions and choices), and
    its small matrix products go through BLAS's gemm, whose rounding of a row does not depend on the rows
    beside it, except that a product of one row goes through gemv, which rounds differently; so a sweep of
    one beacon is estimated alone, as its robot would. Only sweeps the estimator takes without complaint
    are batched (finite readings, gains > 0): the others go alone too, so a bad one fails as it would alone.
    """
    together = [job for job in jobs if _batchable(job)]
    readings = np.concatenate([job.readings for job in together]) if together else None
    if readings is not None and not np.isfinite(readings).all():
        together = [job for job in together if np.isfinite(job.readings).all()]
        readings = np.concatenate([job.readings for job in together]) if together else None
    found = {}
    if readings is not None:
        found = dict(zip(map(id, together), _fixes_together(together, readings, ir, method), strict=True))
    return [
        found[id(job)] if id(job) in found else beacon_fixes(job.names, job.readings, job.gains, ir, method, job.person)
        for job in jobs
    ]


def _batchable(job: SweepJob) -> bool:
    """Whether a sweep may go into the shared estimate: two beacons or more, of the right shape, gains > 0
    (``beacon_fixes_batch`` also checks that the readings are finite)."""
    names, readings, gains, _ = job
    return (
        len(names) >= 2
        and readings.shape == (len(names), RECEIVERS)
        and min(gains) > 0
        and not any(g != g for g in gains)
    )


def _fixes_together(
    jobs: list[SweepJob], readings: np.ndarray, ir: IrConfig, method: str
) -> list[tuple[list[str], np.ndarray]]:
    """``beacon_fixes`` of every job, through one ``estimate_many`` of all their rows (``readings``, the jobs'
    readings one under the other)."""
    brightness: list[float] = []
    for job in jobs:
        brightness += _brightness(job)
    found = estimate_many(readings, ir, method, brightness, [len(job.names) for job in jobs])
    xy = np.empty((len(readings), 2))
    np.multiply(np.cos(found.bearing_rad), found.distance_m, out=xy[:, 0])
    np.multiply(np.sin(found.bearing_rad), found.distance_m, out=xy[:, 1])
    valid = found.valid.tolist()
    out = []
    start = 0
    for job in jobs:
        end = start + len(job.names)
        rows = valid[start:end]
        if all(rows):
            out.append((list(job.names), xy[start:end].copy()))
        else:
            keep = [start + i for i, v in enumerate(rows) if v]
            out.append(([n for n, v in zip(job.names, rows, strict=True) if v], xy[keep]))
        start = end
    return out


TRACK_ALPHA = 0.5
"""The alpha-beta tracker's position gain: each sweep's fix moves the track half way (IR noise ~1-2 cm at 1 m)."""
TRACK_BETA = 0.17
"""Its velocity gain, alpha^2 / (2 - alpha): Benedict and Bordner's choice for that alpha (less lag on a
manoeuvring target than the critically damped 0.09, which a swarm pushing and braking is)."""


class BeaconTracker:
    """Each beacon's position and velocity in the robot's frame, between and across sweeps (designed for 20 Hz
    sweeps under 25 Hz steps; the hub sweeps with the body sensors, 25 Hz, so a lost or late sweep is bridged).

    Why: stepping at 25 Hz on 20 Hz sweeps, a tracker that takes beacons to stand still between sweeps sees
    a neighbour driving beside it at v fall back by v x 40 ms and jump ahead at the next sweep; the law
    differences that sawtooth into a centroid rate of +-v, which the damping B = 6.4 turns into +-6 m/s^2,
    more than the acceleration limit: the clipped noise swamped the surround force, and in a model-time run
    of the cylinder scenario the swarm ended 8 m behind its human (1.6 m with this tracker). Here each beacon
    keeps a velocity of its own (an alpha-beta filter on its fixes, in the robot's non-turning frame), so a
    neighbour driving along stays put relative to us.

    The tracks are kept as arrays (one row per beacon, in the order they were first seen), so a step costs
    a few array operations whatever the number of beacons.
    """

    def __init__(self, alpha: float = TRACK_ALPHA, beta: float = TRACK_BETA) -> None:
        if not 0 < alpha <= 1 or not 0 <= beta < 2:
            raise ValueError(f"alpha must be in (0, 1] and beta in [0, 2), not {alpha}, {beta}")
        self.alpha, self.beta = alpha, beta
        self._names: list[str] = []
        self._rows: dict[str, int] = {}
        self._position = np.zeros((0, 2))
        self._velocity = np.zeros((0, 2))
        """Each beacon's own velocity (not relative to us), in our frame."""
        self._since_fix = 0.0
        self._reorder: tuple[list[str], list[str], np.ndarray | None] = ([], [], None)
        """The last ``_same_beacons`` answer that needed a reordering: the sweep's names, the tracks'
        names (that very list) and the order."""

    @property
    def points(self) -> dict[str, np.ndarray]:
        """The tracked beacons' positions now, in the robot's frame."""
        return dict(zip(self._names, self._position, strict=True))

    @property
    def names(self) -> list[str]:
        """The tracked beacons, in the order of ``positions``."""
        return list(self._names)

    @property
    def positions(self) -> np.ndarray:
        """The tracked beacons' positions now (k, 2), in the order of ``names``."""
        return self._position

    @property
    def velocities(self) -> np.ndarray:
        """The tracked beacons' own velocities (k, 2), in the order of ``names``, in the robot's frame."""
        return self._velocity

    def velocity_of(self, name: str) -> tuple[float, float] | None:
        """The tracked velocity of beacon ``name`` (its own, not relative to us, in our frame), or None untracked."""
        row = self._rows.get(name)
        if row is None:
            return None
        vx, vy = self._velocity[row].tolist()
        return vx, vy

    def predict(self, own_velocity: np.ndarray, dt: float) -> None:
        """Move every track ``dt`` seconds on: it drives at its velocity, we at ``own_velocity`` (odometry)."""
        if not dt >= 0:
            raise ValueError(f"dt must be >= 0, not {dt!r}")
        if self._names:
            # a new array, never written in place: points handed out before stay as they were
            self._position = self._position + (self._velocity - np.asarray(own_velocity, dtype=float)) * dt
        self._since_fix += dt

    def update(self, fixes: dict[str, np.ndarray], own_velocity: np.ndarray) -> None:
        """A sweep's fixes: tracks of beacons in it are corrected, new ones start at rest relative to us, and
        beacons missing from it are dropped (out of sight)."""
        names = list(fixes)
        xy = np.array([np.asarray(fixes[n], dtype=float) for n in names], dtype=float).reshape(-1, 2)
        self.update_many(names, xy, own_velocity)

    def update_many(self, names: list[str], xy: np.ndarray, own_velocity: np.ndarray) -> None:
        """``update`` with the fixes as arrays: ``names`` (k) and their positions ``xy`` (k, 2)."""
        own = np.asarray(own_velocity, dtype=float)
        period = self._since_fix
        self._since_fix = 0.0
        if period > 0 and names:
            order = self._same_beacons(names)
            if order is not None:  # the same beacons as last sweep: every track goes on, in its row
                fixed = np.asarray(xy, dtype=float).reshape(-1, 2)
                innovation = fixed[order] - self._position
                self._position = self._position + self.alpha * innovation
                self._velocity = self._velocity + self.beta * innovation / period
                return
        fix_row = {n: i for i, n in enumerate(names)}
        old = self._rows
        kept = [n for n in self._names if n in fix_row]  # tracks go on in their order, new ones after
        new = [n for n in names if n not in old]
        order = kept + new
        fixed = xy[[fix_row[n] for n in order]] if order != names else np.asarray(xy, dtype=float)
        if period <= 0 or not kept:
            position, velocity = fixed, np.tile(own, (len(order), 1))
        else:
            k = len(kept)
            if kept == self._names:  # every track goes on, in its row
                tracked, moving = self._position, self._velocity
            else:
                rows = [old[n] for n in kept]
                tracked, moving = self._position[rows], self._velocity[rows]
            innovation = fixed[:k] - tracked
            position = tracked + self.alpha * innovation
            velocity = moving + self.beta * innovation / period
            if new:
                position = np.concatenate([position, fixed[k:]])
                velocity = np.concatenate([velocity, np.tile(own, (len(new), 1))])
        self._names, self._rows = order, {n: i for i, n in enumerate(order)}
        self._position, self._velocity = position.reshape(-1, 2), velocity.reshape(-1, 2)

    def _same_beacons(self, names: list[str]) -> np.ndarray | slice | None:
        """When ``names`` are the tracked beacons, perhaps in another order: the row of ``names`` for each track
        (``_IN_ORDER`` when the orders agree), else None. A sweep lists its beacons in its own order, most often
        the same from sweep to sweep, so the last answer is kept."""
        if names == self._names:
            return _IN_ORDER
        key, tracks, order = self._reorder
        if names == key and tracks is self._names:
            return order
        if len(names) != len(self._names) or set(names) != self._rows.keys():
            return None
        row = {n: i for i, n in enumerate(names)}
        order = np.array([row[n] for n in self._names], dtype=np.intp)
        self._reorder = (list(names), self._names, order)
        return order

    @staticmethod
    def predict_all(trackers: list[BeaconTracker], own_velocities: np.ndarray, dts: list[float]) -> None:
        """``predict`` of many trackers at once (``own_velocities`` (n, 2), ``dts`` > 0 from the caller), bit
        for bit as each alone: the same elementwise operations, on every track's rows stacked."""
        moving = [i for i, tracker in enumerate(trackers) if tracker._names]
        for tracker, dt in zip(trackers, dts, strict=True):
            tracker._since_fix += dt
        if not moving:
            return
        counts = [len(trackers[i]._names) for i in moving]
        position = np.concatenate([trackers[i]._position for i in moving])
        velocity = np.concatenate([trackers[i]._velocity for i in moving])
        own = np.repeat(own_velocities[moving], counts, axis=0)
        dt = np.repeat(np.array([dts[i] for i in moving]), counts)[:, None]
        BeaconTracker._spread([trackers[i] for i in moving], counts, position + (velocity - own) * dt, None)

    @staticmethod
    def update_all(
        trackers: list[BeaconTracker], fixes: list[tuple[list[str], np.ndarray]], own_velocities: np.ndarray
    ) -> None:
        """``update_many`` of many trackers at once, bit for bit as each alone: those whose sweep holds the
        beacons they track (the usual sweep) are corrected together, the others one by one."""
        if any(t.alpha != trackers[0].alpha or t.beta != trackers[0].beta for t in trackers):
            raise ValueError("update_all takes trackers of one alpha and beta")  # before any tracker changes
        steady: list[tuple[BeaconTracker, np.ndarray, float]] = []
        for tracker, (names, xy), own in zip(trackers, fixes, own_velocities, strict=True):
            period = tracker._since_fix
            order = tracker._same_beacons(names) if period > 0 and names else None
            if order is None:
                tracker.update_many(names, xy, own)
                continue
            tracker._since_fix = 0.0
            fixed = (
                xy if order is _IN_ORDER and xy.dtype == float else np.asarray(xy, dtype=float).reshape(-1, 2)[order]
            )
            steady.append((tracker, fixed, period))
        if not steady:
            return
        counts = [len(fixed) for _, fixed, _ in steady]
        position = np.concatenate([tracker._position for tracker, _, _ in steady])
        velocity = np.concatenate([tracker._velocity for tracker, _, _ in steady])
        period = np.repeat(np.array([p for _, _, p in steady]), counts)[:, None]
        innovation = np.concatenate([fixed for _, fixed, _ in steady]) - position
        alpha, beta = steady[0][0].alpha, steady[0][0].beta
        position = position + alpha * innovation
        velocity = velocity + beta * innovation / period
        BeaconTracker._spread([tracker for tracker, _, _ in steady], counts, position, velocity)

    @staticmethod
    def _spread(
        trackers: list[BeaconTracker], counts: list[int], position: np.ndarray, velocity: np.ndarray | None
    ) -> None:
        """Hand each tracker its rows of the stacked ``position`` (and ``velocity`` unless None), as views:
        the stacks are new arrays, never written in place, as a lone tracker's are."""
        start = 0
        for tracker, count in zip(trackers, counts, strict=True):
            end = start + count
            tracker._position = position[start:end]
            if velocity is not None:
                tracker._velocity = velocity[start:end]
            start = end

    def clear(self) -> None:
        """Forget every beacon (the sweeps stopped)."""
        self._names, self._rows = [], {}
        self._position, self._velocity = np.zeros((0, 2)), np.zeros((0, 2))


def echo_points(ranges_m: np.ndarray, angles_rad: np.ndarray, robot_radius_m: float) -> np.ndarray:
    """The points (m, 2) the echoes came from, from the robot's centre; sensors without an echo (nan) give none."""
    ranges = np.asarray(ranges_m, dtype=float)
    angles = np.asarray(angles_rad, dtype=float)
    if ranges.shape != angles.shape:
        raise ValueError(f"ranges_m {ranges.shape} and angles_rad {angles.shape} must match")
    points = echo_list(ranges.tolist(), np.cos(angles).tolist(), np.sin(angles).tolist(), robot_radius_m)
    return np.array(points, dtype=float).reshape(-1, 2)


def echo_list(
    ranges: list[float], cos: list[float], sin: list[float], robot_radius_m: float
) -> list[tuple[float, float]]:
    """``echo_points`` in plain floats, given the cosines and sines of the sensors' angles (a robot's ring is
    fixed, so it works them out once): a pilot step handles eight echoes, where numpy's per-call overhead is
    most of the cost."""
    points = []
    for r, c, s in zip(ranges, cos, sin, strict=True):
        if math.isfinite(r):
            reach = robot_radius_m + r
            points.append((c * reach, s * reach))
    return points


def sense(
    beacon_xy: dict[str, np.ndarray],
    echoes: np.ndarray,
    human_id: str,
    config: SensingConfig,
) -> SurroundSensing:
    """Sort beacons into neighbours and the human, add the human's body to the obstacles, and drop the echoes
    that a beacon explains."""
    names = list(beacon_xy)
    xy = np.array([np.asarray(beacon_xy[n], dtype=float) for n in names], dtype=float).reshape(-1, 2)
    return sense_many(names, xy, echoes, human_id, config)


def sense_many(
    names: list[str], xy: np.ndarray, echoes: np.ndarray, human_id: str, config: SensingConfig
) -> SurroundSensing:
    """``sense`` with the beacons as arrays: ``names`` (k) at ``xy`` (k, 2)."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    echoes = np.asarray(echoes, dtype=float).reshape(-1, 2)
    neighbours, obstacles, human, dropped = sense_lists(names, xy, echoes.tolist(), human_id, config)
    return SurroundSensing(
        np.array(neighbours, dtype=float).reshape(-1, 2),
        np.array(obstacles, dtype=float).reshape(-1, 2),
        None if human is None else np.array(human),
        dropped,
    )


Point = tuple[float, float]


def sense_lists(
    names: list[str], xy: np.ndarray, echoes: list[Point], human_id: str, config: SensingConfig
) -> tuple[list[list[float]], list[Point], list[float] | None, int]:
    """``sense_many`` in plain floats (what a pilot step runs): the beacons ``names`` at ``xy`` (k, 2), the
    echo points; returns the neighbours, the obstacle points, the human (or None) and how many echoes a
    beacon explained."""
    rows = xy.tolist()
    at = names.index(human_id) if human_id in names else None
    human = None if at is None else rows[at]
    neighbours = rows if at is None else rows[:at] + rows[at + 1 :]
    obstacles = echoes
    if echoes and rows:
        # an echo within a beacon's body (its radius plus the slack) came off it
        radius = config.robot_radius_m + config.echo_match_m
        person = config.person_radius_m + config.echo_match_m
        reaches = [person if j == at else radius for j in range(len(rows))]
        obstacles = [p for p in echoes if not _explained(p, rows, reaches)]
    dropped = len(echoes) - len(obstacles)
    if at is not None:
        obstacles = [*obstacles, _surface_toward_me(xy[at], config.person_radius_m)]
    return neighbours, obstacles, human, dropped


def explained_echoes(
    points: list[Point], names: list[str], xy: np.ndarray, human_id: str, config: SensingConfig
) -> list[bool]:
    """Per echo point (nan for a cone without echo: False), whether a tracked beacon's body explains it, as
    ``sense_lists`` decides when it drops echoes (the improved law's echo memory keeps only the others)."""
    rows = xy.tolist()
    radius = config.robot_radius_m + config.echo_match_m
    person = config.person_radius_m + config.echo_match_m
    reaches = [person if name == human_id else radius for name in names]
    return [bool(rows) and math.isfinite(p[0]) and _explained(p, rows, reaches) for p in points]


def _explained(point: Point, centres: list[list[float]], reaches: list[float]) -> bool:
    """Whether ``point`` lies within one of the bodies (centre and reach)."""
    x, y = point
    for (cx, cy), reach in zip(centres, reaches, strict=True):
        gx, gy = x - cx, y - cy
        # a body further off along x or y than its reach is out, without the root: in floating point too,
        # sqrt(gx*gx + gy*gy) >= |gx| (sqrt of a rounded square is exact, rounding and sqrt are monotonic)
        if gx > reach or -gx > reach or gy > reach or -gy > reach:
            continue
        if math.sqrt(gx * gx + gy * gy) <= reach:
            return True
    return False


def _surface_toward_me(centre: np.ndarray, radius: float) -> Point:
    """The point of a disc's surface nearest the robot; a centre estimated inside the disc's radius (the robot
    pressed against him, or a short estimate) puts it a hair in front of the robot, pushing straight away."""
    distance = math.sqrt(float(centre.dot(centre)))  # numpy's dot, as ever: its rounding is the record's
    if distance <= 1e-9:
        return (0.0, 0.0)
    reach = max(distance - radius, 0.01)
    x, y = centre.tolist()
    scale = reach / distance
    return (x * scale, y * scale)


@dataclass(frozen=True)
class SensedAll:
    """``sense_lists`` of many robots as padded arrays, for ``SurroundController.step_all``: per robot (row) its
    neighbours first, then its obstacle points (echoes no beacon explains, in ring order, then the human's body),
    left-aligned in ``terms`` (n, t, 2) with zeros after."""

    terms: np.ndarray
    neighbours: np.ndarray
    """How many of a row's terms are neighbours (n,)."""
    count: np.ndarray
    """How many of a row's terms there are (n,)."""
    human: np.ndarray
    """The human's centre (n, 2), zeros where unseen."""
    human_seen: np.ndarray
    dropped: list[int]


def sense_all(
    trackers: list[BeaconTracker],
    ranges: np.ndarray,
    ring: np.ndarray,
    human_id: str,
    config: SensingConfig,
) -> SensedAll:
    """``echo_list`` then ``sense_lists`` of many robots at once, bit for bit as each alone (the same elementwise
    operations in the same order; an echo is explained by any body, so the order of that test is free):
    ``trackers`` their tracked beacons, ``ranges`` (n, s) their rings' ranges (nan: no echo), ``ring`` (2, n, s)
    the cosines and sines of their sensors' angles (as ``echo_list`` is given them)."""
    n = len(trackers)
    reach = config.robot_radius_m + ranges
    echoes = np.stack([ring[0] * reach, ring[1] * reach], axis=-1)  # (n, s, 2)
    finite = np.isfinite(ranges)
    counts = [len(t._names) for t in trackers]
    human_row = [t._names.index(human_id) if human_id in t._rows else -1 for t in trackers]  # as sense_lists
    seen = np.array(human_row) >= 0
    neighbours = np.array(counts, dtype=np.intp) - seen
    explained = np.zeros(ranges.shape, dtype=bool)
    human = np.zeros((n, 2))
    bodies = None
    if sum(counts):
        bodies = _Bodies(trackers, counts, human_row)
        explained = bodies.explained(echoes, config)
    kept = finite & ~explained
    count = neighbours + np.add.reduce(kept, axis=1) + seen
    terms = np.zeros((n, int(count.max(initial=0)), 2))
    if bodies is not None:
        bodies.fill(terms, human, count, config.person_radius_m)
    rows, sensors = np.nonzero(kept)
    slots = neighbours[rows] + np.cumsum(kept, axis=1)[rows, sensors] - 1
    terms[rows, slots] = echoes[rows, sensors]
    dropped = np.add.reduce(finite & explained, axis=1).tolist()
    return SensedAll(terms, neighbours, count, human, seen, dropped)


class _Bodies:
    """Every robot's tracked beacons, stacked (one row per beacon, robot by robot): ``sense_all``'s view."""

    def __init__(self, trackers: list[BeaconTracker], counts: list[int], human_row: list[int]) -> None:
        self.owner = np.repeat(np.arange(len(trackers)), counts)
        self.centres = np.concatenate([t._position for t in trackers if t._names])
        start = np.cumsum([0, *counts[:-1]])
        self.start = start
        self.local = np.arange(len(self.owner)) - start[self.owner]
        row_of = np.array(human_row)[self.owner]
        self.person = self.local == row_of  # the first row of the human's name, as names.index finds it
        self.after_person = (row_of >= 0) & (self.local > row_of)
        self.holders = [i for i, c in enumerate(counts) if c]

    def explained(self, echoes: np.ndarray, config: SensingConfig) -> np.ndarray:
        """Per robot and echo (n, s), whether one of its tracked bodies explains the echo (``_explained``)."""
        owner, centres = self.owner, self.centres
        body = np.where(
            self.person, config.person_radius_m + config.echo_match_m, config.robot_radius_m + config.echo_match_m
        )
        gx = echoes[owner, :, 0] - centres[:, 0:1]
        gy = echoes[owner, :, 1] - centres[:, 1:2]
        inside = np.sqrt(gx * gx + gy * gy) <= body[:, None]  # (rows, s); nan (no echo) is never inside
        explained = np.zeros(echoes.shape[:2], dtype=bool)
        explained[self.holders] = np.logical_or.reduceat(inside, self.start[self.holders], axis=0)
        return explained

    def fill(self, terms: np.ndarray, human: np.ndarray, count: np.ndarray, person_radius_m: float) -> None:
        """Put each robot's neighbours first in its row of ``terms``, in its tracker's order, and its human's
        centre in ``human`` and his body's surface (``_surface_toward_me``) last in its row."""
        others = ~self.person
        terms[self.owner[others], (self.local - self.after_person)[others]] = self.centres[others]
        if not self.person.any():
            return
        holders = self.owner[self.person]
        centres = self.centres[self.person]
        human[holders] = centres
        # numpy's dot of each centre alone, as _surface_toward_me takes it: its rounding is the record's
        distance = np.sqrt(np.array([centre.dot(centre) for centre in centres]))
        near = distance <= 1e-9
        reach = np.maximum(distance - person_radius_m, 0.01)
        scale = reach / np.where(near, 1.0, distance)
        surface = np.where(near[:, None], 0.0, centres * scale[:, None])
        terms[holders, count[holders] - 1] = surface
