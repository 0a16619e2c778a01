"""Named properties judged on a case's record: safety ones hold at every instant, liveness ones once the faults
have cleared, within a stated time. Each says which families it applies to; a failure says what, when and who.

The record is the run's own (events of every robot and the user, the world log, the summary, the supervision
log of robots killed and restarted) and the case's scenario: the judge reads what happened, not the code's own
opinion of itself. Pure functions of a ``Record``: the unit tests feed each one a record that breaks it.
"""

from __future__ import annotations

import bisect
import json
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

from petswarm.lab.checker import check_record
from petswarm.lab.records import read_events
from petswarm.scenario import Scenario, is_action

ALL = ("organize", "drive", "surround", "pings", "follow", "mixed")
SWARMS = ("organize", "drive", "mixed")
"""Families whose user asks for swarms (organize and disperse through the owner's watch)."""

ORGANIZE_WITHIN_S = 4.0
"""Liveness: an organize asked for once the faults have cleared ends (``watch_organized``, at least one member)
within this time: the paper's protocol takes a few hundred ms, each step retries its missing answers."""
LOSS_BOUND = 0.2
"""Liveness: under loss of at most this probability on every reception (no other fault), a swarm still organizes
within ``ORGANIZE_WITHIN_S``."""
DISPERSE_WITHIN_S = 4.0
"""Liveness: every member of a swarm its master disperses (faults over) is back in waiting within this time."""
TOKEN_WITHIN_S = 6.0
"""Liveness: after a swarm member holding (or due) the IR token dies, the schedule drops it and the other
members get IR fixes again within this time (a member is dropped after a few silent rounds)."""
SETTLE_S = 3.0
"""A swarm counts as settled when none of its robots changed state or roster for this long (longer than a
member's ``master_silence_s``, 2 s: by then a member cut off has left)."""
PROGRAMMING_ERRORS = (
    "IndexError",
    "KeyError",
    "AttributeError",
    "TypeError",
    "AssertionError",
    "ZeroDivisionError",
    "UnboundLocalError",
    "NameError",
    "RecursionError",
)
"""An ``error`` event naming one of these is a bug a handler caught, not a fault of the air."""
MEMBER_DROP_S = 6.0
"""A master drops a member that left its swarm unheard (killed, or cut off until it gave up on the master) once
the member missed ``MEMBER_MISSES`` (3) of the master's IR rounds; while a member is silent the token waits out
its regeneration (1.5 s) every round, so a round lasts up to about 1.8 s and a master may count such a member
this long after it left (or after it took the master's role with that member on its roster): measured 3.3-5.6 s
(``petswarm explore --seed 1 --cases 300 --family drive,mixed``, cases 23, 31, 53, 186, 204, 252). A member that
says it leaves (``member_left``) is dropped at once."""
SWARM_STATES = ("organizing", "slave-driving", "master-driving")
HANDOVER_GRACE_S = 0.5
"""A master handing over its role still counts its members until it hears the new master accept (one frame and
its retries): that long, the two claims on a member may overlap."""


@dataclass(frozen=True)
class Violation:
    """What failed, when (model seconds into the run) and who."""

    what: str
    when: float | None = None
    who: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """For the results' JSON."""
        return {"what": self.what, "when": self.when, "who": list(self.who)}


@dataclass
class Record:
    """What a property may read of one case: the scenario, the family, every node's events, the world log,
    the summary, the supervision log and, when the run raised, its traceback."""

    scenario: Scenario
    family: str
    events: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    summary: dict[str, Any] = field(default_factory=dict)
    supervision: list[dict[str, Any]] = field(default_factory=list)
    crash: str | None = None
    path: Path | None = None
    world_lines: list[str] = field(default_factory=list)

    @classmethod
    def read(cls, path: Path | None, scenario: Scenario, family: str, crash: str | None = None) -> Record:
        """The record of a run directory (None: the run left none)."""
        record = cls(scenario, family, crash=crash, path=path)
        if path is None:
            return record
        for events in sorted((path / "events").glob("*.jsonl")):
            record.events[events.stem] = read_events(events)
        if (path / "summary.json").exists():
            record.summary = json.loads((path / "summary.json").read_text())
        if (path / "supervision.jsonl").exists():
            record.supervision = read_events(path / "supervision.jsonl")
        if (path / "world.jsonl").exists():
            record.world_lines = (path / "world.jsonl").read_text().splitlines()
        return record

    @cached_property
    def invariants(self) -> list[str]:
        """The checker's invariants that failed (petswarm/lab/checker.py)."""
        return check_record(self.path) if self.path is not None else ["no record"]

    @cached_property
    def world(self) -> list[dict[str, Any]]:
        """The world log's ticks."""
        return [json.loads(line) for line in self.world_lines]

    @property
    def robots(self) -> list[str]:
        """Node names of the robots (``robot-1``...)."""
        return [f"robot-{k}" for k in range(1, self.scenario.robot_count + 1)]

    @cached_property
    def clear_s(self) -> float:
        """When the last fault is over (model s since the run's start; faults count from the traffic phase,
        which starts within a tenth of a second)."""
        return max((float(f["at"]) for f in self.scenario.faults), default=0.0) + 0.2

    def active_faults(self, t: float) -> list[dict[str, Any]]:
        """The faults active at ``t`` (chaos faults until their clear, kills until the restart, the wearable
        link until it is back)."""
        active: list[dict[str, Any]] = []
        chaos_id = 0
        for fault in sorted(self.scenario.faults, key=lambda f: float(f["at"])):
            if float(fault["at"]) > t:
                break
            if fault.get("clear"):
                active = [a for a in active if fault.get("id") is not None and a.get("_id") != fault["id"]]
            elif fault.get("kind") == "restart":
                active = [a for a in active if not (a["kind"] == "kill" and a.get("robot") == fault.get("robot"))]
            elif fault.get("kind") == "wearable_back":
                active = [a for a in active if a["kind"] != "wearable_lost"]
            elif is_action(fault):
                active.append(dict(fault))
            else:
                chaos_id += 1
                active.append({**fault, "_id": chaos_id})
        return active

    def state_at(self, node: str, t: float) -> dict[str, Any]:
        """``node``'s last state event at or before ``t`` (its ``to`` state; a restarted robot starts waiting)."""
        state: dict[str, Any] = {"to": "waiting"}
        for event in self.events.get(node, []):
            if event["mono"] > t:
                break
            if event["kind"] == "start":
                state = {"to": event.get("state", "waiting"), "mono": event["mono"]}
            elif event["kind"] == "state":
                session = state.get("session")
                state = event
                if "session" not in event and event.get("to") in SWARM_STATES and session is not None:
                    state = {**event, "session": session}  # a handover's state change keeps the swarm's session
        return state

    def states_during(self, node: str, t0: float, t1: float) -> set[str]:
        """Every state ``node`` was in at some time from ``t0`` to ``t1``: the one it was in at ``t0`` and each it
        entered before ``t1`` (a window's two ends alone miss a swarm organized and dispersed between them)."""
        entered = {
            e["to"] for e in self.events.get(node, []) if e["kind"] == "state" and t0 < e["mono"] <= t1 and "to" in e
        }
        return {self.state_at(node, t0).get("to", "waiting"), *entered}

    def left_at(self, node: str, own: dict[str, Any], since: float, t: float) -> float:
        """When ``node``, in state ``own`` at ``t`` (``state_at``), stopped being a slave of a swarm it joined at
        ``since``: its state change out of the swarm, or its death if it died meanwhile."""
        deaths = [
            e["mono"]
            for e in self.supervision
            if e.get("process") == node and e.get("kind") == "died" and since <= e.get("mono", 0) <= t
        ]
        return min([max(float(own.get("mono", since)), since), *deaths])

    def dead_at(self, node: str, t: float) -> bool:
        """True when ``node`` was killed and not (yet) restarted at ``t``."""
        dead = False
        for entry in self.supervision:
            if entry.get("process") == node and entry.get("mono", 0) <= t:
                dead = entry.get("kind") == "died"
        return dead


@dataclass(frozen=True)
class Property:
    """A named predicate over a record, and the families it applies to."""

    name: str
    kind: str
    """``safety`` or ``liveness``."""
    families: tuple[str, ...]
    check: Callable[[Record], list[Violation]]
    doc: str


PROPERTIES: dict[str, Property] = {}


def prop(name: str, kind: str, families: Iterable[str]) -> Callable[[Callable[[Record], list[Violation]]], Any]:
    """Register a property (the function's docstring says what it asks)."""

    def register(check: Callable[[Record], list[Violation]]) -> Callable[[Record], list[Violation]]:
        PROPERTIES[name] = Property(name, kind, tuple(families), check, (check.__doc__ or "").strip())
        return check

    return register


def judge(record: Record, only: Iterable[str] | None = None) -> list[dict[str, Any]]:
    """Every property that applies to the record's family (``only``: these), failed ones only, each with its
    first violations."""
    failures = []
    for prop_ in PROPERTIES.values():
        if record.family not in prop_.families or (only is not None and prop_.name not in only):
            continue
        if record.crash is not None and prop_.name != "no_exception":
            continue  # a run that raised has no whole record to judge: its traceback is the verdict
        violations = prop_.check(record)
        if violations:
            failures.append(
                {"property": prop_.name, "kind": prop_.kind, "violations": [v.to_dict() for v in violations[:5]]}
            )
    return failures


# == safety ==================================================================================================


@prop("no_exception", "safety", ALL)
def no_exception(record: Record) -> list[Violation]:
    """No process raises: an uncaught exception in a robot, the user or the environment fails the case (its
    traceback kept), and so does a programming error a handler caught and logged (``error`` events)."""
    out = []
    if record.crash is not None:
        last = record.crash.strip().splitlines()[-1]
        out.append(Violation(f"the run raised: {last}\n{record.crash}"))
    for node, events in record.events.items():
        for event in events:
            error = str(event.get("error", ""))
            if event["kind"] == "error" and error.split(":")[0] in PROGRAMMING_ERRORS:
                out.append(Violation(f"handler error in {event.get('where')}: {error}", event["mono"], (node,)))
    return out


@prop("checker_invariants", "safety", ALL)
def checker_invariants(record: Record) -> list[Violation]:
    """The checker's invariants (counters add up, records complete and ordered, transitions chain, every robot
    ends waiting or with its user, no two IR modules at once) and the run's own checks. A robot that ends in
    emergency did what the spec says when it lost a user who was truly beyond the LF's reach and never came back
    within it (``_justified_emergency``); a false alarm, or a user in reach for long and not found, fails."""
    texts = [t for t in record.invariants if not _justified_emergency(record, t)]
    out = [Violation(f"invariant violated: {text}") for text in texts]
    problems = [p for p in record.summary.get("problems", []) if not p.startswith("invariant violated")]
    return out + [Violation(f"run check: {p}") for p in problems]


LF_VALID_RANGE_M = 2.0
"""The LF fix's valid range (pet-bot-wearable.md): a user farther than this from his robot is lost to it."""
LF_RANGE_ERROR_M = 0.1
"""How far inside the valid range a burst may still measure the user beyond it: 4 sigma of the LF's ranging
error at 2 m (``LfConfig.noise_db`` 0.3 dB through 60 dB a decade: 1.2 % a burst, 2.4 cm)."""
LOST_AFTER_S = 2.0
"""A robot declares its user lost after this long without a reliable fix (driving_core.LOST_AFTER_S)."""
FOUND_WITHIN_S = 1.0
"""A robot in emergency hears a tracking burst every 0.35 s: a user back within reach this long is found."""
EMERGENCY_END = "ends in emergency, not waiting or driving with its user"


def _justified_emergency(record: Record, invariant: str) -> bool:
    """Whether ``invariant`` is a robot's end in emergency that the spec asks for: following or leading (or
    driving a swarm and then dispersed), a robot too far from its user goes to emergency (pet-bot-wearable.md,
    Robot states). Justified when, at its last loss, the user was truly beyond the LF's valid range (the world
    log, less the ranging error) or out of its hearing (the wearable link lost by a fault), and never came back
    within reach long enough to be found. Whether the robot let him get away is ``no_runaway``'s to judge."""
    node = invariant.split(":", 1)[0]
    if not invariant.endswith(EMERGENCY_END):
        return False
    events = record.events.get(node, [])
    entered = [e["mono"] for e in events if e["kind"] == "state" and e.get("to") == "emergency"]
    losses = [e["mono"] for e in events if e["kind"] == "state" and e.get("cause") == "user lost"]
    if not losses or any(
        e["kind"] == "state" and e.get("cause") == "user found" and e["mono"] > losses[-1] for e in events
    ):
        return False
    lost = losses[-1]
    window = [lost - LOST_AFTER_S + k * 0.1 for k in range(int(LOST_AFTER_S / 0.1) + 1)]
    unheard = [t for t in window if any(f["kind"] == "wearable_lost" for f in record.active_faults(t))]
    beyond = _true_distance(record, node, lost) > LF_VALID_RANGE_M - LF_RANGE_ERROR_M
    if not (beyond or unheard):
        return False
    # found only in emergency (a dispersal may restore it after a swarm): reach counts from the last entry
    since = max([lost, entered[-1], *(_wearable_back(record, t) for t in unheard)])
    return not _in_reach_for(record, node, since, FOUND_WITHIN_S)


def _wearable_back(record: Record, t: float) -> float:
    """When the wearable link lost at ``t`` came back (the end of the run when it never did)."""
    backs = [float(f["at"]) for f in record.scenario.faults if f.get("kind") == "wearable_back" and f["at"] > t]
    return min(backs, default=float(record.summary.get("model_time_s") or 1e9))


def _in_reach_for(record: Record, node: str, since: float, seconds: float) -> bool:
    """Whether the user stood truly within the LF's valid range of ``node`` (less the ranging error) for
    ``seconds`` on end at some time after ``since``."""
    start = None
    for tick in record.world:
        t = tick["t_us"] / 1e6
        if t < since or not tick.get("bodies"):
            continue
        bodies = {b["id"]: b for b in tick["bodies"]}
        if node not in bodies or "user" not in bodies:
            start = None
            continue
        robot, user = bodies[node], bodies["user"]
        near = math.hypot(robot["x"] - user["x"], robot["y"] - user["y"]) < LF_VALID_RANGE_M - LF_RANGE_ERROR_M
        start = (start if start is not None else t) if near else None
        if start is not None and t - start >= seconds:
            return True
    return False


def _true_distance(record: Record, node: str, t: float) -> float:
    """``node``'s distance from the user at the world tick nearest ``t`` (0 when the log has neither)."""
    ticks = [tick for tick in record.world if tick.get("bodies")]
    if not ticks:
        return 0.0
    tick = min(ticks, key=lambda w: abs(w["t_us"] / 1e6 - t))
    bodies = {b["id"]: b for b in tick["bodies"]}
    if node not in bodies or "user" not in bodies:
        return 0.0
    robot, user = bodies[node], bodies["user"]
    return math.hypot(robot["x"] - user["x"], robot["y"] - user["y"])


def claims(record: Record) -> list[tuple[float, float, str, str, int]]:
    """Masters' claims on members from their own events: (from, to, master, member, session). A claim starts
    with ``organized`` (or a handover to the master), ends with ``member_lost``/``member_left``, the swarm's
    dispersal, or the master leaving master-driving (dissolved, handed over, killed)."""
    out: list[tuple[float, float, str, str, int]] = []
    end_of_run = float(record.summary.get("model_time_s") or 1e9)
    deaths = [(e["process"], e["mono"]) for e in record.supervision if e.get("kind") == "died"]
    for node, events in record.events.items():
        open_: dict[int, tuple[float, int]] = {}
        session = None
        for event in events:
            kind, t = event["kind"], event["mono"]
            for process, died in deaths:  # the claims made before a death end with it (a restart claims anew)
                if process == node and died <= t:
                    _close(out, open_, node, died, [m for m, (since, _) in open_.items() if since < died])
            session = event.get("session", session)
            if kind == "state" and event.get("cause") == "handover" and event.get("to") == "master-driving":
                open_.update({member: (t, session) for member in event.get("members", [])})
            if kind == "organized":
                open_.update({member: (t, event["session"]) for member in event.get("members", [])})
            elif kind in ("member_lost", "member_left"):
                _close(out, open_, node, t, [event.get("member")])
            elif kind in ("dispersed", "start") or (kind == "state" and event.get("frm") == "master-driving"):
                _close(out, open_, node, t)
        for process, died in deaths:
            if process == node:
                _close(out, open_, node, died, [m for m, (since, _) in open_.items() if since < died])
        _close(out, open_, node, end_of_run)
    return out


def _close(
    out: list[tuple[float, float, str, str, int]],
    open_: dict[int, tuple[float, int]],
    node: str,
    t: float,
    members: Iterable[Any] | None = None,
) -> None:
    for member in list(open_) if members is None else list(members):
        if member in open_:
            since, session = open_.pop(member)
            out.append((since, t, node, f"robot-{member}", session))


@prop("one_master_per_robot", "safety", SWARMS)
def one_master_per_robot(record: Record) -> list[Violation]:
    """No robot is a member of two swarms, or claimed by two masters, at once: two masters' claims (from their
    own ``organized`` and member-loss events) on one robot never overlap."""
    out = []
    by_member: dict[str, list[tuple[float, float, str, int]]] = {}
    for since, until, master, member, session in claims(record):
        by_member.setdefault(member, []).append((since, until, master, session))
    handovers = {
        (node, e["mono"])
        for node, events in record.events.items()
        for e in events
        if e["kind"] == "state" and e.get("cause") == "handover" and e.get("to") == "master-driving"
    }
    for member, spans in by_member.items():
        spans.sort()
        for i, (since, until, master, _session) in enumerate(spans):
            for since2, _until2, master2, _session2 in spans[i + 1 :]:
                if (master2, since2) in handovers and until - since2 <= HANDOVER_GRACE_S:
                    continue  # the old master hands over: it learns of the acceptance a frame later
                if since2 < until and master2 != master:
                    out.append(
                        Violation(
                            f"{member} claimed by {master} (from {since:.3f} s) and {master2} (from {since2:.3f} s)",
                            since2,
                            (member, master, master2),
                        )
                    )
    return out


@prop("roster_agreement", "safety", SWARMS)
def roster_agreement(record: Record) -> list[Violation]:
    """Once a swarm settles (no robot of it changed state or roster for ``SETTLE_S``), every member's state, PAN
    and master agree with its master's roster, and every robot driving as a slave of that session is on it. A
    member that left unheard (killed, or gave up on a master cut off from it) may stay counted ``MEMBER_DROP_S``."""
    out = []
    changes = sorted(
        {e["mono"] for ev in record.events.values() for e in ev if e["kind"] in _ROSTER_EVENTS}
        | {e["mono"] for e in record.supervision}
    )
    end = float(record.summary.get("model_time_s") or 0.0)
    spans = [(a, b) for a, b in zip(changes, [*changes[1:], end], strict=True) if b - a >= SETTLE_S]
    claim_list = claims(record)
    for a, b in spans:
        t = b - 1e-6  # the end of a settled stretch: everything has had SETTLE_S to agree
        if t < a + SETTLE_S:
            continue
        for since, until, master, member, session in claim_list:
            if not since <= t < until or record.dead_at(member, t) or record.dead_at(master, t):
                continue
            own = record.state_at(member, t)
            if own.get("to") != "slave-driving" or own.get("session") != session:
                if t - record.left_at(member, own, since, t) < MEMBER_DROP_S:
                    continue  # the master has not yet had its rounds to find the member silent
                out.append(
                    Violation(
                        f"{master}'s roster (session {session}) counts {member}, settled in {own.get('to')}"
                        f" (session {own.get('session')})",
                        round(t, 3),
                        (member, master),
                    )
                )
        for node in record.robots:
            own = record.state_at(node, t)
            if own.get("to") != "slave-driving" or record.dead_at(node, t):
                continue
            if not any(c[3] == node and c[4] == own.get("session") and c[0] <= t < c[1] for c in claim_list):
                out.append(
                    Violation(
                        f"{node} drives as a slave of session {own.get('session')} that no master's roster counts",
                        round(t, 3),
                        (node,),
                    )
                )
    return out[:20]


_ROSTER_EVENTS = ("state", "organized", "member_lost", "member_left", "dispersed", "handover", "start")


@prop("pan_hearing", "safety", ALL)
def pan_hearing(record: Record) -> list[Violation]:
    """No robot hears a frame of a PAN it is not on: every frame a robot was handed for a PAN other than the one
    it asked for (``foreign_pan``, with the frame's air time) was sent to the PAN the hub's MAC filtered that
    robot's frames by when the frame ended on the air (the robot's ``start`` and ``pan`` events: each PAN and
    the hub's model time it applied it). A frame held up after the air (a delay fault, the UART) or received
    before a change took effect is fine however late it comes; one for a PAN the robot was not on is not."""
    out = []
    for node, events in record.events.items():
        changes: list[tuple[int, int]] = []  # (model us, PAN) of this life of the robot
        for e in events:
            if e["kind"] == "start":
                changes = [(int(e.get("pan_at_us", 0)), int(e["pan"]))] if "pan" in e else []
            elif e["kind"] == "pan":
                changes.append((int(e["at_us"]), int(e["pan"])))
            elif e["kind"] == "foreign_pan":
                air_end = e.get("air_end_us")
                on_air = None if air_end is None else _pans_at(changes, int(air_end))
                if on_air is not None and e.get("dst_pan") in on_air:
                    continue
                was = "an unknown PAN" if not on_air else " or ".join(f"{p:#06x}" for p in sorted(on_air))
                at = "" if air_end is None else f" (on the air until {int(air_end) / 1e6:.6f} s)"
                out.append(
                    Violation(f"heard a frame for PAN {e.get('dst_pan'):#06x}{at} while on {was}", e["mono"], (node,))
                )
    return out


def _pans_at(changes: list[tuple[int, int]], t_us: int) -> set[int]:
    """The PAN in force at ``t_us`` by the changes (model us, PAN) in time order; both PANs of a change made at
    that very microsecond (the hub may have handled the frame's end or the change first)."""
    pans: set[int] = set()
    for at_us, pan in changes:
        if at_us < t_us:
            pans = {pan}
        elif at_us == t_us:
            pans.add(pan)
        else:
            break
    return pans


PUSHED_S = 0.1
"""A robot the user walked into within this long (five world ticks), or one pressed by such a robot, is excused its
contacts meanwhile: the world pushes it out of the user's way, into whatever is beside it, faster than any law can
react. A pair that parted for no longer than this and touches again is the same contact going on (bodies pressed
together part and touch again tick by tick as the world pushes them apart)."""


@prop("no_contact", "safety", ("organize", "drive", "follow", "mixed"))
def no_contact(record: Record) -> list[Violation]:
    """Where the driving law promises it (robots driving with their user, alone or as a swarm, whose safety
    stage stops short of an echo): no robot touches another robot or an obstacle. Contacts with the user are
    not judged: the scripted user walks blind, into a robot ahead of him as fast as 1.2 m/s, and into walls
    (so are the contacts of a robot he pushes, directly or through the robots it presses, ``PUSHED_S``). Who
    touched what is the world log's ``contacts`` (the pairs touching at each tick): a pair counts once, when it
    begins to touch."""
    out = []
    touched: dict[tuple[str, str], float] = {}  # each pair's last tick in contact
    apart: set[tuple[str, str]] = set()  # pairs of bodies that parted since they last touched
    pushed: dict[str, float] = {}
    seen = 0
    for tick in record.world:
        t = tick["t_us"] / 1e6
        now = {(str(a), str(b)) for a, b in tick.get("contacts", [])}
        pushed.update({who: t for who in _pressed_by_the_user(now)})
        apart |= _parted(tick, set(touched) - now)
        for a, b in sorted(now):
            parted = (a, b) in apart or (a, b) not in touched or not _bodies(tick, a, b)
            begins = parted and t - touched.get((a, b), -math.inf) > PUSHED_S + 1e-9
            touched[(a, b)] = t
            apart.discard((a, b))
            if not begins or "user" in (a, b) or any(t - pushed.get(who, -1.0) <= PUSHED_S for who in (a, b)):
                continue
            out.append(Violation(f"contact {a} / {_name(tick, b)}", round(t, 3), (a, b)))
        count = int(tick.get("collisions", 0))
        if count > seen and "contacts" not in tick:  # a world log that does not name who touched (an older hub's)
            out.append(Violation("a contact the world log names no pair of", round(t, 3)))
        seen = max(seen, count)
    return out


TARGET_DISTANCE_M = 1.0
"""The distance a following or leading robot keeps from its user (pet-bot-wearable.md, Controller)."""
RUNAWAY_M = 0.5
"""How much a robot may open its distance to a user who stands (beyond the target) in ``RUNAWAY_WINDOW_S``:
the most it drives before it can know his side, 0.41 m (side_check.UNSURE_SPEED_MPS: the check's probe, one
LF period at the cautious speed, braking), rounded up. One that takes him for one on the other side and
does not check drives on."""
RUNAWAY_WINDOW_S = 2.0
STANDING_S = 2.0
"""The user counts as standing once he stood this long: longer than a robot braking from its top speed
(1.2 m/s at 1.5 m/s^2 takes 0.8 s), so a leading robot's stop after his is not counted."""
STANDING_MPS = 0.05
STILL_YAW_RPS = 0.15
"""Nor turning: the belt's recogniser calls a turn over below this (``ActivityConfig.rotation_stop_rps``). A leading
robot answers a turning user with an arc (pet-bot-wearable.md, Controller), which may open the distance."""


@prop("no_runaway", "safety", ("drive", "follow", "mixed"))
def no_runaway(record: Record) -> list[Violation]:
    """A robot following or leading its user does not drive away from him while he stands: beyond the target
    distance, its distance to him grows by at most ``RUNAWAY_M`` in ``RUNAWAY_WINDOW_S``. (The LF cannot tell a
    user ahead from one behind; a robot that takes one for the other drives away from him.)"""
    out: list[Violation] = []
    samples = _user_and_distances(record)
    times = [sample[0] for sample in samples]
    for node in record.robots:
        flagged = -math.inf
        for t, standing_since, distances in samples:
            k = bisect.bisect_right(times, t - RUNAWAY_WINDOW_S + 1e-9)
            if not k or node not in distances or t - flagged < RUNAWAY_WINDOW_S:
                continue
            t0, _, before = samples[k - 1]
            d0, d1 = before.get(node, math.inf), distances[node]
            if d1 <= TARGET_DISTANCE_M + RUNAWAY_M or d1 - d0 <= RUNAWAY_M or t0 - standing_since < STANDING_S:
                continue
            if record.states_during(node, t0, t) <= {"following", "leading"}:
                out.append(Violation(f"{node} drove away from its standing user: {d0:.2f} -> {d1:.2f} m", t, (node,)))
                flagged = t
    return out


def _user_and_distances(record: Record) -> list[tuple[float, float, dict[str, float]]]:
    """The world log every 0.1 s: (t, since when the user stands still, neither walking nor turning, each robot's
    distance to him)."""
    out: list[tuple[float, float, dict[str, float]]] = []
    last = None
    standing_since = math.inf
    for tick in record.world:
        t = tick["t_us"] / 1e6
        bodies = {b["id"]: b for b in tick.get("bodies") or []}
        if "user" not in bodies or (out and t - out[-1][0] < 0.1 - 1e-9):
            continue
        user = bodies["user"]
        if last is not None:
            dt = max(t - last[0], 1e-9)
            speed = math.hypot(user["x"] - last[1], user["y"] - last[2]) / dt
            turning = abs(math.remainder(float(user.get("yaw", 0.0)) - last[3], math.tau)) / dt
            still = speed < STANDING_MPS and turning < STILL_YAW_RPS
            standing_since = min(standing_since, last[0]) if still else math.inf
        last = (t, user["x"], user["y"], float(user.get("yaw", 0.0)))
        distances = {
            k: math.hypot(b["x"] - user["x"], b["y"] - user["y"]) for k, b in bodies.items() if k.startswith("robot")
        }
        out.append((t, standing_since, distances))
    return out


PARTED_M = 0.005
"""Two bodies count as parted once this far beyond touching: the world log keeps positions to the millimetre, and
the world pushes overlapping bodies apart to touching exactly, so bodies left pressed together by a push read
within a millimetre or two of touching, in and out of the contact list, until one drives off."""


def _bodies(tick: dict[str, Any], a: str, b: str) -> tuple[dict[str, Any], dict[str, Any]] | None:
    """The two bodies of a pair in this tick (None when either is an obstacle or absent)."""
    found = {body["id"]: body for body in tick.get("bodies") or [] if body["id"] in (a, b)}
    return (found[a], found[b]) if len(found) == 2 else None


def _parted(tick: dict[str, Any], pairs: set[tuple[str, str]]) -> set[tuple[str, str]]:
    """Those of ``pairs`` (bodies not touching now) that are more than ``PARTED_M`` apart in this tick; a pair
    with an obstacle parts as soon as it stops touching (the time rule of ``PUSHED_S`` then applies)."""
    out = set()
    for a, b in pairs:
        bodies = _bodies(tick, a, b)
        if bodies is None:
            out.add((a, b))
            continue
        first, second = bodies
        gap = math.hypot(first["x"] - second["x"], first["y"] - second["y"])
        if gap > float(first.get("radius", 0.0)) + float(second.get("radius", 0.0)) + PARTED_M:
            out.add((a, b))
    return out


def _pressed_by_the_user(pairs: set[tuple[str, str]]) -> set[str]:
    """The bodies the user touches, and those they touch in turn (an obstacle passes no push on): the user's
    connected part of the contact graph."""
    reached, frontier = set(), {"user"}
    while frontier:
        reached |= frontier
        frontier = {
            other
            for a, b in pairs
            for me, other in ((a, b), (b, a))
            if me in frontier and other not in reached and not other.startswith("obstacle-")
        }
    return reached - {"user"}


def _name(tick: dict[str, Any], who: str) -> str:
    """A body's id, or an obstacle as the world log lists it (``obstacle-2 (wall (0, 1)-(0, 5))``)."""
    if not who.startswith("obstacle-"):
        return who
    obstacles = tick.get("obstacles", [])
    k = int(who.rsplit("-", 1)[1])
    if not 0 <= k < len(obstacles):
        return who
    o = obstacles[k]
    if o.get("kind") == "circle":
        return f"{who} (circle r {o['r']:g} at ({o['x']:g}, {o['y']:g}))"
    if o.get("kind") == "wall":
        return f"{who} (wall ({o['x0']:g}, {o['y0']:g})-({o['x1']:g}, {o['y1']:g}))"
    return f"{who} ({o.get('kind')})"


# == liveness ================================================================================================


def _requests(record: Record, request: str) -> list[tuple[str, dict[str, Any]]]:
    """The watch's requests of one kind, each with the robot that took it (the owner, or after a master change
    the robot the owner's role moved to)."""
    return sorted(
        (
            (node, e)
            for node in record.robots
            for e in record.events.get(node, [])
            if e["kind"] == "watch_request" and e.get("request") == request
        ),
        key=lambda pair: pair[1]["mono"],
    )


def _bounded_loss_only(record: Record, t: float) -> bool:
    active = record.active_faults(t)
    return bool(active) and all(
        a["kind"] == "loss" and float(a.get("p", 1.0)) <= LOSS_BOUND and "node" not in a for a in active
    )


@prop("organize_completes", "liveness", SWARMS)
def organize_completes(record: Record) -> list[Violation]:
    """An organize asked for once the faults have cleared (or under loss of at most ``LOSS_BOUND`` alone), with
    another robot waiting, completes with at least one member within ``ORGANIZE_WITHIN_S``."""
    out = []
    end = float(record.summary.get("model_time_s") or 0.0)
    for owner, req in _requests(record, "organize"):
        events = record.events.get(owner, [])
        t = req["mono"]
        if t + ORGANIZE_WITHIN_S > end or not (t >= record.clear_s or _bounded_loss_only(record, t)):
            continue
        before = t - 1e-6  # the request's own state change comes at the same instant
        if record.state_at(owner, before).get("to") not in ("following", "leading"):
            continue  # no swarm to lead from here (the watch refuses it): nothing was promised
        waiting = [r for r in record.robots if r != owner and record.state_at(r, before).get("to") == "waiting"]
        if not waiting:
            continue
        done = next((e for e in events if e["mono"] >= t and e["kind"] in _ORGANIZE_ENDS), None)
        if done is None or done["kind"] != "watch_organized" or not done.get("members"):
            what = "no answer" if done is None else f"{done['kind']} {done.get('members', done.get('error'))}"
            out.append(Violation(f"organize asked at {t:.3f} s did not complete: {what}", t, (owner,)))
        elif done["mono"] - t > ORGANIZE_WITHIN_S:
            out.append(Violation(f"organize asked at {t:.3f} s took {done['mono'] - t:.3f} s", t, (owner,)))
    return out


_ORGANIZE_ENDS = ("watch_organized", "watch_organize_failed")


@prop("disperse_returns_waiting", "liveness", SWARMS)
def disperse_returns_waiting(record: Record) -> list[Violation]:
    """Once the faults have cleared, every member of a swarm its master disperses is back in waiting within
    ``DISPERSE_WITHIN_S``."""
    out = []
    end = float(record.summary.get("model_time_s") or 0.0)
    for owner, req in _requests(record, "disperse"):
        t = req["mono"]
        if t < record.clear_s or t + DISPERSE_WITHIN_S > end:
            continue
        before = t - 1e-6
        session = record.state_at(owner, before).get("session")
        if record.state_at(owner, before).get("to") != "master-driving":
            continue
        for node in record.robots:
            own = record.state_at(node, before)
            if node == owner or own.get("to") != "slave-driving" or own.get("session") != session:
                continue
            later = record.state_at(node, t + DISPERSE_WITHIN_S)
            if later.get("to") in SWARM_STATES and later.get("session") == session:
                out.append(
                    Violation(f"{node} still {later['to']} {DISPERSE_WITHIN_S:g} s after the dispersal", t, (node,))
                )
    return out


@prop("token_regenerates", "liveness", SWARMS)
def token_regenerates(record: Record) -> list[Violation]:
    """The IR token schedule regenerates after a member dies: the swarm's other members get IR fixes again
    within ``TOKEN_WITHIN_S`` of the death, while their master keeps driving them."""
    out = []
    end = float(record.summary.get("model_time_s") or 0.0)
    for death in (e for e in record.supervision if e.get("kind") == "died"):
        t, dead = death["mono"], death["process"]
        own = record.state_at(dead, t - 1e-6)
        if own.get("to") != "slave-driving" or t + TOKEN_WITHIN_S + 1.0 > end:
            continue
        session = own.get("session")
        window = (t + TOKEN_WITHIN_S - 2.0, t + TOKEN_WITHIN_S + 1.0)
        for node in record.robots:
            if node == dead or any(record.dead_at(node, x) for x in (t, *window)):
                continue
            if not all(
                record.state_at(node, x).get("to") == "slave-driving"
                and record.state_at(node, x).get("session") == session
                for x in (t, *window)
            ):
                continue  # not a member throughout: nothing promised
            fixes = [
                e for e in record.events.get(node, []) if e["kind"] == "ir_fix" and window[0] <= e["mono"] <= window[1]
            ]
            if not fixes:
                out.append(
                    Violation(
                        f"no IR fix between {window[0]:.1f} and {window[1]:.1f} s after {dead} died", t, (node, dead)
                    )
                )
    return out
