"""A pure simulation of the surround formation: N robots, obstacles and a walking human, all in numpy.

Each robot runs the surround law (``petswarm.controllers.surround``) in its own frame on what it would sense: the
robots within its sight (centre positions, as coded IR beacons give them), the nearest surface point of
every obstacle and of the human's body within the avoidance range (as ultrasonic gives it), and the
human's position. Truth, or truth with Gaussian distance and bearing noise. Robots keep a fixed heading
drawn per robot from the seed (so frames really differ) and move holonomically within the speed and
acceleration limits. Occlusion is not modelled: a robot sees every neighbour within S.

Used by the unit tests and by ``surround_figures`` (the paper's setups, for ``petswarm bench surround --paper``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from petswarm.controllers.surround import Obstacles, SurroundConfig, SurroundLaw, connected, extent

DISTANCE_SIGMA_M = 0.03
BEARING_SIGMA_RAD = math.radians(3.0)
SETTLE_S = 15.0
"""Local forces alone: long enough for both lattices to settle (the 0.8 m one is the slower)."""


@dataclass(frozen=True)
class HumanWalk:
    """The human stands, then speeds up at a constant rate to ``speed_mps`` and walks on in a straight line.

    ``radius_m`` 0.2: a person seen from above (shoulders ~0.45 m, legs narrower), the body the robots
    must keep clear of. Standing ``start_s`` lets the swarm gather round him first.
    """

    start: tuple[float, float] = (0.0, 0.0)
    heading_rad: float = 0.0
    start_s: float = 2.0
    ramp_s: float = 3.0
    speed_mps: float = 1.0
    radius_m: float = 0.2

    def travelled(self, t: float) -> float:
        """Distance walked by time ``t``."""
        moving = max(0.0, t - self.start_s)
        ramp = min(moving, self.ramp_s)
        return 0.5 * self.speed_mps * ramp**2 / self.ramp_s + self.speed_mps * (moving - ramp)

    def time_at(self, distance: float) -> float:
        """When the human has walked ``distance``."""
        ramp_distance = 0.5 * self.speed_mps * self.ramp_s
        if distance <= ramp_distance:
            return self.start_s + math.sqrt(2 * distance * self.ramp_s / self.speed_mps)
        return self.start_s + self.ramp_s + (distance - ramp_distance) / self.speed_mps

    def position(self, t: float) -> np.ndarray:
        """Where the human is at ``t``."""
        s = self.travelled(t)
        return np.array(self.start) + s * np.array([math.cos(self.heading_rad), math.sin(self.heading_rad)])


@dataclass(frozen=True)
class Scenario:
    """What a run starts from and moves through. ``span_x`` is where the obstacle lies along the human's path
    (x from, x to), to split the extent into before and after."""

    name: str
    robots: int = 20
    spacing_m: float = 0.8
    centre: tuple[float, float] = (0.0, 0.0)
    obstacles: Obstacles = field(default_factory=Obstacles)
    human: HumanWalk | None = None
    span_x: tuple[float, float] | None = None
    noisy: bool = False

    def __post_init__(self) -> None:
        if self.robots < 1:
            raise ValueError(f"robots must be >= 1, not {self.robots}")
        if not self.spacing_m > 0:
            raise ValueError(f"spacing_m must be > 0, not {self.spacing_m}")


def free(spacing_m: float, robots: int = 20) -> Scenario:
    """Local forces alone: no human, no obstacles (the paper's convergence test)."""
    return Scenario(f"free-{spacing_m:g}", robots, spacing_m)


def corridor(
    width_m: float = 1.2,
    length_m: float = 3.0,
    entry_x: float = 4.0,
    depth_m: float = 0.0,
    chamfer_m: float = 0.0,
    robots: int = 20,
) -> Scenario:
    """A straight corridor along the human's path; the swarm gathers round him 4 m before it.

    ``depth_m`` 0: two thin walls (robots may pass outside them); above 0: the walls are the inner faces of
    solid blocks that deep, with the mouth's corners bevelled ``chamfer_m`` at 45 degrees.
    """
    half = width_m / 2
    x0, x1 = entry_x, entry_x + length_m
    if depth_m > 0:
        left = [(x0, half + depth_m), (x0, half + chamfer_m), (x0 + chamfer_m, half), (x1, half), (x1, half + depth_m)]
        segments = np.concatenate([polygon(left), polygon([(x, -y) for x, y in left])])
    else:
        segments = np.array([[x0, half, x1, half], [x0, -half, x1, -half]])
    return Scenario(
        f"corridor-{width_m:g}" + (f"-solid-{depth_m:g}" if depth_m > 0 else ""),
        robots,
        0.8,
        obstacles=Obstacles(segments=segments),
        human=HumanWalk(),
        span_x=(x0, x1),
    )


def polygon(corners: list[tuple[float, float]]) -> np.ndarray:
    """The sides (k, 4) of a closed polygon, as segments (repeated corners give no side)."""
    a = np.array(corners, dtype=float)
    sides = np.concatenate([a, np.roll(a, -1, axis=0)], axis=1)
    return sides[np.any(sides[:, :2] != sides[:, 2:], axis=1)]


def cylinder(radius_m: float = 1.0, offset_m: float = 1.6, at_x: float = 5.0, robots: int = 20) -> Scenario:
    """A cylinder beside the human's path: its axis ``offset_m`` to his left, so it cuts into the swarm and
    leaves a 0.4 m gap between his body and it (a robot fits, a pair abreast does not)."""
    return Scenario(
        f"cylinder-{radius_m:g}",
        robots,
        0.8,
        obstacles=Obstacles(circles=np.array([[at_x, offset_m, radius_m]])),
        human=HumanWalk(),
        span_x=(at_x - radius_m, at_x + radius_m),
    )


def lattice(n: int, spacing: float, centre: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """``n`` positions (n, 2) on a square lattice as near square as n allows, row by row, centred on ``centre``."""
    if n < 1:
        raise ValueError(f"n must be >= 1, not {n}")
    if not spacing > 0:
        raise ValueError(f"spacing must be > 0, not {spacing}")
    cols = math.ceil(math.sqrt(n))
    rows = math.ceil(n / cols)
    index = np.arange(n)
    grid = np.stack([index % cols - (cols - 1) / 2, index // cols - (rows - 1) / 2], axis=1) * spacing
    return grid + np.asarray(centre, dtype=float)


@dataclass(frozen=True)
class SurroundRun:
    """Time series of one run, one entry per step (after the step's motion).

    Contact counts are overlapping pairs at that instant; a run without collisions has them all zero.
    Clearances are gaps between bodies' surfaces (negative = overlap); inf where there is nothing.
    """

    scenario: Scenario
    t: np.ndarray
    r: np.ndarray
    connected: np.ndarray
    min_separation: np.ndarray
    """Smallest robot-robot centre distance (m)."""
    obstacle_clearance: np.ndarray
    human_clearance: np.ndarray
    robot_robot: np.ndarray
    robot_obstacle: np.ndarray
    robot_human: np.ndarray
    human: np.ndarray
    """(T, 2), NaN without a human."""
    positions: np.ndarray
    """The robots' final positions (n, 2)."""

    @property
    def collisions(self) -> int:
        """Pair-steps in contact, all kinds: zero means no body ever touched another."""
        return int(self.robot_robot.sum() + self.robot_obstacle.sum() + self.robot_human.sum())

    def mean_r(self, start_s: float, end_s: float) -> float:
        """Mean extent over [start_s, end_s)."""
        window = (self.t >= start_s) & (self.t < end_s)
        if not window.any():
            raise ValueError(f"no samples in [{start_s}, {end_s})")
        return float(self.r[window].mean())


def simulate(config: SurroundConfig, scenario: Scenario, seed: int, duration: float) -> SurroundRun:
    """Run ``scenario`` for ``duration`` seconds at the config's dt; every random draw comes from ``seed``."""
    if not duration > 0:
        raise ValueError(f"duration must be > 0, not {duration}")
    rng = np.random.default_rng(seed)
    n = scenario.robots
    pos = lattice(n, scenario.spacing_m, scenario.centre)
    yaw = rng.uniform(-math.pi, math.pi, n)
    vel = np.zeros((n, 2))
    law = SurroundLaw(config, n)
    human = scenario.human
    human_body = Obstacles()
    steps = max(1, round(duration / config.dt_s))
    rows: list[tuple[float, ...]] = []
    track = np.full((steps, 2), np.nan)
    for k in range(steps):
        t = k * config.dt_s
        if human is not None:
            track[k] = human.position(t)
            human_body = Obstacles(circles=np.array([[*track[k], human.radius_m]]))
        command = _control(law, config, scenario, pos, vel, yaw, track[k] if human else None, human_body, rng)
        vel = _move(vel, command, config)
        pos = pos + vel * config.dt_s
        rows.append(_measure(t + config.dt_s, pos, config, scenario.obstacles, human_body))
    table = np.array(rows)
    return SurroundRun(
        scenario,
        t=table[:, 0],
        r=table[:, 1],
        connected=table[:, 2].astype(bool),
        min_separation=table[:, 3],
        obstacle_clearance=table[:, 4],
        human_clearance=table[:, 5],
        robot_robot=table[:, 6].astype(int),
        robot_obstacle=table[:, 7].astype(int),
        robot_human=table[:, 8].astype(int),
        human=track,
        positions=pos,
    )


def _control(
    law: SurroundLaw,
    config: SurroundConfig,
    scenario: Scenario,
    pos: np.ndarray,
    vel: np.ndarray,
    yaw: np.ndarray,
    human_xy: np.ndarray | None,
    human_body: Obstacles,
    rng: np.random.Generator,
) -> np.ndarray:
    """Each robot's sensing in its own frame, the law's step, and the commands back in the world frame."""
    n = len(pos)
    rel = pos[None, :, :] - pos[:, None, :]
    seen = ~np.eye(n, dtype=bool) & (np.linalg.norm(rel, axis=-1) <= config.sight_m)
    offsets, _ = scenario.obstacles.nearest(pos)
    human_offset, _ = human_body.nearest(pos)
    points = np.concatenate([offsets, human_offset], axis=1)
    points_seen = np.linalg.norm(points, axis=-1) <= config.avoidance_m
    human_rel = np.zeros((n, 2)) if human_xy is None else human_xy[None, :] - pos
    if scenario.noisy:
        rel, points, human_rel = (_noisy(a, rng) for a in (rel, points, human_rel))
    command = law.step(
        _to_body(rel, yaw),
        seen,
        _to_body(points, yaw),
        points_seen,
        _to_body(human_rel, yaw),
        np.full(n, human_xy is not None),
        _to_body(vel, yaw),
        config.dt_s,
    )
    return _to_body(command, -yaw)


def _move(vel: np.ndarray, command: np.ndarray, config: SurroundConfig) -> np.ndarray:
    """Holonomic base: the velocity goes toward the command within the acceleration and speed limits."""
    change = command - vel
    limit = config.max_accel_mps2 * config.dt_s
    change *= np.minimum(1.0, limit / np.maximum(np.linalg.norm(change, axis=1, keepdims=True), 1e-12))
    vel = vel + change
    speed = np.linalg.norm(vel, axis=1, keepdims=True)
    return vel * np.minimum(1.0, config.max_speed_mps / np.maximum(speed, 1e-12))


def _measure(
    t: float, pos: np.ndarray, config: SurroundConfig, obstacles: Obstacles, human_body: Obstacles
) -> tuple[float, ...]:
    radius = config.robot_radius_m
    d = np.linalg.norm(pos[:, None, :] - pos[None, :, :], axis=-1)
    np.fill_diagonal(d, np.inf)
    obstacle_gap = obstacles.nearest(pos)[1].min() - radius if obstacles.count else np.inf
    human_gap = human_body.nearest(pos)[1].min() - radius if human_body.count else np.inf
    return (
        t,
        extent(pos),
        float(connected(pos, config.sight_m)),
        float(d.min()) if len(pos) > 1 else np.inf,
        float(obstacle_gap),
        float(human_gap),
        float(np.sum(np.triu(d < 2 * radius, k=1))),
        float(np.sum(obstacles.nearest(pos)[1] < radius)) if obstacles.count else 0.0,
        float(np.sum(human_body.nearest(pos)[1] < radius)) if human_body.count else 0.0,
    )


def _to_body(world: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """World-frame vectors of each robot (leading axis) in that robot's frame (a rotation by -yaw)."""
    c, s = np.cos(yaw), np.sin(yaw)
    shape = (len(yaw),) + (1,) * (world.ndim - 2)
    c, s = c.reshape(shape), s.reshape(shape)
    x, y = world[..., 0], world[..., 1]
    return np.stack([c * x + s * y, -s * x + c * y], axis=-1)


def _noisy(points: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Points with Gaussian noise on their distance (3 cm) and bearing (3 degrees), as IR and ultrasonic read."""
    distance = np.linalg.norm(points, axis=-1)
    bearing = np.arctan2(points[..., 1], points[..., 0])
    distance = np.maximum(distance + rng.normal(0.0, DISTANCE_SIGMA_M, distance.shape), 0.0)
    bearing = bearing + rng.normal(0.0, BEARING_SIGMA_RAD, bearing.shape)
    return np.stack([distance * np.cos(bearing), distance * np.sin(bearing)], axis=-1)


def surround_figures(seed: int, config: SurroundConfig | None = None) -> dict[str, Any]:
    """The paper's setups and their figures, for ``petswarm bench surround --paper``.

    ``r_star``: the extent under local forces alone from the 0.8 m and the 0.2 m lattice. For each obstacle
    scenario (thin-walled corridor, solid-walled corridor, cylinder; each also with noisy sensing):
    contacts by kind, smallest gaps, connectivity, the extent before (2 s until the human is 1 m from the
    obstacle) and after (the last 2 s), and how far the swarm's centre trails the human at the end.
    """
    config = config or SurroundConfig()
    figures: dict[str, Any] = {"seed": seed, "config": config.to_dict(), "r_star": {}}
    for spacing in (0.8, 0.2):
        run = simulate(config, free(spacing), seed, SETTLE_S)
        figures["r_star"][f"{spacing:g}"] = round(run.mean_r(SETTLE_S - 3.0, SETTLE_S + 1.0), 4)
    scenarios = [corridor(), corridor(depth_m=3.0), cylinder()]
    scenarios += [replace(s, name=f"{s.name}-noisy", noisy=True) for s in scenarios]
    for scenario in scenarios:
        figures[scenario.name] = _obstacle_figures(simulate(config, scenario, seed, WALK_S))
    return figures


WALK_S = 16.0
"""An obstacle run: 2 s standing, 3 s speeding up, through the obstacle by ~11 s, then 5 s to recover."""


def _obstacle_figures(run: SurroundRun) -> dict[str, Any]:
    human, span = run.scenario.human, run.scenario.span_x
    if human is None or span is None:
        raise ValueError(f"scenario {run.scenario.name!r} has no human or no obstacle span to measure around")
    approach = human.time_at(span[0] - human.start[0] - 1.0)
    end = float(run.t[-1])
    return {
        "robot_robot_contacts": int(run.robot_robot.sum()),
        "robot_obstacle_contacts": int(run.robot_obstacle.sum()),
        "robot_human_contacts": int(run.robot_human.sum()),
        "min_separation_m": round(float(run.min_separation.min()), 4),
        "min_obstacle_gap_m": round(float(run.obstacle_clearance.min()), 4),
        "min_human_gap_m": round(float(run.human_clearance.min()), 4),
        "connected_fraction": round(float(run.connected.mean()), 4),
        "always_connected": bool(run.connected.all()),
        "r_before_m": round(run.mean_r(approach - 2.0, approach), 4),
        "r_after_m": round(run.mean_r(end - 2.0, end + 1.0), 4),
        "trailing_m": round(float(np.linalg.norm(run.positions.mean(axis=0) - run.human[-1])), 4),
    }
