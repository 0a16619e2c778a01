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

from dataclasses import dataclass

import numpy as np

from petswarm.ir_estimator import estimate_many
from radio_hub.light import PERSON_BEACON_POWER, IrConfig


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
    gains = gains or {}
    groups: dict[float, list[str]] = {}
    for name in beacons:
        power = (PERSON_BEACON_POWER if name == person else 1.0) * gains.get(name, 1.0)
        groups.setdefault(power, []).append(name)
    points: dict[str, np.ndarray] = {}
    for power, group in groups.items():
        config = ir if power == 1.0 else ir.brighter(power)
        readings = np.stack([np.asarray(beacons[n], dtype=float) for n in group])
        found = estimate_many(readings, config, method)
        xy = np.stack([np.cos(found.bearing_rad), np.sin(found.bearing_rad)], axis=1) * found.distance_m[:, None]
        points.update({n: xy[i] for i, n in enumerate(group) if found.valid[i]})
    return points


TRACK_ALPHA = 0.5
"""The alpha-beta tracker's position gain: each sweep's fix moves the track half way (IR noise ~1-2 cm at 1 m)."""
TRACK_BETA = 0.17
"""Its velocity gain, alpha^2 / (2 - alpha): Benedict and Bordner's choice for that alpha (less lag on a
manoeuvring target than the critically damped 0.09, which a swarm pushing and braking is)."""


class BeaconTracker:
    """Each beacon's position and velocity in the robot's frame, between and across 20 Hz sweeps.

    Why: stepping at 25 Hz on 20 Hz sweeps, a tracker that takes beacons to stand still between sweeps sees
    a neighbour driving beside it at v fall back by v x 40 ms and jump ahead at the next sweep; the law
    differences that sawtooth into a centroid rate of +-v, which the damping B = 6.4 turns into +-6 m/s^2,
    more than the acceleration limit: the clipped noise swamped the surround force, and in a model-time run
    of the cylinder scenario the swarm ended 8 m behind its human (1.6 m with this tracker). Here each beacon
    keeps a velocity of its own (an alpha-beta filter on its fixes, in the robot's non-turning frame), so a
    neighbour driving along stays put relative to us.
    """

    def __init__(self, alpha: float = TRACK_ALPHA, beta: float = TRACK_BETA) -> None:
        if not 0 < alpha <= 1 or not 0 <= beta < 2:
            raise ValueError(f"alpha must be in (0, 1] and beta in [0, 2), not {alpha}, {beta}")
        self.alpha, self.beta = alpha, beta
        self._position: dict[str, np.ndarray] = {}
        self._velocity: dict[str, np.ndarray] = {}
        """Each beacon's own velocity (not relative to us), in our frame."""
        self._since_fix = 0.0

    @property
    def points(self) -> dict[str, np.ndarray]:
        """The tracked beacons' positions now, in the robot's frame."""
        return dict(self._position)

    def predict(self, own_velocity: np.ndarray, dt: float) -> None:
        """Move every track ``dt`` seconds on: it drives at its velocity, we at ``own_velocity`` (odometry)."""
        if not dt >= 0:
            raise ValueError(f"dt must be >= 0, not {dt!r}")
        own = np.asarray(own_velocity, dtype=float)
        for name, velocity in self._velocity.items():
            self._position[name] = self._position[name] + (velocity - own) * dt
        self._since_fix += dt

    def update(self, fixes: dict[str, np.ndarray], own_velocity: np.ndarray) -> None:
        """A sweep's fixes: tracks of beacons in it are corrected, new ones start at rest relative to us, and
        beacons missing from it are dropped (out of sight)."""
        own = np.asarray(own_velocity, dtype=float)
        period = self._since_fix
        self._since_fix = 0.0
        for name in list(self._position):
            if name not in fixes:
                del self._position[name], self._velocity[name]
        for name, fix in fixes.items():
            fix = np.asarray(fix, dtype=float)
            if name not in self._position or period <= 0:
                self._position[name], self._velocity[name] = fix, own.copy()
                continue
            innovation = fix - self._position[name]
            self._position[name] = self._position[name] + self.alpha * innovation
            self._velocity[name] = self._velocity[name] + self.beta * innovation / period

    def clear(self) -> None:
        """Forget every beacon (the sweeps stopped)."""
        self._position.clear()
        self._velocity.clear()


def echo_points(ranges_m: np.ndarray, angles_rad: np.ndarray, robot_radius_m: float) -> np.ndarray:
    """The points (m, 2) the echoes came from, from the robot's centre; sensors without an echo (nan) give none."""
    ranges = np.asarray(ranges_m, dtype=float)
    angles = np.asarray(angles_rad, dtype=float)
    if ranges.shape != angles.shape:
        raise ValueError(f"ranges_m {ranges.shape} and angles_rad {angles.shape} must match")
    heard = np.isfinite(ranges)
    reach = robot_radius_m + ranges[heard]
    return np.stack([np.cos(angles[heard]), np.sin(angles[heard])], axis=1) * reach[:, None]


def sense(
    beacon_xy: dict[str, np.ndarray],
    echoes: np.ndarray,
    human_id: str,
    config: SensingConfig,
) -> SurroundSensing:
    """Sort beacons into neighbours and the human, add the human's body to the obstacles, and drop the echoes
    that a beacon explains."""
    human = beacon_xy.get(human_id)
    others = [np.asarray(p, dtype=float) for n, p in beacon_xy.items() if n != human_id]
    neighbours = np.array(others, dtype=float).reshape(-1, 2)
    echoes = np.asarray(echoes, dtype=float).reshape(-1, 2)
    bodies = [(p, config.robot_radius_m) for p in neighbours]
    if human is not None:
        bodies.append((np.asarray(human, dtype=float), config.person_radius_m))
    explained = np.zeros(len(echoes), dtype=bool)
    for centre, radius in bodies:
        explained |= np.linalg.norm(echoes - centre, axis=1) <= radius + config.echo_match_m
    obstacles = [echoes[~explained]]
    if human is not None:
        obstacles.append(_surface_toward_me(np.asarray(human, dtype=float), config.person_radius_m)[None])
    return SurroundSensing(neighbours, np.concatenate(obstacles), human, int(explained.sum()))


def _surface_toward_me(centre: np.ndarray, radius: float) -> np.ndarray:
    """The point of a disc's surface nearest the robot; a centre estimated inside the disc's radius (the robot
    pressed against him, or a short estimate) puts it a hair in front of the robot, pushing straight away."""
    distance = float(np.linalg.norm(centre))
    if distance <= 1e-9:
        return np.zeros(2)
    reach = max(distance - radius, 0.01)
    return centre * (reach / distance)
