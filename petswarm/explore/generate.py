"""Cases of a campaign: ``case(seed, i)`` is a scenario file's tables, drawn only from a generator seeded ``(seed, i)``.

A case is a world (robots, obstacles, the user's path), a mission (the watch requests of its family) and a fault
schedule (every chaos kind of the hub, robots killed and restarted, the wearables' link lost), written as a user
could have written it: ``petswarm.scenario.parse`` takes it and ``petswarm run FILE --clock model`` runs it.
Pure: case 17 is the same whether 16 ran first, on another worker, or alone.

Every fault ends by ``FAULTS_CLEAR_S`` before the mission's last requests (an organize, a dispersal), so the
liveness properties have a fault-free stretch to judge; each case is sized (robots, duration) to cost about a
CPU-second.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

FAMILIES = ("organize", "drive", "surround", "pings", "follow", "mixed")
"""What a case asks of the swarm: organize / disperse / organize again; swarm driving with Table 3's mode changes
and master changes; surround under either law; robots pinging; one robot following or leading its user; a mix."""
DEFAULT_WEIGHTS = {"organize": 3, "drive": 3, "surround": 1, "pings": 1, "follow": 1, "mixed": 2}
FAULT_KINDS = (
    "loss",
    "burst",
    "delay",
    "duplicate",
    "corrupt",
    "partition",
    "ir_blind",
    "ir_noise",
    "kill",
    "wearable_lost",
)
"""The fault kinds a case draws from: the hub's chaos kinds, a robot killed (and restarted), the wearable link lost."""
SETTLE_S = 4.0
"""Fault-free model seconds a case keeps after its last fault clears and before its final requests."""
TURN_ABOUT_S = 3.0
"""How long the user stands after asking the robots to change sides (following <-> leading): they turn round in
place on their AHRS, 180 degrees at the base's 1.5 rad/s slowing at the end, 2.4-2.6 s measured."""


def rng_of(seed: int, i: int) -> np.random.Generator:
    """Case ``i`` of seed ``seed``'s own generator (never a shared stream)."""
    return np.random.default_rng([int(seed), int(i), 0x9E37])


def pick_family(seed: int, i: int, weights: dict[str, float]) -> str:
    """The family of case ``i`` under ``weights`` (families with weight 0 never come)."""
    names = [f for f in FAMILIES if weights.get(f, 0) > 0]
    p = np.array([weights[f] for f in names], dtype=float)
    return str(np.random.default_rng([int(seed), int(i), 0xFA]).choice(names, p=p / p.sum()))


def case(seed: int, i: int, family: str | None = None) -> dict[str, Any]:
    """Case ``i`` of campaign seed ``seed`` as a scenario file's tables (``family`` None: by the default weights)."""
    family = family or pick_family(seed, i, DEFAULT_WEIGHTS)
    if family not in FAMILIES:
        raise ValueError(f"family must be one of {', '.join(FAMILIES)}, not {family!r}")
    rng = rng_of(seed, i)
    build = {
        "organize": _organize,
        "drive": _drive,
        "surround": _surround,
        "pings": _pings,
        "follow": _follow,
        "mixed": _mixed,
    }[family]
    data = build(rng)
    data["name"] = f"explore-{seed}-{i}-{family}"
    data["description"] = f"petswarm explore --seed {seed} --case {i} ({family})"
    return data


# -- worlds ----------------------------------------------------------------------------------------------


def _robots(rng: np.random.Generator, count: int, spread: float = 0.6) -> dict[str, Any]:
    """``count`` robots behind the user (who starts at the origin facing north), on a jittered grid."""
    per_row = max(2, math.ceil(math.sqrt(count)))
    positions = []
    for k in range(count):
        row, col = divmod(k, per_row)
        x = (col - (per_row - 1) / 2) * spread + float(rng.uniform(-0.1, 0.1))
        y = -0.8 - row * spread + float(rng.uniform(-0.1, 0.1))
        positions.append(
            [round(x, 3), round(y, 3), round(float(rng.uniform(-180, 180)) if rng.random() < 0.3 else 90, 1)]
        )
    return {"count": count, "positions": positions}


def _owner_faces_user(robots: dict[str, Any]) -> dict[str, Any]:
    """Robot 1, the user's own, turned to face him (the user at the origin) when it was drawn facing away: LF
    cannot tell front from back (pet-bot-wearable.md: y >= 0), so a robot with its user behind it takes him for
    one ahead, and following drives it away from him. The others may face anywhere."""
    x, y, heading = robots["positions"][0]
    toward = math.degrees(math.atan2(-y, -x))
    if abs((heading - toward + 180.0) % 360.0 - 180.0) > 90.0:
        robots["positions"][0] = [x, y, round(toward, 1)]
    return robots


def _obstacles(rng: np.random.Generator, far: float = 3.0) -> list[dict[str, Any]]:
    """Walls, corridors of any width and length, cylinders, pairs and rows, kept clear of the start area."""
    out: list[dict[str, Any]] = []
    for _ in range(int(rng.integers(0, 4))):
        kind = str(rng.choice(["wall", "corridor", "cylinder", "pair", "row"]))
        side = 1 if rng.random() < 0.5 else -1
        x0, y0 = float(side * rng.uniform(1.5, far + 2)), float(rng.uniform(1.0, far + 6))
        if kind == "wall":
            length = float(rng.uniform(1.0, 6.0))
            out.append(wall_obstacle(x0, y0, x0 + float(rng.uniform(-1, 1)), y0 + length))
        elif kind == "corridor":
            width, length = float(rng.uniform(1.2, 4.0)), float(rng.uniform(2.0, 10.0))
            y = float(rng.uniform(1.0, 3.0))
            out += [
                wall_obstacle(-width / 2, y, -width / 2, y + length),
                wall_obstacle(width / 2, y, width / 2, y + length),
            ]
        elif kind == "cylinder":
            out.append(circle_obstacle(x0, y0, float(rng.uniform(0.2, 1.2))))
        elif kind == "pair":
            r, gap = float(rng.uniform(0.2, 0.8)), float(rng.uniform(0.8, 3.0))
            out += [circle_obstacle(-gap / 2 - r, y0, r), circle_obstacle(gap / 2 + r, y0, r)]
        else:
            r, step = float(rng.uniform(0.15, 0.5)), float(rng.uniform(1.0, 2.5))
            out += [circle_obstacle(x0, y0 + k * step, r) for k in range(int(rng.integers(2, 5)))]
    return out


def wall_obstacle(x0: float, y0: float, x1: float, y1: float) -> dict[str, Any]:
    """A scenario's wall from (x0, y0) to (x1, y1), to the millimetre."""
    return {"kind": "wall", "x0": round(x0, 3), "y0": round(y0, 3), "x1": round(x1, 3), "y1": round(y1, 3)}


def circle_obstacle(x: float, y: float, r: float) -> dict[str, Any]:
    """A scenario's cylinder of radius ``r`` at (x, y), to the millimetre."""
    return {"kind": "circle", "x": round(x, 3), "y": round(y, 3), "r": round(r, 3)}


def _path(rng: np.random.Generator, seconds: float) -> list[dict[str, Any]]:
    """The user's path for about ``seconds``: stand, walk, turn, stop and speed steps."""
    legs: list[dict[str, Any]] = []
    left = seconds
    while left > 0.5:
        what = str(rng.choice(["walk", "walk", "turn", "stop", "steps"]))
        if what == "walk":
            speed = round(float(rng.uniform(0.3, 1.2)), 2)
            dist = round(min(float(rng.uniform(0.5, 4.0)), left * speed), 2)
            legs.append({"walk": max(dist, 0.1), "speed": speed})
            left -= dist / speed
        elif what == "turn":
            angle = round(float(rng.choice([-1, 1]) * rng.uniform(20, 180)), 1)
            rate = round(float(rng.uniform(30, 120)), 1)
            legs.append({"turn": angle, "rate": rate})
            left -= abs(angle) / rate
        elif what == "stop":
            stop = round(float(rng.uniform(0.5, 3.0)), 2)
            legs.append({"stop": stop})
            left -= stop
        else:  # speeding up in steps
            for speed in (0.3, 0.6, 0.9):
                legs.append({"walk": 0.4, "speed": speed})
                left -= 0.4 / speed
    return legs


def leg_seconds(leg: dict[str, Any]) -> float:
    """How long a path leg lasts (s)."""
    if "walk" in leg:
        return float(leg["walk"]) / float(leg["speed"])
    if "turn" in leg:
        return abs(float(leg["turn"])) / float(leg["rate"])
    return float(leg["stop"])


def _split_leg(leg: dict[str, Any], dt: float) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """``leg`` as the part of its first ``dt`` seconds and the rest, each as a list of one leg (or none, when
    shorter than 10 ms)."""
    rest = leg_seconds(leg) - dt
    if "walk" in leg:
        speed = leg["speed"]
        parts = [{"walk": round(speed * dt, 3), "speed": speed}, {"walk": round(speed * rest, 3), "speed": speed}]
    elif "turn" in leg:
        rate, sign = leg["rate"], math.copysign(1.0, leg["turn"])
        parts = [
            {"turn": round(sign * rate * dt, 2), "rate": rate},
            {"turn": round(sign * rate * rest, 2), "rate": rate},
        ]
    else:
        parts = [{"stop": round(dt, 3)}, {"stop": round(rest, 3)}]
    kept = [[p] if seconds >= 0.01 and leg_seconds(p) > 0 else [] for p, seconds in zip(parts, (dt, rest), strict=True)]
    return kept[0], kept[1]


def turns_about(path: list[dict[str, Any]]) -> bool:
    """Whether the user's path has a turn-about before a change of side (a turn, then ``TURN_ABOUT_S`` standing)."""
    return any("turn" in leg and path[k + 1 : k + 2] == [{"stop": TURN_ABOUT_S}] for k, leg in enumerate(path))


def _heading_and_reference(user: dict[str, Any], t: float, changes: list[tuple[float, str]]) -> tuple[float, float]:
    """The user's heading at ``t`` (degrees) and the heading the robots' side is taken from: following, the robots
    are behind the way he last walked (they do not circle him when he turns on the spot); leading, ahead of the way
    he faces (they drive an arc when he turns). ``changes``: (when, new side) of the changes of side before ``t``,
    each made while he stands after his turn."""
    heading = float(user["start"][2])
    side, reference, clock = "following", heading, float(user["walk_at"])
    pending = sorted(changes)
    for leg in user["path"]:
        if clock >= t:
            break
        seconds = leg_seconds(leg)
        while pending and pending[0][0] < min(t, clock + seconds):  # a change made during this leg (a stop)
            side, reference = pending.pop(0)[1], heading
        if "turn" in leg:
            heading += math.copysign(float(leg["rate"]) * min(seconds, t - clock), float(leg["turn"]))
        elif "walk" in leg and side == "following":
            reference = heading
        clock += seconds
    for _, new in (c for c in pending if c[0] < t):
        side, reference = new, heading
    return heading, (heading if side == "leading" else reference)


def _turn_about_at(rng: np.random.Generator, user: dict[str, Any], t: float, angle: float) -> tuple[float, float]:
    """Make the user turn by ``angle`` degrees at ``t`` (s after the start; a leg under way is cut there) and stand
    ``TURN_ABOUT_S`` after it: (when the turn ends, the seconds added to the user's timeline)."""
    turn = {"turn": round(angle, 1), "rate": round(float(rng.uniform(60, 120)), 1)}
    added = [turn, {"stop": TURN_ABOUT_S}]
    legs, walk_at = user["path"], float(user["walk_at"])
    if t <= walk_at:  # still standing where the path starts: the path now starts with the turn
        user["walk_at"] = round(t, 3)
        user["path"] = [*added, *([{"stop": round(walk_at - t, 3)}] if walk_at - t >= 0.01 else []), *legs]
    else:
        clock, out = walk_at, []
        for k, leg in enumerate(legs):
            seconds = leg_seconds(leg)
            if clock + seconds > t:
                first, last = _split_leg(leg, t - clock)
                out += [*first, *added, *last, *legs[k + 1 :]]
                break
            out.append(leg)
            clock += seconds
        else:  # past the path's end: stand until then
            out += ([{"stop": round(t - clock, 3)}] if t - clock >= 0.01 else []) + added
        user["path"] = out
    return t + leg_seconds(turn), leg_seconds(turn) + TURN_ABOUT_S


def _sides_with_turn_abouts(rng: np.random.Generator, user: dict[str, Any]) -> float:
    """The user turns about before every request that makes the robots change sides, and stands while they turn.

    Following and leading put the robots on opposite sides of the user (about 1 m behind, about 1 m ahead), and
    the LF fix cannot tell front from back (pet-bot-wearable.md, "Locating the user": y >= 0), so a robot cannot
    pass its user: a change between them is the user's turn-about (the paper's trajectory "a turn-about that
    switches following into leading"), each robot turning round where it stands. The first choice (the robots
    stand behind the user: following) turns nothing. Returns the seconds added to the timeline (every later
    request moves on by the time the user spent turning and standing)."""
    side, shift, changes = None, 0.0, []
    for req in user["watch"]:
        req["at"] = round(req["at"] + shift, 2)
        want = {"follow": "following", "lead": "leading"}.get(req["request"], req.get("mode"))
        if want is None or want == side:
            continue
        if side is not None:
            heading, reference = _heading_and_reference(user, req["at"], changes)
            # to leading: face the robots behind him; to following: turn his back on the robots ahead of him
            angle = (reference + 180.0 - heading + 180.0) % 360.0 - 180.0 if side == "following" else 180.0
            if abs(angle) > 179.5:
                angle = float(rng.choice([-180.0, 180.0]))
            end, added = _turn_about_at(rng, user, req["at"], angle if abs(angle) >= 1.0 else math.copysign(1.0, angle))
            req["at"] = round(end + 0.05, 2)
            shift += added
            changes.append((req["at"], want))
        side = want
    return shift


# -- faults ----------------------------------------------------------------------------------------------


def _faults(
    rng: np.random.Generator, robots: int, start: float, clear_by: float, *, user: bool
) -> list[dict[str, Any]]:
    """0-4 faults between ``start`` and ``clear_by`` s, every one over by then (an explicit clear, or a restart);
    heavy ones included (loss up to 0.6, a partition the whole window long)."""
    if clear_by - start < 0.5:
        return []
    out: list[dict[str, Any]] = []
    chaos_id = 0
    nodes = [f"robot-{k}" for k in range(1, robots + 1)]
    for _ in range(int(rng.choice([0, 1, 1, 2, 2, 3, 4]))):
        kind = str(rng.choice(FAULT_KINDS))
        if kind == "wearable_lost" and not user:
            kind = "loss"
        at = round(float(rng.uniform(start, clear_by - 0.3)), 2)
        end = round(float(rng.uniform(at + 0.2, clear_by)), 2)
        if kind == "kill":
            robot = int(rng.integers(1, robots + 1))
            out += [{"at": at, "kind": "kill", "robot": robot}, {"at": end, "kind": "restart", "robot": robot}]
            continue
        if kind == "wearable_lost":
            out += [{"at": at, "kind": "wearable_lost"}, {"at": end, "kind": "wearable_back"}]
            continue
        fault: dict[str, Any] = {"at": at, "kind": kind}
        if kind in ("loss", "corrupt", "duplicate"):
            fault["p"] = round(float(rng.choice([rng.uniform(0.05, 0.3), rng.uniform(0.3, 0.6)], p=[0.7, 0.3])), 3)
        elif kind == "delay":
            fault["ms"] = round(float(rng.uniform(1, 200)), 1)
            if rng.random() < 0.5:
                fault["jitter_ms"] = round(float(rng.uniform(0, fault["ms"])), 1)
        elif kind == "burst":
            fault["p_gb"] = round(float(rng.uniform(0.02, 0.2)), 3)
            fault["p_bg"] = round(float(rng.uniform(0.1, 0.6)), 3)
        elif kind == "partition":
            size = int(rng.integers(1, max(2, robots // 2 + 1)))
            fault["group"] = sorted(str(n) for n in rng.choice(nodes, size=size, replace=False))
        elif kind == "ir_noise":
            fault["sigma"] = round(float(rng.uniform(5, 200)), 1)
        if kind in ("loss", "corrupt", "duplicate", "delay", "burst", "ir_blind", "ir_noise") and rng.random() < 0.3:
            fault["node"] = str(rng.choice(nodes))
        chaos_id += 1  # the hub numbers the faults it takes from 1, in the order they come
        out += [fault, {"at": end, "clear": True, "id": chaos_id}]
    # the hub numbers faults as they are added: keep each clear's id on its own fault in time order
    return _renumber(out)


def _renumber(faults: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Give each clear the id the hub will give its fault (faults are added in time order)."""
    adds = [f for f in faults if "clear" not in f and "kind" in f and f["kind"] not in _ACTIONS]
    clears = [f for f in faults if f.get("clear")]
    order = sorted(range(len(adds)), key=lambda k: (adds[k]["at"], k))
    new_id = {k: rank + 1 for rank, k in enumerate(order)}
    for k, clear in enumerate(clears):  # clears were written right after their fault, in the same order
        clear["id"] = new_id[k]
    return sorted(faults, key=lambda f: f["at"])


_ACTIONS = ("kill", "restart", "wearable_lost", "wearable_back")


def clear_time(faults: list[dict[str, Any]]) -> float:
    """When the last fault of a schedule is over (0 without faults)."""
    return max((float(f["at"]) for f in faults), default=0.0)


# -- families --------------------------------------------------------------------------------------------


def _user(rng: np.random.Generator, watch: list[dict[str, Any]], walk_at: float, seconds: float) -> dict[str, Any]:
    return {"owner": 1, "start": [0.0, 0.0, 90.0], "walk_at": walk_at, "path": _path(rng, seconds), "watch": watch}


def _organize(rng: np.random.Generator) -> dict[str, Any]:
    """Organize, disperse, organize again (after the faults), disperse."""
    n = int(rng.choice([int(rng.integers(2, 6)), int(rng.integers(6, 31))], p=[0.7, 0.3]))
    k = int(rng.integers(1, n)) if n > 2 else 1
    shape = str(rng.choice(["column", "line", "wedge"]))
    faults_end = round(float(rng.uniform(5.0, 8.0)), 2)
    again = faults_end + SETTLE_S
    watch = [
        {"at": 1.0, "request": "follow"},
        {"at": 3.0, "request": "organize", "robots": k, "shape": shape, "spacing": 0.6},
        {"at": round(float(rng.uniform(4.0, faults_end)), 2), "request": "disperse"},
        {"at": again, "request": "organize", "robots": k, "shape": shape, "spacing": 0.6},
        {"at": again + 3.0, "request": "disperse"},
    ]
    duration = again + 6.0
    return {
        "duration_s": duration,
        "user": _user(rng, watch, duration, 0),
        "robots": _owner_faces_user(_robots(rng, n)),
        "faults": _faults(rng, n, 2.0, faults_end, user=True),
    }


def _drive(rng: np.random.Generator) -> dict[str, Any]:
    """A swarm driving with its user through a path, with Table 3's mode changes (and master changes)."""
    n = int(rng.integers(2, 7))
    shape = str(rng.choice(["column", "line", "wedge"]))
    faults_end = round(float(rng.uniform(6.0, 10.0)), 2)
    watch: list[dict[str, Any]] = [
        {"at": 1.0, "request": "follow"},
        {
            "at": 3.0,
            "request": "organize",
            "robots": n - 1,
            "shape": shape,
            "spacing": float(rng.choice([0.5, 0.6, 0.8])),
        },
    ]
    for _ in range(int(rng.integers(0, 3))):
        change = {"at": round(float(rng.uniform(4.5, faults_end + 2)), 2), "request": "mode"}
        change["mode"] = str(rng.choice(["following", "leading"]))
        change["change_master"] = bool(rng.random() < 0.5)
        watch.append(change)
    duration = faults_end + SETTLE_S + 4.0
    watch.append({"at": duration - 3.0, "request": "disperse"})
    data = {
        "duration_s": duration,
        "user": _user(rng, sorted(watch, key=lambda r: r["at"]), 4.5, duration - 8.0),
        "robots": _owner_faces_user(_robots(rng, n)),
        "faults": _faults(rng, n, 2.0, faults_end, user=True),
    }
    if rng.random() < 0.5:
        data["obstacles"] = _obstacles(rng)
    data["duration_s"] = round(duration + _sides_with_turn_abouts(rng, data["user"]), 2)
    return data


def _surround(rng: np.random.Generator) -> dict[str, Any]:
    """The surround formation under either law round a user who stands, then walks."""
    n = int(rng.integers(3, 9))
    duration = round(float(rng.uniform(8.0, 12.0)), 2)
    return {
        "duration_s": duration,
        "hub": {"world": {"robot_radius_m": 0.1}},
        "surround": {"enabled": True, "law": str(rng.choice(["paper", "improved"]))},
        "obstacles": _obstacles(rng, far=4.0),
        "user": {"start": [0.0, 0.0, 90.0], "walk_at": 3.0, "path": _path(rng, duration - 4.0)},
        "robots": _robots(rng, n, spread=0.8),
        "faults": _faults(rng, n, 1.0, duration - 3.0, user=False),
    }


def _pings(rng: np.random.Generator) -> dict[str, Any]:
    """Robots pinging each other, no user."""
    n = int(rng.integers(2, 16))
    duration = round(float(rng.uniform(4.0, 8.0)), 2)
    robots = _robots(rng, n, spread=1.0)
    robots["ping_interval"] = round(float(rng.uniform(0.2, 1.0)), 2)
    return {"duration_s": duration, "robots": robots, "faults": _faults(rng, n, 0.5, duration - 1.0, user=False)}


def _follow(rng: np.random.Generator) -> dict[str, Any]:
    """One robot follows or leads its user along a path (others wait)."""
    n = int(rng.integers(1, 4))
    duration = round(float(rng.uniform(8.0, 14.0)), 2)
    watch = [{"at": 1.0, "request": str(rng.choice(["follow", "lead"]))}]
    if rng.random() < 0.3:
        watch.append({"at": round(float(rng.uniform(3, duration - 2)), 2), "request": "cancel"})
    data = {
        "duration_s": duration,
        "user": _user(rng, watch, 3.0, duration - 4.0),
        "robots": _owner_faces_user(_robots(rng, n)),
        "faults": _faults(rng, n, 2.0, duration - 2.0, user=True),
    }
    if rng.random() < 0.5:
        data["obstacles"] = _obstacles(rng)
    return data


def _mixed(rng: np.random.Generator) -> dict[str, Any]:
    """Requests of every kind in a random order, then (faults over) an organize and a dispersal."""
    n = int(rng.integers(2, 8))
    faults_end = round(float(rng.uniform(6.0, 10.0)), 2)
    watch: list[dict[str, Any]] = [{"at": 1.0, "request": "follow"}]
    t = 2.0
    while t < faults_end:
        what = str(rng.choice(["organize", "disperse", "mode", "cancel", "follow", "lead"]))
        req: dict[str, Any] = {"at": round(t, 2), "request": what}
        if what == "organize":
            req.update(robots=int(rng.integers(1, n)), shape=str(rng.choice(["column", "line", "wedge"])))
        elif what == "mode":
            req.update(mode=str(rng.choice(["following", "leading"])), change_master=bool(rng.random() < 0.5))
        watch.append(req)
        t += float(rng.uniform(0.5, 3.0))
    again = faults_end + SETTLE_S
    watch += [
        {"at": again - 1.5, "request": "follow"},
        {"at": again, "request": "organize", "robots": n - 1},
        {"at": again + 3.0, "request": "disperse"},
    ]
    duration = again + 6.0
    data = {
        "duration_s": duration,
        "user": _user(rng, watch, 4.0, duration - 6.0),
        "robots": _owner_faces_user(_robots(rng, n)),
        "obstacles": _obstacles(rng) if rng.random() < 0.3 else [],
        "faults": _faults(rng, n, 2.0, faults_end, user=True),
    }
    data["duration_s"] = round(duration + _sides_with_turn_abouts(rng, data["user"]), 2)
    return data
