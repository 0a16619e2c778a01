"""The IR token schedule as a sans-IO core: events and ``now`` in, actions out (paper Fig. 7).

``TokenSchedule`` holds every rule of the schedule (who holds the token, when members answer, when a lost
token is regenerated, when a window of readings becomes a fix) and nothing else: no clock, no event loop, no
radio. Each event is a method taking ``now`` (seconds) and returning the actions it calls for, in order:

- from the formation: ``join``, ``update_members``, ``rejoin``, ``leave``;
- from the radio: ``receive`` (the holder's ``IrStart``, ``Token``, ``Sync``, a neighbour's ``Heading``) and
  ``offer`` (the answers to this robot's own start sign and token);
- from the runtime, when an action it was given finishes: ``sent``, ``mode_set``, ``failed`` (each names
  the action's ``ref``), and ``measured`` (the mean readings of the window ``CloseWindow`` closed);
- from time: ``handle_timer(now)`` once ``next_timer()`` is due. ``timers()`` lists every wakeup wanted, so
  a runtime may keep one loop timer each (``IrTokenSchedule`` does, so that wakeups due at one instant keep
  the order they were asked for in, as the model clock orders its timers).

The rules, one round per holder: the holder broadcasts the start sign (a ``Step``: deadline, retries of
the missing) and members switch to receive, open their window, answer in their slot and, if neighbours,
send their heading; the holder shines for ``slot_s``, switches off, then broadcasts the token naming the
next holder (a second step); members close their window, estimate the holder's bearing and distance and
answer; the holder broadcasts ``Sync`` and the robot it names starts the next round. A named robot whose
Sync is lost starts anyway once the holder's token step is surely over. When nothing is heard for
``regen_timeout_s`` (the holder died, a Sync and its fallback were lost), the master, checking every
``WATCH_PERIOD_S``, regenerates the token with a higher round. A holder that hears the start sign of a
higher round stops at once (ties go to the higher address).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from petswarm.grid import next_on_grid
from petswarm.managers import messages as m
from petswarm.managers.actions import Incoming, Log, Send, SetIrMode
from petswarm.managers.decisions import reply_delay_s
from petswarm.managers.exchange import SendRequest, Step, StepTiming, WaitUntil
from petswarm.managers.ir_estimator import IrEstimate, estimate
from radio_hub.datasheet import IrConfig
from radio_hub.values import BROADCAST, lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

ANSWER_SLOT_MS = 3
"""Members answer the holder's start sign and token in slots of this length, in member order."""
WATCH_PERIOD_S = 0.05
"""How often the master looks for a lost token."""


@dataclass(frozen=True)
class TokenConfig:
    """Timing of the token schedule and the estimator the robot uses."""

    slot_s: float = 0.1
    """How long each holder shines: ten sweeps at the module's 100 Hz."""
    step: StepTiming = field(default_factory=lambda: StepTiming(0.05, 3))
    estimator: str = "lsq"

    @property
    def regen_timeout_s(self) -> float:
        """Silence after which the master regenerates a lost token: three times the longest a live
        holder's round can take (shine, and both steps with every retry): 1.5 s at the defaults."""
        worst_round = self.slot_s + 2 * (self.step.max_retries + 1) * self.step.deadline_s
        return 3 * worst_round

    @property
    def sync_fallback_s(self) -> float:
        """How long a robot named next waits for the Sync before it starts its round anyway: the holder's
        token step with every retry, and one deadline more."""
        return (self.step.max_retries + 2) * self.step.deadline_s


def next_holder(chain: tuple[int, ...], me: int, alive: set[int]) -> int:
    """The next robot after ``me`` in member order that answered this round (``me`` if nobody did)."""
    if me not in chain:
        return chain[0] if chain else me  # a member that has not had a roster yet hands back to the master
    start = chain.index(me)
    for step in range(1, len(chain)):
        candidate = chain[(start + step) % len(chain)]
        if candidate in alive:
            return candidate
    return me


# -- actions ------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SendHeading:
    """Send this robot's heading (the AHRS yaw, read when sending) to ``dst``, in ``session``."""

    dst: int
    session: int


@dataclass(frozen=True)
class OpenWindow:
    """Start collecting sweeps: ``holder`` shines next."""

    holder: int


@dataclass(frozen=True)
class CloseWindow:
    """Stop collecting; report the mean readings with ``measured(holder, readings, sweeps, now)``."""

    holder: int


@dataclass(frozen=True)
class DropWindow:
    """Stop collecting and throw the sweeps away (the swarm is over)."""


@dataclass(frozen=True)
class RecordFix:
    """A new bearing and distance of ``addr``, taken at ``at``."""

    addr: int
    fix: IrEstimate
    at: float


@dataclass(frozen=True)
class RecordHeading:
    """``addr`` told us its heading at ``at``."""

    addr: int
    heading_deg: float
    at: float


@dataclass(frozen=True)
class ForgetTable:
    """The swarm is over: forget every neighbour's fix and heading."""


@dataclass(frozen=True)
class Answers:
    """After a start sign this robot sent: who answered and who stayed silent (for the formation)."""

    answered: set[int]
    silent: set[int]


Action = (
    Send
    | SendHeading
    | SetIrMode
    | OpenWindow
    | CloseWindow
    | DropWindow
    | RecordFix
    | RecordHeading
    | ForgetTable
    | Answers
    | Log
)


@dataclass
class _Round:
    """The round this robot holds the token for."""

    round: int
    session: int
    others: set[int]
    phase: str = "start"
    """start (start-sign step), switch_on, shine, switch_off, token (token step), sync (Sync on its way)."""
    step: Step | None = None
    step_name: str = ""
    alive: set[int] = field(default_factory=set)
    next: int = 0
    wakeup: int | None = None
    """The step's answer deadline or the end of the shine."""
    ref: int | None = None
    """The action whose end the round waits for."""


class TokenSchedule:
    """The relative-location identification manager's schedule for one robot, with no I/O."""

    def __init__(self, me: int, config: TokenConfig, now: float, ir_config: IrConfig | None = None) -> None:
        self.me = me
        self.config = config
        self.ir_config = ir_config or IrConfig()  # the module's calibration (its datasheet), not the hub's truth
        self.session = 0
        self.chain: tuple[int, ...] = ()
        self.neighbours: tuple[int, ...] = ()
        self.is_master = False
        self.round = 0
        self.rounds_held = 0
        self.fixes = 0
        self.regenerations = 0
        self.retries = 0
        self.duplicates = 0
        self.last_activity = now
        self.air = True
        """False while the hub is away: with no air, silence means nothing and no token is lost."""
        self._window_of: tuple[int, int] | None = None
        self._holding: _Round | None = None
        self._ids = itertools.count(1)
        self._wakeups: dict[int, tuple[float, Callable[[float], list[Action]]]] = {}
        self._pending: dict[int, Callable[[float], list[Action]]] = {}
        self._watch_at = math.inf
        """When the lost-token check is next due on its ``WATCH_PERIOD_S`` grid (kept, not woken for, while out of
        a swarm)."""
        self._watching = False
        """Whether a wakeup for that check is pending."""

    @property
    def active(self) -> bool:
        """True while this robot belongs to a swarm."""
        return bool(self.session)

    @property
    def holding(self) -> int | None:
        """The round this robot holds the token for, if any."""
        return None if self._holding is None else self._holding.round

    # -- time ---------------------------------------------------------------------------------------

    def start(self, now: float) -> list[Action]:
        """The robot runs: start looking for a lost token every ``WATCH_PERIOD_S`` (while in a swarm)."""
        self._watch_at, self._watching = now + WATCH_PERIOD_S, True
        self._wake(self._watch_at, self._watch)
        return []

    def timers(self) -> dict[int, float]:
        """Every wakeup wanted, by id (ids grow in the order they were asked for)."""
        return {wid: when for wid, (when, _) in self._wakeups.items()}

    def next_timer(self) -> float | None:
        """When ``handle_timer`` is next due (None: nothing to wait for)."""
        return min((when for when, _ in self._wakeups.values()), default=None)

    def handle_timer(self, now: float) -> list[Action]:
        """Carry out the wakeups due at ``now``, in the order they were asked for; a wakeup this asks for at
        ``now`` itself (a zero answer slot) waits for the next call."""
        actions: list[Action] = []
        for wid in sorted(wid for wid, (when, _) in self._wakeups.items() if when <= now):
            wakeup = self._wakeups.pop(wid, None)  # an earlier one may have dropped it
            if wakeup is not None:
                actions += wakeup[1](now)
        return actions

    # -- the formation's events ---------------------------------------------------------------------

    def join(
        self, session: int, chain: tuple[int, ...], neighbours: tuple[int, ...], is_master: bool, now: float
    ) -> list[Action]:
        """Take part in the schedule of a swarm (the master starts the first round)."""
        self._resume_watch(now)
        self.session, self.chain, self.neighbours, self.is_master = session, chain, neighbours, is_master
        self.round = 0
        self.last_activity = now
        actions: list[Action] = [Log("ir_schedule", {"session": session, "chain": list(chain), "master": is_master})]
        if is_master:
            actions += self._hold(1, now)
        return actions

    def update_members(self, chain: tuple[int, ...], neighbours: tuple[int, ...]) -> list[Action]:
        """The roster changed: later rounds pass the token along the new chain."""
        self.chain, self.neighbours = chain, neighbours
        return []

    def rejoin(self, chain: tuple[int, ...], neighbours: tuple[int, ...], is_master: bool, now: float) -> list[Action]:
        """The master's role moved within the running swarm (a handover): the new chain and master flag.
        The round count is kept (members ignore start signs of older rounds) and the token keeps passing
        where it is; only who regenerates a lost token changes."""
        self.chain, self.neighbours, self.is_master = chain, neighbours, is_master
        self.last_activity = now
        detail = {"session": self.session, "chain": list(chain), "master": is_master, "rejoined": True}
        return [Log("ir_schedule", detail)]

    def leave(self, now: float) -> list[Action]:  # every event takes now, this one needs none
        """The swarm is over: stop holding, module off, forget the table (answers already due still go)."""
        self.session = 0
        actions = self._drop_round()
        self._window_of = None
        return [*actions, DropWindow(), ForgetTable(), SetIrMode("idle")]

    # -- the radio's events -------------------------------------------------------------------------

    @staticmethod
    def handles(message: m.SwarmMessage) -> bool:
        """True for the schedule's requests (answers go to ``offer``)."""
        return isinstance(message, (m.IrStart, m.Token, m.Sync, m.Heading))

    def receive(self, sender: int, message: m.SwarmMessage, now: float) -> list[Action]:
        """A holder's start sign, token or Sync, or a neighbour's heading."""
        if not self.active or message.session_id != self.session:
            return []
        self.last_activity = now
        if isinstance(message, m.IrStart):
            return self._on_start(sender, message, now)
        if isinstance(message, m.Token):
            return self._on_token(sender, message, now)
        if isinstance(message, m.Sync):
            actions = self._hold(message.round, now) if message.holder == self.me and message.round > self.round else []
            self.round = max(self.round, message.round)
            return actions
        if isinstance(message, m.Heading):
            return [RecordHeading(sender, message.centideg / 100.0, now)]
        return []

    def offer(self, incoming: Incoming, now: float) -> list[Action] | None:
        """An answer to this robot's start sign or token; None when no step of ours wants it."""
        held = self._holding
        if held is None or held.step is None:
            return None
        before = held.step.duplicates
        if not held.step.offer(incoming, now):
            return None
        self.duplicates += held.step.duplicates - before
        if held.ref is not None:
            return []  # the request is still on its way: the step goes on once it is sent
        return self._step_on(held, now)

    # -- the runtime's reports ----------------------------------------------------------------------

    def sent(self, ref: int, now: float) -> list[Action]:
        """The ``Send`` with ``ref`` is on the air."""
        return self._done(ref, now)

    def mode_set(self, ref: int, now: float) -> list[Action]:
        """The module is in the mode the ``SetIrMode`` with ``ref`` asked for."""
        return self._done(ref, now)

    def failed(self, ref: int, now: float) -> list[Action]:
        """The action with ``ref`` failed (the hub is away): what waited for it is given up."""
        self._pending.pop(ref, None)
        held = self._holding
        if held is None or held.ref != ref:
            return []
        return self._drop_round()

    def measured(self, holder: int, readings: np.ndarray | None, sweeps: int, now: float) -> list[Action]:
        """The window ``CloseWindow(holder)`` closed held ``sweeps`` sweeps averaging ``readings``."""
        fix = None if readings is None else estimate(readings, self.ir_config, self.config.estimator)
        if fix is None:
            return [Log("ir_no_fix", {"holder": holder, "sweeps": sweeps})]
        self.fixes += 1
        detail = {
            "holder": holder,
            "round": self.round,
            "sweeps": sweeps,
            "bearing_deg": round(math.degrees(fix.bearing_rad), 4),
            "distance_m": round(fix.distance_m, 5),
        }
        return [RecordFix(holder, fix, now), Log("ir_fix", detail)]

    def status(self) -> dict[str, Any]:
        """Counters for the robot's status answer."""
        return {
            "round": self.round,
            "rounds_held": self.rounds_held,
            "fixes": self.fixes,
            "regenerations": self.regenerations,
            "chain": list(self.chain),
        }

    # -- as a member --------------------------------------------------------------------------------

    def _on_start(self, holder: int, msg: m.IrStart, now: float) -> list[Action]:
        if msg.round < self.round and self._window_of != (holder, msg.round):
            return []  # a stale start sign
        actions: list[Action] = []
        if self._holding is not None:
            if (msg.round, holder) <= (self.round, self.me):
                return []  # the same round with a lower address yields to us: ties go to the higher address
            actions += self._drop_round()  # a higher round holds: never shine together
            actions.append(Log("ir_overtaken", {"round": msg.round, "by": holder}))
        self.round = max(self.round, msg.round)
        if self._window_of == (holder, msg.round):
            self._after_slot(holder, now, self._answer_start(holder, msg.round))
            return actions
        self._window_of = (holder, msg.round)
        ref = self._await(lambda at: self._receiving(holder, msg.round, at))
        return [*actions, OpenWindow(holder), SetIrMode("receive", ref)]

    def _receiving(self, holder: int, round_: int, now: float) -> list[Action]:
        if self.active:
            self._after_slot(holder, now, self._answer_start(holder, round_))
        return []

    def _answer_start(self, holder: int, round_: int) -> Callable[[float], list[Action]]:
        def answer(_: float) -> list[Action]:
            ref = self._await(lambda at: self._started_answered(holder))
            return [Send(holder, m.IrStartAck(self.session, round_), ref=ref)]

        return answer

    def _started_answered(self, holder: int) -> list[Action]:
        return [SendHeading(holder, self.session)] if holder in self.neighbours else []

    def _on_token(self, holder: int, msg: m.Token, now: float) -> list[Action]:
        actions: list[Action] = []
        if self._window_of == (holder, msg.round):
            self._window_of = None
            actions.append(CloseWindow(holder))
        if msg.next == self.me and msg.round >= self.round:
            self._wake(now + self.config.sync_fallback_s, lambda at: self._sync_missed(msg.round + 1, at))

        def answer(_: float) -> list[Action]:
            return [Send(holder, m.TokenAck(self.session, msg.round))]

        self._after_slot(holder, now, answer)
        return actions

    def _sync_missed(self, round_: int, now: float) -> list[Action]:
        """Named next and the Sync never came: start our round anyway; the holder's token step is surely over
        (it stopped shining before it sent the token, so this never overlaps it)."""
        if not self.active or self.round >= round_:
            return []
        return [Log("sync_missed", {"round": round_}), *self._hold(round_, now)]

    def _after_slot(self, holder: int, now: float, answer: Callable[[float], list[Action]]) -> None:
        """Answer the holder in this robot's slot: every member would answer its broadcast at once otherwise,
        and their CSMA backoffs collide."""
        others = tuple(a for a in self.chain if a != holder)
        self._wake(now + reply_delay_s(self.me, ANSWER_SLOT_MS, others), answer)

    # -- holding the token --------------------------------------------------------------------------

    def _hold(self, round_: int, now: float) -> list[Action]:
        actions = self._drop_round()
        self.round = round_
        held = _Round(round_, self.session, set(self.chain) - {self.me})
        self._holding = held
        self.last_activity = now
        return actions + self._begin_step(held, "ir_start", (m.IrStartAck,), held.others, now)

    def _drop_round(self) -> list[Action]:
        """Stop holding (overtaken, a new round of our own, the swarm over); the module off if it shines."""
        held, self._holding = self._holding, None
        if held is None:
            return []
        if held.wakeup is not None:
            self._wakeups.pop(held.wakeup, None)
        if held.ref is not None:
            self._pending.pop(held.ref, None)
        return [SetIrMode("idle")] if held.phase in ("switch_on", "shine") else []

    def _end_round(self, held: _Round) -> None:
        if self._holding is held:
            self._holding = None

    def _begin_step(
        self, held: _Round, name: str, kinds: tuple[type[m.SwarmMessage], ...], expected: set[int], now: float
    ) -> list[Action]:
        held.phase = "start" if name == "ir_start" else "token"
        held.step, held.step_name = Step(held.session, kinds, expected, self.config.step), name
        return self._step_on(held, now)

    def _step_on(self, held: _Round, now: float) -> list[Action]:
        """Drive the current step: send, wait for answers or the deadline, or go on once it is over."""
        step = held.step
        assert step is not None
        if held.wakeup is not None:
            self._wakeups.pop(held.wakeup, None)
            held.wakeup = None
        action = step.next_action(now)
        if isinstance(action, WaitUntil):
            held.wakeup = self._wake(action.when, lambda at: self._step_on(held, at))
            return []
        if isinstance(action, SendRequest):
            actions: list[Action] = []
            if action.retry:
                self.retries += 1
                missing = sorted(action.missing or ())
                detail = {
                    "step": held.step_name,
                    "session": held.session,
                    "attempt": step.attempts - 1,
                    "missing": missing,
                }
                actions.append(Log("retry", detail))
            held.ref = self._await(lambda at: self._request_sent(held, at))
            return [*actions, Send(BROADCAST, self._request(held), ack=False, ref=held.ref)]
        held.step = None
        if held.phase == "start":
            return self._started(held, step, now)
        return self._passed(held, now)

    def _request(self, held: _Round) -> m.SwarmMessage:
        if held.phase == "start":
            return m.IrStart(held.session, held.round)
        return m.Token(held.session, held.round, held.next)

    def _request_sent(self, held: _Round, now: float) -> list[Action]:
        held.ref = None
        assert held.step is not None
        held.step.sent(now)
        return self._step_on(held, now)

    def _started(self, held: _Round, step: Step, now: float) -> list[Action]:
        """Everyone answered the start sign, or the attempts ran out: shine, unless nobody heard us."""
        if self.round != held.round or not self.active:
            self._end_round(held)  # overtaken by a higher round while we waited
            return []
        held.alive = set(step.responses)
        actions: list[Action] = [Answers(held.alive, held.others - held.alive)]
        if held.others and not held.alive:
            # nobody heard us: we may be the deaf one while the others pass the token; never shine blind
            self.last_activity = now
            self._end_round(held)
            return [*actions, Log("ir_unheard", {"round": held.round})]
        if not self.is_master and self.chain and self.chain[0] not in held.alive:
            # our master did not hear us (a partition, or it died): it regenerates the token on its side once the
            # air is silent for regen_timeout_s, and two modules would shine at once; end the round unshone and
            # unpassed, so the members cut off with us fall silent too
            self.last_activity = now
            self._end_round(held)
            return [*actions, Log("ir_master_unheard", {"round": held.round, "master": self.chain[0]})]
        held.phase = "switch_on"
        held.ref = self._await(lambda at: self._shining(held, at))
        return [*actions, SetIrMode("transmit", held.ref)]

    def _shining(self, held: _Round, now: float) -> list[Action]:
        held.ref, held.phase = None, "shine"
        held.wakeup = self._wake(now + self.config.slot_s, lambda at: self._switch_off(held))
        return []

    def _switch_off(self, held: _Round) -> list[Action]:
        held.wakeup, held.phase = None, "switch_off"
        held.ref = self._await(lambda at: self._switched_off(held, at))
        return [SetIrMode("idle", held.ref)]

    def _switched_off(self, held: _Round, now: float) -> list[Action]:
        held.ref = None
        self.rounds_held += 1
        held.next = next_holder(self.chain, self.me, held.alive)
        return self._begin_step(held, "token", (m.TokenAck,), held.alive, now)

    def _passed(self, held: _Round, now: float) -> list[Action]:
        """The token step is over: name the next holder with Sync."""
        if self.round != held.round or not self.active:
            self._end_round(held)
            return []
        held.phase = "sync"
        held.ref = self._await(lambda at: self._synced(held, at))
        return [Send(BROADCAST, m.Sync(held.session, held.round + 1, held.next), ack=False, ref=held.ref)]

    def _synced(self, held: _Round, now: float) -> list[Action]:
        self.last_activity = now
        self._end_round(held)
        return self._hold(held.round + 1, now) if held.next == self.me else []

    # -- a lost token -------------------------------------------------------------------------------

    def _watch(self, now: float) -> list[Action]:
        """The master regenerates the token after ``regen_timeout_s`` of silence.

        Out of a swarm the check finds nothing to do, and what it would note (``last_activity`` while the air
        is away) counts only in a swarm, whose ``join`` sets it afresh: so it stops waking there (a surround
        robot never joins one, and these wakeups were 20 a second per robot) and ``join`` takes it up again on
        the same grid of instants, as if it had gone on."""
        actions: list[Action] = []
        if not self.air:
            self.last_activity = now  # no air, no token to lose
        elif self.active and self.is_master and now - self.last_activity > self.config.regen_timeout_s:
            self.regenerations += 1
            actions = [Log("token_regenerated", {"round": self.round + 1}), *self._hold(self.round + 1, now)]
        self._watch_at = now + WATCH_PERIOD_S
        self._watching = self.active
        if self._watching:
            self._wake(self._watch_at, self._watch)
        return actions

    def _resume_watch(self, now: float) -> None:
        """Wake for the lost-token check again, at its next instant after ``now`` on its grid (one at ``now``
        itself would have found the swarm just joined, with nothing to regenerate)."""
        if self._watching or self._watch_at == math.inf:  # still waking, or not started
            return
        at = self._watch_at if self._watch_at > now else next_on_grid(self._watch_at, WATCH_PERIOD_S, now)
        self._watch_at, self._watching = at, True
        self._wake(at, self._watch)

    # -- bookkeeping --------------------------------------------------------------------------------

    def _wake(self, when: float, then: Callable[[float], list[Action]]) -> int:
        wid = next(self._ids)
        self._wakeups[wid] = (when, then)
        return wid

    def _await(self, then: Callable[[float], list[Action]]) -> int:
        ref = next(self._ids)
        self._pending[ref] = then
        return ref

    def _done(self, ref: int, now: float) -> list[Action]:
        then = self._pending.pop(ref, None)
        return [] if then is None else then(now)
