"""World frames for ``petswarm watch``: the hub's snapshots of the world, checked, and a replay's clock.

A frame is what the hub publishes about ten times a second on ``petswarm/<world>/hub/world`` (msgpack) and
what a run record keeps in ``world.jsonl`` (one JSON object per line)::

    {"v": 1, "t_us": int, "wall": float,
     "bodies": [{"id": "1", "kind": "robot"|"user", "x", "y", "yaw", "vx", "vy", "radius",
                 "pan_id": int|None, "ir": "idle"|"receive"|"transmit"|"beacon", "state": str|None,
                 "role": "master"|"slave"|"single"|None, "reference": [x, y]|None}],
     "obstacles": [{"kind": "circle", "x", "y", "r"} | {"kind": "wall"|"rect", "x0", "y0", "x1", "y1"}],
     "collisions": int, "radio": {"delivered": int, "collided": int, "lost": int},
     "events": [{"kind": "collision"|"loss", "node": "3", "t_us": int}]}

Everything here is pure: no I/O, and the replay clock is given the wall time.
"""

from __future__ import annotations

import bisect
import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

VERSION = 1
BODY_KINDS = ("robot", "user")
IR_MODES = ("idle", "receive", "transmit", "beacon")
ROLES = ("master", "slave", "single")
"""single: a robot driving with its user outside any swarm."""
EVENT_KINDS = ("collision", "loss")
RADIO_COUNTERS = ("delivered", "collided", "lost")
DEFAULT_RADIUS_M = 0.15
"""A body without a radius is drawn at the robots' default size (the project's 0.15 m)."""
_OBSTACLE_FIELDS = {"circle": ("x", "y", "r"), "wall": ("x0", "y0", "x1", "y1"), "rect": ("x0", "y0", "x1", "y1")}


def check_frame(raw: Any) -> dict[str, Any]:
    """A clean frame from the hub's or a record's; ValueError naming the first bad field.

    Optional fields get their defaults and unknown fields are dropped, so the page can trust every field.
    """
    if not isinstance(raw, dict):
        raise ValueError(f"frame must be a mapping, got {type(raw).__name__}")
    if raw.get("v") != VERSION:
        raise ValueError(f"v must be {VERSION}, got {raw.get('v')!r}")
    radio = raw.get("radio") or {}
    if not isinstance(radio, dict):
        raise ValueError("radio must be a mapping of counters")
    return {
        "v": VERSION,
        "t_us": _int(raw, "t_us"),
        "wall": _number(raw, "wall", 0.0),
        "bodies": [_body(b, i) for i, b in enumerate(_list(raw, "bodies"))],
        "obstacles": [_obstacle(o, i) for i, o in enumerate(_list(raw, "obstacles"))],
        "collisions": _int(raw, "collisions", 0),
        "radio": {name: _int(radio, name, 0, f"radio.{name}") for name in RADIO_COUNTERS},
        "events": [_event(e, i) for i, e in enumerate(_list(raw, "events"))],
    }


def _body(raw: Any, i: int) -> dict[str, Any]:
    where = f"bodies[{i}]"
    if not isinstance(raw, dict):
        raise ValueError(f"{where} must be a mapping")
    reference = raw.get("reference")
    if reference is not None:
        if not (isinstance(reference, list | tuple) and len(reference) == 2):
            raise ValueError(f"{where}.reference must be [x, y] or null")
        reference = [_finite(reference[0], f"{where}.reference"), _finite(reference[1], f"{where}.reference")]
    pan = raw.get("pan_id")
    if pan is not None and (not isinstance(pan, int) or isinstance(pan, bool) or not 0 <= pan <= 0xFFFF):
        raise ValueError(f"{where}.pan_id must be 0-65535 or null, got {pan!r}")
    state = raw.get("state")
    if state is not None and not isinstance(state, str):
        raise ValueError(f"{where}.state must be a string or null")
    radius = _number(raw, "radius", DEFAULT_RADIUS_M, f"{where}.radius")
    if radius <= 0:
        raise ValueError(f"{where}.radius must be positive, got {radius}")
    return {
        "id": _text(raw, "id", where),
        "kind": _choice(raw, "kind", BODY_KINDS, where),
        "x": _number(raw, "x", None, f"{where}.x"),
        "y": _number(raw, "y", None, f"{where}.y"),
        "yaw": _number(raw, "yaw", 0.0, f"{where}.yaw"),
        "vx": _number(raw, "vx", 0.0, f"{where}.vx"),
        "vy": _number(raw, "vy", 0.0, f"{where}.vy"),
        "radius": radius,
        "pan_id": pan,
        "ir": _choice(raw, "ir", IR_MODES, where, "idle"),
        "state": state,
        "role": _choice(raw, "role", ROLES, where, None),
        "reference": reference,
    }


def _obstacle(raw: Any, i: int) -> dict[str, Any]:
    where = f"obstacles[{i}]"
    if not isinstance(raw, dict):
        raise ValueError(f"{where} must be a mapping")
    kind = _choice(raw, "kind", tuple(_OBSTACLE_FIELDS), where)
    shape: dict[str, Any] = {"kind": kind}
    for name in _OBSTACLE_FIELDS[kind]:
        shape[name] = _number(raw, name, None, f"{where}.{name}")
    if kind == "circle" and shape["r"] <= 0:
        raise ValueError(f"{where}.r must be positive")
    return shape


def _event(raw: Any, i: int) -> dict[str, Any]:
    where = f"events[{i}]"
    if not isinstance(raw, dict):
        raise ValueError(f"{where} must be a mapping")
    return {
        "kind": _choice(raw, "kind", EVENT_KINDS, where),
        "node": _text(raw, "node", where),
        "t_us": _int(raw, "t_us", None, f"{where}.t_us"),
    }


def _list(raw: dict[str, Any], name: str) -> list[Any]:
    value = raw.get(name, [])
    if not isinstance(value, list | tuple):
        raise ValueError(f"{name} must be a list")
    return list(value)


def _int(raw: dict[str, Any], name: str, default: int | None = None, label: str | None = None) -> int:
    value = raw.get(name, default)
    if not isinstance(value, int) or isinstance(value, bool):
        raise ValueError(f"{label or name} must be an integer, got {value!r}")
    return value


def _number(raw: dict[str, Any], name: str, default: float | None = None, label: str | None = None) -> float:
    return _finite(raw.get(name, default), label or name)


def _finite(value: Any, label: str) -> float:
    if not isinstance(value, int | float) or isinstance(value, bool) or not math.isfinite(value):
        raise ValueError(f"{label} must be a finite number, got {value!r}")
    return float(value)


def _text(raw: dict[str, Any], name: str, where: str) -> str:
    value = raw.get(name)
    if isinstance(value, int) and not isinstance(value, bool):
        value = str(value)  # an id sent as a number still names the same body
    if not isinstance(value, str) or not value:
        raise ValueError(f"{where}.{name} must be a non-empty string, got {value!r}")
    return value


def _choice(raw: dict[str, Any], name: str, allowed: tuple[Any, ...], where: str, default: Any = ...) -> Any:
    value = raw.get(name) if default is ... else raw.get(name, default)
    if value not in allowed and not (value is None and default is None):
        raise ValueError(f"{where}.{name} must be one of {', '.join(map(str, allowed))}, got {value!r}")
    return value


@dataclass(frozen=True)
class Replay:
    """A recorded run's frames in time order, and how many lines were dropped (cut short or malformed)."""

    frames: list[dict[str, Any]]
    dropped: int

    @property
    def times_us(self) -> list[int]:
        """Each frame's model time."""
        return [f["t_us"] for f in self.frames]


def parse_replay(lines: Iterable[str]) -> Replay:
    """The frames of a ``world.jsonl``; a line cut short by a kill, or not a frame, is counted and dropped."""
    frames: list[dict[str, Any]] = []
    dropped = 0
    for line in lines:
        if not line.strip():
            continue
        try:
            frames.append(check_frame(json.loads(line)))
        except (json.JSONDecodeError, ValueError):
            dropped += 1
    frames.sort(key=lambda f: f["t_us"])  # stable: frames of one instant keep their order
    return Replay(frames, dropped)


def with_events_since(frames: Sequence[dict[str, Any]], before: int, index: int) -> dict[str, Any]:
    """Frame ``index`` carrying the events of every frame after ``before`` up to it, so a replay that skips
    frames (played fast, or a slow page) still flashes every collision and loss it passes over."""
    frame = frames[index]
    if not before < index - 1:
        return frame
    events = [e for f in frames[max(before + 1, 0) : index + 1] for e in f["events"]]
    return {**frame, "events": events}


@dataclass
class ReplayClock:
    """Where a replay is at a given wall time: play, pause, seek and speed, as a page asks for them.

    ``times_us`` are the frames' model times in order. Model time advances ``speed`` times as fast as the
    wall clock while playing and stops at the last frame.
    """

    times_us: Sequence[int]
    speed: float = 1.0
    playing: bool = True
    seeks: int = 0
    """How many seeks so far: frames passed over by a seek are jumped, not played, so they flash nothing."""
    _anchor_wall: float = 0.0
    _anchor_t_us: float = field(default=0.0)

    def __post_init__(self) -> None:
        if not self.times_us:
            raise ValueError("times_us: a replay needs at least one frame")
        self._check_speed(self.speed)
        self._anchor_t_us = float(self.times_us[0])

    @property
    def start_us(self) -> int:
        """The first frame's time."""
        return self.times_us[0]

    @property
    def end_us(self) -> int:
        """The last frame's time."""
        return self.times_us[-1]

    def start(self, wall: float) -> None:
        """Begin at the first frame at wall time ``wall``."""
        self._anchor_wall = wall
        self._anchor_t_us = float(self.start_us)

    def t_us(self, wall: float) -> float:
        """Model time shown at ``wall``."""
        if not self.playing:
            return self._anchor_t_us
        t = self._anchor_t_us + (wall - self._anchor_wall) * 1e6 * self.speed
        return min(t, float(self.end_us))

    def index(self, wall: float) -> int:
        """The last frame at or before the model time shown at ``wall``."""
        return max(bisect.bisect_right(self.times_us, self.t_us(wall)) - 1, 0)

    def finished(self, wall: float) -> bool:
        """The replay has reached its last frame."""
        return self.t_us(wall) >= self.end_us

    def pause(self, wall: float) -> None:
        """Hold the current model time."""
        self._rebase(wall)
        self.playing = False

    def play(self, wall: float) -> None:
        """Go on from the current model time (from the start when at the end)."""
        if self.finished(wall):
            self._anchor_t_us = float(self.start_us)
        else:
            self._rebase(wall)
        self._anchor_wall = wall
        self.playing = True

    def seek(self, t_us: float, wall: float) -> None:
        """Show model time ``t_us`` (clamped to the recording) from ``wall`` on."""
        if not math.isfinite(t_us):
            raise ValueError(f"t_us must be a finite number, got {t_us!r}")
        self._anchor_t_us = min(max(float(t_us), float(self.start_us)), float(self.end_us))
        self._anchor_wall = wall
        self.seeks += 1

    def set_speed(self, speed: float, wall: float) -> None:
        """Play ``speed`` times real time from ``wall`` on."""
        self._check_speed(speed)
        self._rebase(wall)
        self.speed = speed

    def _rebase(self, wall: float) -> None:
        self._anchor_t_us = self.t_us(wall)
        self._anchor_wall = wall

    @staticmethod
    def _check_speed(speed: float) -> None:
        if not (isinstance(speed, int | float) and 0.01 <= speed <= 100):
            raise ValueError(f"speed must be between 0.01 and 100, got {speed!r}")
