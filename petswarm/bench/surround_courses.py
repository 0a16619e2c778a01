"""Generated surround courses: a world, a walk and a swarm, drawn only from ``(set seed, course index)``.

A course is a scenario file's tables (``petswarm.scenario.parse`` takes it; ``petswarm run FILE --clock model``
runs it once written with ``petswarm.explore.toml_out.dumps``), built from the exploration's world pieces
(``petswarm.explore.generate``: its generator per case, its walls and circles). Pure: course 17 of a set is the
same whether 16 was drawn first, on another worker, or alone.

What a course holds (the ranges are the surround law's generalisation target, docs/SURROUND.md):
- 10-30 robots on a jittered square lattice (0.6-0.8 m) centred on the human, none within 0.5 m of him;
- one obstacle feature 3-3.5 m ahead of where his approach starts: a corridor 1.0-2.0 m wide and 2-6 m long
  (straight, or bent by 20-45 degrees part way: a turn inside), a cylinder of radius 0.4-1.5 m beside his path,
  a pair of cylinders with a gap of 1.2-2.0 m he walks through, or a row of three or four across his path with
  gaps of 1.2-1.8 m;
- his walk: standing ``WALK_AT_S``, speeding up in four steps to a top speed of 0.5-1.2 m/s, sometimes a turn of
  20-60 degrees before the feature, sometimes a stop of 1-2.5 s inside it, walking ``EXIT_M`` past it and standing
  ``END_STAND_S`` (r at the end is measured over his last second there);
- the run's own seed (IR noise and every other random draw of the run), drawn last.

r* for each robot count comes from the paper's pure simulation (``surround_sim``: local forces alone, the mean of
the 0.8 m and 0.2 m lattices' settled extents): ``R_STAR_M``, reproduced by ``r_star``.

The split (fixed, never changed after tuning started): ``TRAINING_SET`` courses are the only ones any law's
parameters were tuned on; ``TEST_SET`` courses are for reporting only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from petswarm.explore.generate import circle_obstacle, wall_obstacle

TRAINING_SET = 1
"""The set seed of the training courses: the only courses a law was tuned on."""
TEST_SET = 2
"""The set seed of the test courses: reported on, never used to choose anything."""
KINDS = ("corridor", "cylinder", "pair", "row")
"""The obstacle features a course draws from (equally likely)."""
WALK_AT_S = 3.0
"""The human stands this long first: the swarm gathers round him."""
EXIT_M = 1.5
"""He walks this far past the feature's far edge before he stops."""
END_STAND_S = 5.0
"""He stands this long at the end (the swarm settles; r at the end is its mean over the last second)."""
RAMP_SHARES = (0.2, 0.4, 0.6, 0.8)
"""He speeds up to his top speed through these shares of it, 0.75 s each (as the paper's scenario files do)."""
RAMP_STEP_S = 0.75
START_CLEAR_M = 0.4
"""Every robot's start is at least this clear of every obstacle surface (else the feature moves further on)."""

R_STAR_M = {
    10: 0.4858,
    11: 0.4991,
    12: 0.5299,
    13: 0.5449,
    14: 0.5698,
    15: 0.5819,
    16: 0.5761,
    17: 0.6049,
    18: 0.6325,
    19: 0.6457,
    20: 0.6523,
    21: 0.6682,
    22: 0.6704,
    23: 0.6935,
    24: 0.7101,
    25: 0.7207,
    26: 0.7295,
    27: 0.7458,
    28: 0.7722,
    29: 0.7779,
    30: 0.7962,
}
"""r* (m) per robot count: ``r_star(n)`` for n = 10..30 (the paper's law at the shipped gains, seed 1)."""


def r_star(robots: int, seed: int = 1) -> float:
    """The extent ``robots`` robots settle to under the paper's local forces alone (pure simulation, exact
    sensing): the mean over the last 3 s of 15 s from the paper's two lattices (0.8 m and 0.2 m)."""
    from petswarm.bench.surround_sim import SETTLE_S, free, simulate
    from petswarm.controllers.surround import SurroundConfig

    config = SurroundConfig()
    settled = [
        simulate(config, free(spacing, robots), seed, SETTLE_S).mean_r(SETTLE_S - 3.0, SETTLE_S + 1.0)
        for spacing in (0.8, 0.2)
    ]
    return round(float(np.mean(settled)), 4)


def course_rng(set_seed: int, i: int) -> np.random.Generator:
    """Course ``i`` of set ``set_seed``'s own generator (never a shared stream)."""
    return np.random.default_rng([int(set_seed), int(i), 0x5A7])


@dataclass
class _Walker:
    """The human's pose as his path is built, so features can be placed along his heading."""

    x: float = 0.0
    y: float = 0.0
    heading: float = 0.0
    legs: list[dict[str, Any]] | None = None
    moving: bool = False

    def __post_init__(self) -> None:
        self.legs = []

    def walk(self, distance: float, speed: float) -> None:
        """Walk ``distance`` at ``speed``, speeding up from a standstill first (``RAMP_SHARES``)."""
        assert self.legs is not None
        if not self.moving:
            for share in RAMP_SHARES:
                step = round(share * speed * RAMP_STEP_S, 3)
                self.legs.append({"walk": step, "speed": round(share * speed, 3)})
                distance -= step
                self._advance(step)
            self.moving = True
        distance = round(max(distance, 0.1), 3)
        self.legs.append({"walk": distance, "speed": round(speed, 3)})
        self._advance(distance)

    def turn(self, degrees: float, rate: float) -> None:
        """Turn on the spot (he stops to turn)."""
        assert self.legs is not None
        self.legs.append({"turn": round(degrees, 1), "rate": round(rate, 1)})
        self.heading += math.radians(round(degrees, 1))
        self.moving = False

    def stop(self, seconds: float) -> None:
        """Stand ``seconds``."""
        assert self.legs is not None
        self.legs.append({"stop": round(seconds, 2)})
        self.moving = False

    def _advance(self, distance: float) -> None:
        self.x += distance * math.cos(self.heading)
        self.y += distance * math.sin(self.heading)

    def seconds(self) -> float:
        """How long the path takes."""
        assert self.legs is not None
        total = 0.0
        for leg in self.legs:
            if "walk" in leg:
                total += leg["walk"] / leg["speed"]
            elif "turn" in leg:
                total += abs(leg["turn"]) / leg["rate"]
            else:
                total += leg["stop"]
        return total


def course(set_seed: int, i: int) -> dict[str, Any]:
    """Course ``i`` of set ``set_seed`` as a scenario file's tables, plus ``course`` (what was drawn: kind, sizes,
    top speed, turns, stop, robots, r*) and ``run_seed`` (the seed to run it with)."""
    rng = course_rng(set_seed, i)
    kind = str(rng.choice(KINDS))
    robots = int(rng.integers(10, 31))
    speed = round(float(rng.uniform(0.5, 1.2)), 2)
    turn_before = float(rng.choice([-1, 1]) * rng.uniform(20, 60)) if rng.random() < 0.3 else 0.0
    stop_inside = round(float(rng.uniform(1.0, 2.5)), 2) if rng.random() < 0.3 else 0.0
    approach = float(rng.uniform(3.0, 3.5))
    spacing = float(rng.uniform(0.6, 0.8))
    positions = _lattice(rng, robots, spacing)
    feature = _feature(rng, kind)
    drawn: dict[str, Any] = {
        "kind": kind,
        "robots": robots,
        "top_speed_mps": speed,
        "turn_before_deg": round(turn_before, 1),
        "stop_inside_s": stop_inside,
        "spacing_m": round(spacing, 3),
        **{k: v for k, v in feature.items() if k != "build"},
        "r_star_m": R_STAR_M[robots],
    }
    while True:  # the feature moves on until every robot starts clear of it (a turn may swing it toward them)
        walker = _Walker()
        if turn_before:
            walker.walk(1.2, speed)
            walker.turn(turn_before, 90.0)
        obstacles, inside, length = feature["build"](walker, approach)
        if _clear(positions, obstacles):
            break
        approach += 0.5
    _walk_through(walker, speed, approach, inside, length, stop_inside, feature.get("bend_deg", 0.0))
    walker.stop(END_STAND_S)
    drawn["approach_m"] = round(approach, 2)
    duration = round(WALK_AT_S + walker.seconds(), 2)
    return {
        "name": f"course-{set_seed}-{i}-{kind}",
        "description": f"surround course {i} of set {set_seed} ({kind}, {robots} robots, {speed} m/s)",
        "duration_s": duration,
        "hub": {"world": {"robot_radius_m": 0.1}},
        "surround": {"enabled": True},
        "obstacles": obstacles,
        "user": {"start": [0.0, 0.0, 0.0], "walk_at": WALK_AT_S, "path": walker.legs},
        "robots": {"count": robots, "positions": positions},
        "course": drawn,
        "run_seed": int(rng.integers(1, 2**31 - 1)),
    }


def scenario_tables(data: dict[str, Any]) -> dict[str, Any]:
    """A course's scenario tables alone (what ``petswarm.scenario.parse`` takes): ``course`` and ``run_seed`` off."""
    return {k: v for k, v in data.items() if k not in ("course", "run_seed")}


def _lattice(rng: np.random.Generator, robots: int, spacing: float) -> list[list[float]]:
    """``robots`` starts on a square lattice of ``spacing`` round the human (at the origin), the nearest to him first
    but none within 0.5 m of him, each jittered by up to 0.1 m, headings anywhere."""
    side = math.ceil(math.sqrt(robots + 1)) + 2
    offsets = (np.arange(side) - (side - 1) / 2) * spacing
    grid = [(float(x), float(y)) for y in offsets for x in offsets if math.hypot(x, y) >= 0.5]
    grid.sort(key=lambda p: (round(math.hypot(*p), 6), p[1], p[0]))
    out = []
    for x, y in grid[:robots]:
        jx, jy = rng.uniform(-0.1, 0.1, 2)
        out.append([round(x + float(jx), 3), round(y + float(jy), 3), round(float(rng.uniform(-180, 180)), 1)])
    return out


def _feature(rng: np.random.Generator, kind: str) -> dict[str, Any]:
    """The feature's sizes, drawn now (the same draws whatever the placement), and how to build it."""
    if kind == "corridor":
        width, length = float(rng.uniform(1.0, 2.0)), float(rng.uniform(2.0, 6.0))
        bend = float(rng.choice([-1, 1]) * rng.uniform(20, 45)) if rng.random() < 0.3 else 0.0
        at = float(rng.uniform(0.4, 0.6))

        def build(w: _Walker, approach: float) -> tuple[list[dict[str, Any]], float, float]:
            return _corridor(w, approach, width, length, bend, at), approach + at * length, length

        return {"width_m": round(width, 3), "length_m": round(length, 3), "bend_deg": round(bend, 1), "build": build}
    if kind == "cylinder":
        radius, clear = float(rng.uniform(0.4, 1.5)), float(rng.uniform(0.3, 0.9))
        side = 1.0 if rng.random() < 0.5 else -1.0

        def build(w: _Walker, approach: float) -> tuple[list[dict[str, Any]], float, float]:
            x, y = _ahead(w, approach + radius, side * (radius + clear))
            return [circle_obstacle(x, y, radius)], approach + radius, 2 * radius

        return {"radius_m": round(radius, 3), "clear_m": round(clear, 3), "build": build}
    if kind == "pair":
        radii = rng.uniform(0.3, 1.0, 2)
        gap = float(rng.uniform(1.2, 2.0))
        shift = float(rng.uniform(-0.1, 0.1)) * (gap - 1.2)

        def build(w: _Walker, approach: float) -> tuple[list[dict[str, Any]], float, float]:
            r = float(radii.max())
            left = _ahead(w, approach + r, shift + gap / 2 + float(radii[0]))
            right = _ahead(w, approach + r, shift - gap / 2 - float(radii[1]))
            return (
                [circle_obstacle(*left, float(radii[0])), circle_obstacle(*right, float(radii[1]))],
                approach + r,
                2 * r,
            )

        return {"radii_m": [round(float(r), 3) for r in radii], "gap_m": round(gap, 3), "build": build}
    count = int(rng.integers(3, 5))
    radii = rng.uniform(0.2, 0.5, count)
    gaps = rng.uniform(1.2, 1.8, count - 1)
    through = int(rng.integers(0, count - 1))

    def build_row(w: _Walker, approach: float) -> tuple[list[dict[str, Any]], float, float]:
        # across his path, his path through the middle of gap ``through``
        across = [0.0]
        for k in range(1, count):
            across.append(across[-1] + float(radii[k - 1] + gaps[k - 1] + radii[k]))
        middle = (across[through] + float(radii[through]) + across[through + 1] - float(radii[through + 1])) / 2
        r = float(radii.max())
        out = [
            circle_obstacle(*_ahead(w, approach + r, middle - a), float(rk))
            for a, rk in zip(across, radii, strict=True)
        ]
        return out, approach + r, 2 * r

    return {
        "radii_m": [round(float(r), 3) for r in radii],
        "gaps_m": [round(float(g), 3) for g in gaps],
        "build": build_row,
    }


def _ahead(w: _Walker, along: float, left: float) -> tuple[float, float]:
    """The point ``along`` ahead of the walker and ``left`` to his left."""
    c, s = math.cos(w.heading), math.sin(w.heading)
    return w.x + along * c - left * s, w.y + along * s + left * c


def _corridor(w: _Walker, approach: float, width: float, length: float, bend: float, at: float) -> list[dict[str, Any]]:
    """Two walls ``width`` apart along his heading from ``approach`` ahead, ``length`` long; bent by ``bend`` degrees
    at ``at`` of its length (each wall's two pieces meet on the bisector of the bend)."""
    half = width / 2
    if not bend:
        return [
            wall_obstacle(*_ahead(w, approach, side * half), *_ahead(w, approach + length, side * half))
            for side in (1, -1)
        ]
    first = at * length
    turn = math.radians(bend)
    out = []
    for side in (1, -1):
        start = _ahead(w, approach, side * half)
        # the corner of the offset lines: on the bisector, half / cos(bend / 2) from the centreline's joint
        joint = _ahead(w, approach + first, 0.0)
        normal = w.heading + math.pi / 2 + turn / 2
        reach = side * half / math.cos(turn / 2)
        corner = (joint[0] + reach * math.cos(normal), joint[1] + reach * math.sin(normal))
        second = w.heading + turn
        rest = length - first
        end_centre = (joint[0] + rest * math.cos(second), joint[1] + rest * math.sin(second))
        end = (
            end_centre[0] - side * half * math.sin(second),
            end_centre[1] + side * half * math.cos(second),
        )
        out += [wall_obstacle(*start, *corner), wall_obstacle(*corner, *end)]
    return out


def _walk_through(
    w: _Walker, speed: float, approach: float, inside: float, length: float, stop: float, bend: float
) -> None:
    """His walk from the approach's start: to the feature, through it (a stop of ``stop`` s at ``inside``, a turn by
    ``bend`` degrees there for a bent corridor), and ``EXIT_M`` past its far edge."""
    if bend:
        w.walk(inside, speed)
        if stop:
            w.stop(stop)
        w.turn(bend, 90.0)
        w.walk(approach + length - inside + EXIT_M, speed)
        return
    if stop:
        w.walk(inside, speed)
        w.stop(stop)
        w.walk(approach + length - inside + EXIT_M, speed)
        return
    w.walk(approach + length + EXIT_M, speed)


def _clear(positions: list[list[float]], obstacles: list[dict[str, Any]]) -> bool:
    """Whether every start is ``START_CLEAR_M`` clear of every obstacle's surface (and the human's too)."""
    points = np.array([[x, y] for x, y, _ in positions] + [[0.0, 0.0]])
    for o in obstacles:
        if o["kind"] == "circle":
            d = np.hypot(points[:, 0] - o["x"], points[:, 1] - o["y"]) - o["r"]
        else:
            a, b = np.array([o["x0"], o["y0"]]), np.array([o["x1"], o["y1"]])
            ab = b - a
            t = np.clip((points - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
            d = np.hypot(*(points - (a + t[:, None] * ab)).T)
        if float(d.min()) < START_CLEAR_M:
            return False
    return True
