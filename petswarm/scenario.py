"""Scenario files: the world, the user's walk and watch requests, the robots, and a fault timeline.

A scenario is one TOML file (``scenarios/*.toml`` ship with the project)::

    name = "following-turn"
    duration_s = 30          # the run ends then (after the last watch request at the latest)
    [hub]                    # optional hub tables: [hub.world], [hub.ble], [hub.lf], [hub.ir], [hub.medium]
    [[obstacles]]            # kind = circle (x, y, r) | wall (x0, y0, x1, y1) | rect (x0, y0, x1, y1)
    [user]
    owner = 1                # the robot whose wake-up pattern the belt holds
    start = [0, 0, 90]       # x, y (m), heading (degrees)
    walk_at = 6              # when the path starts (s after the user process starts)
    path = [ {walk = 5, speed = 1.0}, {turn = -90, rate = 60}, {stop = 2} ]
    watch = [ {at = 1, request = "follow"}, {at = 3, request = "organize", robots = 3} ]
    [robots]
    count = 4
    positions = [[0, -1, 90], [0, -1.6, 90]]   # x, y, heading (deg) per robot id 1, 2, ... (at most count;
                                               # robots without one stand on a default grid)
    ping_interval = 0.5      # optional: each robot pings this often (s) and answers the others (default 0)
    [[faults]]               # as in experiment files: at = s, then a fault or an action
    [[faults]]               # model time only: at = s, kind = "kill" | "restart" (robot = id), or
                             # kind = "wearable_lost" | "wearable_back" (the user's BLE link, every robot)

Pure: parsing and the user's path as a function of time; every error names what is wrong, and a key
no table takes is refused with the nearest one it does take (``radio_hub.config.check_keys``).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from petswarm.controllers.formation_shapes import Mode, Shape
from petswarm.controllers.surround import SurroundConfig
from petswarm.wearables.gestures import Gesture
from petswarm.wearables.plan import Leg, UserPlan, WatchRequest
from radio_hub.datasheet import check_keys
from radio_hub.values import check_timed_fault

REQUESTS = ("follow", "lead", "remote", "cancel", "organize", "disperse", "mode", "return", "gesture")
"""Watch requests: select a main operation, cancel it, organize/disperse a swarm, change driving mode,
return from an obstacle exception, or perform a gesture."""
REQUEST_ARGS: dict[str, tuple[str, ...]] = {
    "organize": ("robots", "shape", "spacing"),
    "mode": ("mode", "change_master"),
    "gesture": ("gesture",),
}
"""What each watch request takes besides ``at`` and ``request`` (as petswarm/controllers/driving.py reads them)."""
_CHOICES = {"shape": tuple(Shape), "mode": tuple(Mode), "gesture": tuple(Gesture)}
TOP_KEYS = (
    "name",
    "description",
    "duration_s",
    "seed",
    "hub",
    "obstacles",
    "user",
    "robots",
    "faults",
    "surround",
    "explore",
)
EXPLORE_KEYS = ("family", "seed", "property")
"""``[explore]``: where a case written by ``petswarm explore`` came from (its family, the run's seed, the property
it failed); a run ignores it, ``petswarm explore --replay`` reads it."""
ROBOTS_KEYS = ("count", "formation", "positions", "ping_interval")
USER_KEYS = ("id", "owner", "start", "walk_at", "path", "watch")
LEG_KEYS = {"walk": ("walk", "speed"), "turn": ("turn", "rate"), "stop": ("stop",)}
ACTIONS: dict[str, tuple[str, ...]] = {
    "kill": ("robot",),
    "restart": ("robot",),
    "wearable_lost": (),
    "wearable_back": (),
}
"""Faults of a scenario's timeline that are not the air's: a robot killed (as SIGKILL) or restarted (a fresh
process of the same id, in waiting), and the user's wearables' BLE link lost or back. The run carries them out
(model time only), and what they take besides ``at`` and ``kind``."""


class ScenarioError(ValueError):
    """A scenario file that cannot be run, and why."""


@dataclass
class Scenario:
    """A whole scenario file."""

    name: str
    path: Path | None
    duration_s: float
    hub: dict[str, Any]
    obstacles: list[dict[str, Any]]
    user: UserPlan | None
    robot_count: int
    robot_poses: list[tuple[float, float, float]]
    """x, y, heading (deg) for robots 1..robot_count."""
    formation: str = "surround-free"
    ping_interval: float = 0.0
    """Seconds between a robot's pings (0: none), as ``petswarm robot --ping-interval``."""
    faults: list[dict[str, Any]] = field(default_factory=list)
    surround: dict[str, Any] = field(default_factory=dict)
    raw: dict[str, Any] = field(default_factory=dict)

    @property
    def surround_enabled(self) -> bool:
        """True when the robots run the surround formation (and the user wears an IR beacon)."""
        return bool(self.surround.get("enabled", False))

    def surround_law(self) -> dict[str, Any]:
        """The ``[surround]`` table's law settings (``SurroundConfig`` fields), ``enabled`` left out."""
        return {k: v for k, v in self.surround.items() if k != "enabled"}

    @property
    def actions(self) -> list[dict[str, Any]]:
        """The ``[[faults]]`` the run carries out itself: robots killed or restarted, the wearable link lost."""
        return [f for f in self.faults if is_action(f)]

    def hub_tables(self) -> dict[str, Any]:
        """The hub's config tables with the obstacles, as ``radio_hub.shell.hub.environment_from_dict`` takes them."""
        return {**self.hub, "obstacles": self.obstacles}


MAX_FILE_BYTES = 1 << 20
"""A scenario (or experiment) file's size at most: the shipped ones are a few kB; ``/dev/zero`` is endless."""
MAX_DURATION_S = 86400.0
"""The longest duration a scenario (or one leg of its walk) takes: a day, as ``petswarm run --duration``."""


def read_bounded(path: Path, limit: int = MAX_FILE_BYTES) -> str:
    """A text file's contents, refused (ValueError) past ``limit`` bytes without reading further."""
    with path.open("rb") as stream:
        data = stream.read(limit + 1)
    if len(data) > limit:
        raise ValueError(f"{path} is longer than {limit} bytes: not a scenario file")
    return data.decode()


def parse_toml(text: str) -> dict[str, Any]:
    """TOML that may come from anyone: nesting deeper than the parser's recursion is refused (ValueError)."""
    try:
        return tomllib.loads(text)
    except RecursionError:
        raise ValueError("nested too deeply") from None


def load(path: str | Path) -> Scenario:
    """Read and check a scenario file; ScenarioError names the first problem."""
    path = Path(path)
    try:
        data = parse_toml(read_bounded(path))
    except FileNotFoundError:
        raise ScenarioError(f"no scenario file {path}") from None
    except IsADirectoryError:
        raise ScenarioError(
            f"{path} is a directory, not a scenario file (the shipped ones: scenarios/*.toml)"
        ) from None
    except (OSError, UnicodeDecodeError) as err:
        raise ScenarioError(f"cannot read scenario file {path}: {err}") from None
    except (tomllib.TOMLDecodeError, ValueError) as err:
        raise ScenarioError(f"{path}: not TOML: {err}") from None
    try:
        return parse(data, path)
    except (TypeError, KeyError, ValueError, RecursionError) as err:
        raise ScenarioError(f"{path}: {err}") from None


def parse(data: dict[str, Any], path: Path | None = None) -> Scenario:
    """A scenario from its tables; ValueError naming the table and key of the first problem."""
    check_keys(data, TOP_KEYS, "the top level")
    check_keys(data.get("explore", {}), EXPLORE_KEYS, "[explore]")
    duration = _positive(data.get("duration_s", 30.0), "duration_s")
    robots = data.get("robots", {})
    check_keys(robots, ROBOTS_KEYS, "[robots]")
    count = int(robots.get("count", 0))
    if not 0 <= count <= 64:
        raise ValueError(f"robots.count must be 0-64, got {count}")
    poses = [_pose(p, f"robots.positions[{i}]") for i, p in enumerate(robots.get("positions", []))]
    if len(poses) > count:  # silently dropped, a robot meant to be in the run would not be
        raise ValueError(
            f"[robots] gives {len(poses)} positions for count = {count}: at most one position per robot "
            "(raise count or drop positions)"
        )
    if len(poses) < count:
        poses += [(1.5 * (i % 5), -1.5 * (i // 5) - 2.0, 90.0) for i in range(len(poses), count)]
    user = _user(data["user"]) if "user" in data else None
    obstacles = list(data.get("obstacles", []))
    faults = list(data.get("faults", []))
    for i, fault in enumerate(faults):
        if isinstance(fault, dict) and fault.get("kind") in ACTIONS:
            _check_action(fault, f"[[faults]][{i}]", count)
        else:
            check_timed_fault(fault, f"[[faults]][{i}]")
    return Scenario(
        name=str(data.get("name", path.stem if path else "scenario")),
        path=path,
        duration_s=duration,
        hub=_hub_tables(data.get("hub", {}), obstacles),
        obstacles=obstacles,
        user=user,
        robot_count=count,
        robot_poses=poses[:count],
        formation=str(robots.get("formation", "column")),
        ping_interval=_ping_interval(robots.get("ping_interval", 0.0)),
        faults=faults,
        surround=_surround(data.get("surround", {})),
        raw=data,
    )


def is_action(fault: dict[str, Any]) -> bool:
    """True for a ``[[faults]]`` entry the run carries out itself (``ACTIONS``), not the hub's chaos."""
    return fault.get("kind") in ACTIONS


def _check_action(spec: dict[str, Any], where: str, robots: int) -> None:
    kind = spec["kind"]
    check_keys(spec, ("at", "kind", *ACTIONS[kind]), where)
    at = spec.get("at")
    if not isinstance(at, int | float) or isinstance(at, bool) or not at >= 0:
        raise ValueError(f"{where} needs at = seconds (a number >= 0), not {at!r}")
    if "robot" in ACTIONS[kind]:
        robot = spec.get("robot")
        if not isinstance(robot, int) or isinstance(robot, bool) or not 1 <= robot <= robots:
            raise ValueError(f"{where}: robot must be a robot id 1-{robots}, not {robot!r}")


def _hub_tables(table: Any, obstacles: list[Any]) -> dict[str, Any]:
    """``[hub]`` and ``[[obstacles]]``, checked here as the hub will read them, so a typo fails before a run starts."""
    from radio_hub.hosting import parse_obstacle

    for i, obstacle in enumerate(obstacles):
        parse_obstacle(obstacle, f"[[obstacles]][{i}]")
    from radio_hub.hosting import environment_from_dict  # here: the environment brings numpy, parsing rarely needs it
    from radio_hub.values import MediumConfig

    # no [hub.obstacles]: a scenario's obstacles are its own [[obstacles]]
    check_keys(table, ("world", "ble", "lf", "ir", "medium", *MediumConfig().to_dict()), "[hub]")

    try:
        environment_from_dict(table)
    except ValueError as err:
        raise ValueError(f"[hub]: {err}") from None
    return dict(table)


def _surround(table: Any) -> dict[str, Any]:
    """``[surround]``: ``enabled`` and any ``SurroundConfig`` field (the law's gains), checked here."""
    check_keys(table, ("enabled", *SurroundConfig().to_dict()), "[surround]")
    enabled = table.get("enabled", False)
    if not isinstance(enabled, bool):
        raise ValueError(f"surround.enabled must be true or false, not {enabled!r}")
    SurroundConfig.from_dict({k: v for k, v in table.items() if k != "enabled"})  # raises naming the key
    return dict(table)


def _user(table: dict[str, Any]) -> UserPlan:
    check_keys(table, USER_KEYS, "[user]")
    start = _pose(table.get("start", [0.0, 0.0, 0.0]), "user.start")
    plan = UserPlan(
        node_id=str(table.get("id", "user")),
        owner=int(table.get("owner", 1)),
        start=(start[0], start[1], math.radians(start[2])),
        walk_at=float(table.get("walk_at", 0.0)),
        legs=[_leg(leg, i) for i, leg in enumerate(table.get("path", []))],
        watch=sorted((_request(r, i) for i, r in enumerate(table.get("watch", []))), key=lambda r: r.at),
    )
    if plan.walk_at < 0:
        raise ValueError("user.walk_at must be >= 0")
    return plan


def _leg(spec: dict[str, Any], i: int) -> Leg:
    where = f"[user] path[{i}]"
    kind = next((k for k in LEG_KEYS if isinstance(spec, dict) and k in spec), None)
    check_keys(spec, LEG_KEYS[kind] if kind else [k for keys in LEG_KEYS.values() for k in keys], where)
    if "walk" in spec:
        speed = _positive(spec.get("speed", 1.0), f"{where}.speed")
        if speed > 3.0:
            raise ValueError(f"{where}.speed {speed} m/s is faster than a person runs here (max 3)")
        return Leg("walk", _positive(spec["walk"], f"{where}.walk") / speed, speed=speed)
    if "turn" in spec:
        angle = math.radians(float(spec["turn"]))
        rate = math.radians(_positive(spec.get("rate", 60.0), f"{where}.rate"))
        return Leg("turn", abs(angle) / rate, rate=math.copysign(rate, angle))
    if "stop" in spec:
        return Leg("stop", _positive(spec["stop"], f"{where}.stop"))
    raise ValueError(f"{where} must have walk (m), turn (deg) or stop (s), got {sorted(spec)}")


def _request(spec: dict[str, Any], i: int) -> WatchRequest:
    where = f"[user] watch[{i}]"
    check_keys(spec, {"at", "request", *(k for keys in REQUEST_ARGS.values() for k in keys)}, where)
    spec = dict(spec)
    at = float(spec.pop("at", math.nan))
    if not at >= 0:
        raise ValueError(f"{where} needs at = seconds (>= 0)")
    request = spec.pop("request", "gesture" if "gesture" in spec else None)
    if request not in REQUESTS:
        raise ValueError(f"{where}: request must be one of {', '.join(REQUESTS)}, not {request!r}")
    check_keys({"at": at, "request": request, **spec}, ("at", "request", *REQUEST_ARGS.get(request, ())), where)
    for name, choices in _CHOICES.items():
        if name in spec and spec[name] not in choices:
            raise ValueError(f"{where}: {name} must be one of {', '.join(choices)}, not {spec[name]!r}")
    return WatchRequest(at, request, spec)


def _pose(values: Any, where: str) -> tuple[float, float, float]:
    if not isinstance(values, list) or len(values) not in (2, 3):
        raise ValueError(f"{where} is [x, y] or [x, y, heading_deg]")
    x, y, heading = (*(float(v) for v in values), 0.0)[:3]
    if not all(math.isfinite(v) for v in (x, y, heading)):
        raise ValueError(f"{where} must be finite numbers")
    return x, y, heading


def _ping_interval(value: Any) -> float:
    number = float(value)
    if not 0 <= number <= 3600:
        raise ValueError(f"robots.ping_interval must be 0-3600 s, got {value!r}")
    return number


def _positive(value: Any, where: str) -> float:
    number = float(value)
    if not 0 < number <= MAX_DURATION_S:  # also refuses NaN and infinity
        raise ValueError(f"{where} must be a positive number of seconds up to {MAX_DURATION_S:g}, got {value!r}")
    return number
