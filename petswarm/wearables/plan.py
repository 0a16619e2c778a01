"""What the user does in a run: the start, the path's legs and the watch requests, with the pose they give at
any instant. A scenario file's ``[user]`` table becomes one (``petswarm.scenario``); the user's process walks it
(``petswarm.wearables.user``). Pure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from petswarm.angles import wrap


@dataclass(frozen=True)
class Leg:
    """One piece of the user's path: walk ``distance`` at ``speed``, turn ``angle`` at ``rate``, or stop."""

    kind: str
    duration_s: float
    speed: float = 0.0
    """m/s while walking."""
    rate: float = 0.0
    """rad/s while turning (signed: positive counter-clockwise)."""


@dataclass(frozen=True)
class WatchRequest:
    """A request the user makes on the watch at ``at`` seconds."""

    at: float
    request: str
    args: dict[str, Any] = field(default_factory=dict)


@dataclass
class UserPlan:
    """The user's start, path and watch requests."""

    node_id: str = "user"
    owner: int = 1
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """x, y (m), heading (rad)."""
    walk_at: float = 0.0
    legs: list[Leg] = field(default_factory=list)
    watch: list[WatchRequest] = field(default_factory=list)

    def pose_at(self, t: float) -> tuple[float, float, float, float, float, float]:
        """x, y, yaw and world velocity (vx, vy, omega) at ``t`` seconds after the user process started."""
        x, y, yaw = self.start
        elapsed = t - self.walk_at
        for leg in self.legs:
            if elapsed <= 0:
                break
            dt = min(elapsed, leg.duration_s)
            moving = dt < leg.duration_s
            if leg.kind == "walk":
                x, y = x + math.cos(yaw) * leg.speed * dt, y + math.sin(yaw) * leg.speed * dt
                if moving:
                    return x, y, yaw, math.cos(yaw) * leg.speed, math.sin(yaw) * leg.speed, 0.0
            elif leg.kind == "turn":
                yaw += leg.rate * dt
                if moving:
                    return x, y, wrap(yaw), 0.0, 0.0, leg.rate
            elapsed -= leg.duration_s
        return x, y, wrap(yaw), 0.0, 0.0, 0.0

    @property
    def path_end_s(self) -> float:
        """When the last leg ends."""
        return self.walk_at + sum(leg.duration_s for leg in self.legs)

    def turn_starts(self) -> list[float]:
        """When each turn leg begins (s after the user process started): reaction times count from them."""
        starts, t = [], self.walk_at
        for leg in self.legs:
            if leg.kind == "turn":
                starts.append(t)
            t += leg.duration_s
        return starts
