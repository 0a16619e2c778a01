"""The improved surround law: beyond the paper, a swarm that keeps its human inside it while he walks.

The paper's law (``surround.SurroundController``) moves the swarm only through the surround force of its rear
robots, c_i ~ 1 where the local centroid lies toward the human; a robot between its local swarm and the human
has c_i = 0. Measured in petswarm (docs/RESULTS.md), a swarm under it trails a walking human as a tail and
jams at a corridor's mouth. This law keeps the paper's local forces (the impedance toward the local centroid,
the repulsion within A) and replaces the surround force and the drag by two terms a robot works out from the
same sensing (the human's IR beacon, tracked; its own odometry):

    f_i = f_R + f_O + f_P + f_M
    f_P = F_P * clip((|p_G| - rho) / w, 0, 1) * p_G / |p_G|      (pull on robots the human has left behind)
    f_M = D (v_G - v_i)                                          (move with the human)

- f_M, the velocity match: the paper's drag (-drag v) measured against the human's velocity v_G instead of
  the ground. A swarm under the paper's law needs a standing lag behind a walking human for its rear to push
  it along; with f_M the whole swarm moves at his pace with no lag, front robots included, so those ahead of
  him stay ahead.
- f_P, the pull: zero within rho of the human, so round him the local forces alone shape the swarm (its extent
  stays the paper's r*), growing to F_P over w beyond it. Every robot the human has left behind (past an
  obstacle that held it, at the tail of a swarm squeezed through a gap) is drawn back to him whatever its
  local centroid says; a robot facing an obstacle's edge slides along it toward the side he is on.

Without the human's beacon (not seen yet, or lost) both terms fall back to the paper's: no pull, drag on
the robot's own velocity. The force becomes a velocity as in the paper's law (unit virtual mass, clipped
acceleration and speed).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from petswarm.controllers.surround import SurroundConfig, SurroundController


class ImprovedSurroundController(SurroundController):
    """One robot's improved surround law, in its own frame, in plain floats (see the module's docstring)."""

    def __init__(self, config: SurroundConfig | None = None) -> None:
        super().__init__(config)
        self._human_velocity: tuple[float, float] | None = None

    def step_plain(
        self,
        neighbours: Sequence[Sequence[float]],
        obstacles: Sequence[Sequence[float]],
        human: Sequence[float] | None,
        velocity: Sequence[float],
        dt: float,
        human_velocity: Sequence[float] | None = None,
    ) -> tuple[float, float]:
        """The velocity command; as the paper's ``step_plain``, with the human's own velocity ``human_velocity``
        (his tracked beacon's, in this robot's frame; None when unknown)."""
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
        f_o = self._repulsion(neighbours, distances, near, obstacles)
        f_p = self._pull(human)
        self._forces = (f_r, f_o, f_p)
        force = (f_r[0] + f_o[0] + f_p[0], f_r[1] + f_o[1] + f_p[1])
        return self._matched_command(force, velocity, human if human is None else human_velocity, dt)

    def _pull(self, human: Sequence[float] | None) -> tuple[float, float]:
        """f_P: toward the human, growing from 0 at ``pull_radius_m`` to ``pull_force`` ``pull_ramp_m`` further."""
        if human is None:
            return 0.0, 0.0
        c = self.config
        hx, hy = human
        distance = math.sqrt(hx * hx + hy * hy)
        if distance <= c.pull_radius_m:
            return 0.0, 0.0
        strength = c.pull_force * min(1.0, (distance - c.pull_radius_m) / c.pull_ramp_m)
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


def _clip(x: float, y: float, limit: float) -> tuple[float, float]:
    """The vector (x, y) shortened to ``limit`` if longer."""
    scale = min(1.0, limit / max(math.sqrt(x * x + y * y), 1e-12))
    return x * scale, y * scale
