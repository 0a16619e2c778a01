"""The sans-IO core of network formation (paper section 3.4, Fig. 8): both sides, events and ``now`` in,
actions out. No clock, no sleeping, no radio, no zenoh: ``petswarm.managers.formation`` is the asyncio runtime that
carries the actions out; a test drives the core by hand with explicit times.

Master side: the user's requests are *procedures*, generators that yield actions and are resumed with a
``Done`` (the time, and the action's outcome): ``organize`` runs scan -> joining query -> result notices,
each an ``Exchange`` of an ``exchange.Step`` (deadline, retries of the missing), then announces the roster
on the new PAN; ``disperse`` sends every member home; ``hand_over`` gives the master's role to a member.
A procedure reads as the paper's sequence does, one step after the other, and a test resumes it by hand.

Member side: ``receive(incoming, now)`` answers the master's requests per Table 1, switches PAN when chosen
and follows rosters and handovers; it returns the actions at once. ``get_timer()`` says when a candidate or
a member gives up (no result notice, or the master went silent), ``handle_timer(now)`` does it. A member
that is left out of a roster returns to waiting: membership is never believed by a robot that the master
does not count. A master that hears a roster of its own swarm from another robot settles which of the two
stays master (``decisions.rival_master``). ``answer_sent`` takes the MAC's report on an answer and retries it.

Frames to a particular robot use the broadcast PAN ID (0xFFFF) with its short address, so they reach it
whether it is still on the waiting PAN or already on the swarm's; answers go to the sender's PAN.

The runtime tells the core two facts about its radio before each event: its short address (``me``) and
the PAN it is on (``pan_id``). The order of the actions is the order in which the runtime must carry them
out, and the core has already changed its state (and the robot's, in ``SequenceManager``) when it returns.
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Iterable, Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, TypeVar

from petswarm.managers import messages as m
from petswarm.managers.actions import Incoming, Log, Send
from petswarm.managers.decisions import Rival, choose_pan, may_join, reply_delay_s, rival_master, select_members
from petswarm.managers.exchange import Step, StepResult, StepTiming
from petswarm.managers.sequence import DRIVING, RobotState, SequenceManager, StateChange
from radio_hub.values import BROADCAST, TxResult, lazy_numpy, max_payload

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

PROTOCOLS = ("paper", "slotted")
MAX_MEMBERS = 32
"""Members of one swarm besides the master: the roster lists them all in one frame."""
MAX_LISTED = 30
"""Robots a joining query can list as pending in one frame."""
MEMBER_MISSES = 3
"""Rounds of the master in a row a member may leave its start sign unanswered before it is dropped."""
ANSWER_ATTEMPTS = 3
"""Sends of one answer when the MAC reports a failure (channel access failure or no ACK)."""

_FREE = frozenset(int(s) for s in (RobotState.WAITING, *DRIVING))


class FormationError(RuntimeError):
    """An organize or disperse request this robot cannot carry out."""


@dataclass(frozen=True)
class FormationConfig:
    """Timing of the swarm process. ``paper`` answers at once; ``slotted`` answers in address slots."""

    waiting_pan: int = 0x1000
    protocol: str = "paper"
    slot_ms: int = 4
    step: StepTiming = field(default_factory=StepTiming)
    min_rssi_dbm: int = -70
    """The available region: -70 dBm is about 10 m with the hub's default path loss."""
    candidate_timeout_s: float = 3.0
    """A robot that said 'available' returns to waiting if no result notice comes in this time; it covers
    the query's and the notice's retries at the default timing."""
    roster_interval_s: float = 0.25
    master_silence_s: float = 2.0
    """A member that hears no roster for this long returns to waiting (the master is gone)."""

    def __post_init__(self) -> None:
        if self.protocol not in PROTOCOLS:
            raise ValueError(f"protocol must be one of {PROTOCOLS}, not {self.protocol!r}")

    def slot(self, protocol: str | None = None) -> int:
        """The slot length to put in requests: 0 for the paper's protocol."""
        return self.slot_ms if (protocol or self.protocol) == "slotted" else 0


@dataclass
class Swarm:
    """A robot's view of the swarm it belongs to."""

    session: int
    pan_id: int
    master: int
    number: int
    """0 for the master, 1.. for members in the order chosen (closest first)."""
    members: tuple[int, ...] = ()
    """Short addresses of the members, by member number from 1."""

    @property
    def neighbours(self) -> tuple[int, ...]:
        """Members next in number (a column by default; formation shapes come with driving)."""
        chain = (self.master, *self.members)
        i = self.number
        return tuple(chain[j] for j in (i - 1, i + 1) if 0 <= j < len(chain))

    def to_dict(self) -> dict[str, Any]:
        """For status answers."""
        return {
            "session": self.session,
            "pan_id": self.pan_id,
            "master": self.master,
            "number": self.number,
            "members": list(self.members),
            "neighbours": list(self.neighbours),
        }


# == actions: what the runtime carries out, in order ======================================================


@dataclass(frozen=True)
class Answer:
    """Send an answer to a master's request, or a master's non-participating notice; its MAC report goes back
    to the core (``answer_sent``), which sends it again when it failed."""

    dst: int
    message: m.SwarmMessage
    dst_pan: int
    attempt: int = 0


@dataclass(frozen=True)
class Pause:
    """Wait ``seconds`` (an answer slot, or the pause before a retried answer) before the next action."""

    seconds: float


@dataclass(frozen=True)
class ConfigurePan:
    """Switch the radio to ``pan_id``; ``where`` as in ``Send``."""

    pan_id: int
    where: str | None = None


@dataclass(frozen=True)
class SwarmChanged:
    """This robot joined a swarm, its members changed, or it left (None). ``swarm`` is a copy as it was
    when the change happened: a later change in the same event must not show in an earlier report."""

    swarm: Swarm | None

    @classmethod
    def of(cls, swarm: Swarm | None) -> SwarmChanged:
        """The change to ``swarm`` as it is now."""
        return cls(None if swarm is None else replace(swarm))


@dataclass(frozen=True)
class HandedOver:
    """The master's role moved in this robot's swarm: the chain before, the handover (None: learned from a roster)."""

    old_chain: tuple[int, ...]
    message: m.MasterHandover | None


@dataclass(frozen=True)
class StartRoster:
    """Start announcing ``roster()`` every ``roster_interval_s`` while it is not None."""


@dataclass(frozen=True)
class StopRoster:
    """Stop announcing the roster."""


@dataclass(frozen=True)
class Dissolve:
    """As soon as no request runs, call ``dissolve(swarm, reason, now)``: this master's swarm is over."""

    swarm: Swarm
    reason: str


@dataclass(frozen=True)
class Exchange:
    """Run ``step``: send ``requests(missing)`` whenever it asks, route answers to it, wait out its windows.
    The procedure is resumed with the step's ``StepResult``."""

    name: str
    step: Step
    requests: Callable[[set[int] | None], list[Send]]


Action = (
    Send | Answer | Pause | ConfigurePan | Log | StateChange | SwarmChanged | HandedOver | StartRoster | StopRoster
) | (Dissolve | Exchange)


@dataclass(frozen=True)
class Done:
    """What a procedure is resumed with: the time, and the outcome of the action it yielded (an
    ``Exchange``'s ``StepResult``; None for the others)."""

    now: float
    value: Any = None


T = TypeVar("T")
Procedure = Generator[Action, Done, T]
"""A master's request: yields actions, each resumed with a ``Done``; returns the request's result."""


def check_count(count: int) -> None:
    """Raise FormationError when a swarm of ``count`` members cannot be organized at all."""
    if not 1 <= count <= MAX_MEMBERS:
        raise FormationError(f"a swarm has 1 to {MAX_MEMBERS} members besides the master (its roster fills a frame)")


class FormationCore:
    """Network formation of one robot, both sides, without I/O."""

    def __init__(
        self, me: int, sequence: SequenceManager, config: FormationConfig, rng: np.random.Generator, user: int = 0
    ) -> None:
        self.me = me
        """This robot's short address (the runtime keeps it current)."""
        self.pan_id = config.waiting_pan
        """The PAN the radio is on (the runtime keeps it current)."""
        self.sequence = sequence
        self.config = config
        self.rng = rng
        self.user = user
        self.swarm: Swarm | None = None
        self.candidate_of: tuple[int, int] | None = None
        """(session, master) while this robot said 'available' and waits for the result."""
        self.organizations: list[dict[str, Any]] = []
        self._former_masters: set[int] = set()
        """Masters of this swarm that handed over: their late rosters must not take the role back."""
        self._unaccepted: m.MasterHandover | None = None
        """The last handover this master sent and saw no acceptance of (yet): if its target's roster comes,
        the target took the role and only the acceptance was lost, so this robot follows it after all."""
        self._attempted_at = 0.0
        self._outranked: set[tuple[int, int]] = set()
        """(session, rival) of rival masters this master outranks and has already recorded."""
        self._last_left: int | None = None
        self._deadline = 0.0
        """When a candidate or a member gives up waiting for its master."""
        self._misses: dict[int, int] = {}
        self._dissolving = 0
        """``Dissolve`` actions handed out and not yet carried out."""

    # == master side ==================================================================================

    def organize(self, count: int, protocol: str, now: float) -> Procedure[dict[str, Any]]:
        """Form a swarm of up to ``count`` other robots (``check_count`` first); returns the figures."""
        if self.sequence.state == RobotState.MASTER_DRIVING:
            raise FormationError("this robot already leads a swarm: disperse it first")
        if self.sequence.state not in DRIVING:
            raise FormationError(
                f"robot is {self.sequence.state.label}: only a robot driving with its user can organize"
            )
        if self.sequence.state == RobotState.EMERGENCY:
            # it has no fix of its user: a swarm it led would drive without him, and his watch's disperse may
            # never reach it once he walks out of BLE range
            raise FormationError("robot has lost its user (emergency): it organizes once it finds him again")
        session = int(self.rng.integers(1, 0xFFFF))
        slot = self.config.slot(protocol)
        t0 = now
        yield self.sequence.enter(RobotState.ORGANIZING, session=session, requested=count, protocol=protocol)
        steps: dict[str, StepResult] = {}
        try:
            steps["scan"] = yield from self._exchange(self._scan(session, slot, count))
            scan = steps["scan"].responses
            replies = {a: i.message for a, i in scan.items() if isinstance(i.message, m.ScanReply)}
            # everyone not already in a swarm is asked: each decides with Table 1 (a robot connected
            # to another user refuses on its own)
            candidates = {a for a, r in replies.items() if _free_reply(r)}
            pan = choose_pan(self.rng, {r.pan_id for r in replies.values()} | {self.config.waiting_pan})
            steps["query"] = yield from self._exchange(self._query(session, slot, candidates))
            available, refused = _answers(steps["query"])
            chosen = select_members(available, count)
            yield ConfigurePan(pan)
            yield from _each(_releases(session, set(available) - set(chosen)))
            done = yield self._notify(session, slot, pan, chosen)
            steps["notice"] = done.value
            members = tuple(a for a in chosen if a in steps["notice"].responses)
            done = yield from _each(_releases(session, set(chosen) - set(members)), done)
        except GeneratorExit:  # the runtime dropped the procedure: nothing is carried out any more
            raise
        except BaseException:
            yield from _each(self._abandon(session))
            raise
        elapsed = _last_arrival(steps["notice"], t0) if members else done.now - t0
        if not members:
            yield ConfigurePan(self.config.waiting_pan)
        figures = {
            "session": session,
            "protocol": protocol,
            "requested": count,
            "pan_id": pan,
            "candidates": sorted(candidates),
            "available": sorted(available),
            "refused": refused,
            "members": list(members),
            "missing": sorted(set(chosen) - set(members)),
            "organize_time_s": round(elapsed, 6),
            "retries": sum(s.retries for s in steps.values()),
            "step_retries": {name: s.retries for name, s in steps.items()},
        }
        yield from _each(self._settle(session, pan, members, figures))
        return figures

    def _settle(self, session: int, pan: int, members: tuple[int, ...], figures: dict[str, Any]) -> list[Action]:
        self.organizations.append(figures)
        if not members:
            return [Log("organized", figures), self.sequence.restore(session=session, reason="no robot joined")]
        self.swarm = Swarm(session, pan, self.me, 0, members)
        self._misses = {}
        change = self.sequence.enter(RobotState.MASTER_DRIVING, session=session, members=list(members))
        return [change, Log("organized", figures), SwarmChanged.of(self.swarm), StartRoster()]

    def _abandon(self, session: int) -> list[Action]:
        actions: list[Action] = [Log("organize_failed", {"session": session})]
        if self.sequence.state == RobotState.ORGANIZING:
            actions.append(self.sequence.restore(session=session, reason="organizing failed"))
        # the hub may be the reason organizing failed: a failure to switch back is recorded, not raised
        return [*actions, ConfigurePan(self.config.waiting_pan, where="abandon")]

    def _scan(self, session: int, slot: int, count: int) -> Exchange:
        """The scan is open (the master knows nobody yet), so "every answer came" means: as many free robots as
        the user asked for answered. Until then the scan is retried, as the paper retries any step whose
        responses have not all arrived; a robot whose answer was lost (a collision, no MAC ACK) answers again.

        Only a robot that Table 1 will let join counts: waiting, connected to no user, and heard inside the
        available region (the link's loss is the same both ways, up to its fading). The others are asked all
        the same and refuse; counted, they ended the scan early: of 50 robots, the first 11 to answer
        included 4 outside the region, and 7 joined a swarm of 10 while robots inside it went unasked."""
        region = self.config.min_rssi_dbm

        def requests(_: set[int] | None) -> list[Send]:
            return [Send(BROADCAST, m.Scan(session, self.user, slot), dst_pan=BROADCAST, ack=False)]

        def enough(responses: Mapping[int, Incoming]) -> bool:
            return sum(1 for i in responses.values() if _may_join(i, region)) >= count

        step = Step(session, (m.ScanReply,), None, self._timing(slot, 8), enough=enough)
        return Exchange("scan", step, requests)

    def _query(self, session: int, slot: int, candidates: set[int]) -> Exchange:
        def requests(missing: set[int] | None) -> list[Send]:
            pending = tuple(sorted(missing or candidates))
            if len(pending) > MAX_LISTED:
                pending = ()  # too many to list in one frame: every free robot answers
            query = m.JoinQuery(session, self.user, self.config.min_rssi_dbm, slot, pending)
            return [Send(BROADCAST, query, dst_pan=BROADCAST, ack=False)]

        kinds = (m.JoinAvailable, m.JoinUnavailable)
        return Exchange("query", Step(session, kinds, candidates, self._timing(slot, len(candidates))), requests)

    def _notify(self, session: int, slot: int, pan: int, chosen: list[int]) -> Exchange:
        def requests(missing: set[int] | None) -> list[Send]:
            return [
                Send(addr, m.JoinNotice(session, pan, len(chosen) + 1, number, slot), dst_pan=BROADCAST)
                for number, addr in enumerate(chosen, start=1)
                if missing is None or addr in missing
            ]

        step = Step(session, (m.Joined,), set(chosen), self._timing(slot, len(chosen)))
        return Exchange("notice", step, requests)

    def _timing(self, slot: int, responders: int) -> StepTiming:
        # the slotted protocol's deadline grows with the slots it asked responders to use; since every
        # answer has a slot, an open step (the scan) can end once all eight slots and a margin have
        # passed without a new answer, instead of always waiting out the deadline
        base = self.config.step
        if not slot:
            return base
        slots_s = min(responders, 8) * slot / 1000.0
        return StepTiming(base.deadline_s + slots_s, base.max_retries, quiet_s=8 * slot / 1000.0 + 0.01)

    @staticmethod
    def _exchange(exchange: Exchange) -> Procedure[StepResult]:
        done = yield exchange
        result: StepResult = done.value
        return result

    def roster(self) -> m.Roster | None:
        """The roster to announce now; None once this robot is no longer a master (the announcing stops)."""
        swarm = self.swarm
        if swarm is None or self.sequence.state != RobotState.MASTER_DRIVING:
            return None
        return m.Roster(swarm.session, swarm.members)

    def hand_over(
        self,
        chain: tuple[int, ...],
        mode: str,
        shape: str,
        spacing: float,
        mirrored: int,
        kept: int,
        owner: str,
        now: float,
    ) -> Procedure[bool]:
        """Table 3's Change column, the old master's side: make ``chain[0]`` the master of this swarm, with
        ``chain[1:]`` as its members in order. An ``Exchange`` takes the handover to the new master
        (deadline, retries, recorded) and waits for its acceptance; then a broadcast tells every member (one
        that misses it learns from the new master's rosters) and this robot becomes a slave. False when the
        new master never accepted: this robot is still the master; if the new master took the role all the
        same (only its acceptance was lost), its first roster heard here makes this robot follow the
        handover after all (``_on_rival_roster``)."""
        swarm = self.swarm
        if swarm is None or swarm.number or self.sequence.state != RobotState.MASTER_DRIVING:
            raise FormationError(f"robot is {self.sequence.state.label}, not the master of a swarm")
        if sorted(chain) != sorted((swarm.master, *swarm.members)) or chain[0] == self.me:
            raise FormationError(f"handover chain {list(chain)} is not a reordering of the swarm with a new master")
        msg = m.MasterHandover(swarm.session, swarm.pan_id, chain, mode, shape, spacing, mirrored, kept, owner)
        if len(msg.encode()) > max_payload(pan_compressed=False):
            raise FormationError(f"a handover of {len(chain)} robots does not fit one frame")
        new = chain[0]

        def requests(_: set[int] | None) -> list[Send]:
            return [Send(new, msg, dst_pan=BROADCAST)]

        # remembered before the first send: the target may take the role however the step ends
        self._unaccepted, self._attempted_at = msg, now
        step = Step(swarm.session, (m.HandoverAccepted,), {new}, self.config.step)
        result = yield from self._exchange(Exchange("handover", step, requests))
        if swarm.number:
            return True  # the new master's roster came before its acceptance: followed already
        if self.swarm is not swarm:
            return False  # a rival master made this robot give the swarm up meanwhile
        if new not in result.responses:
            yield Log("handover_failed", {"session": swarm.session, "to": new, "retries": result.retries})
            return False
        yield StopRoster()
        # the members that miss the broadcast learn the handover from the new master's rosters
        done = yield Send(BROADCAST, msg, ack=False, where="handover_broadcast")
        if not swarm.number:  # the new master's roster may have come while the broadcast was on the air
            yield from _each(self._follow_handover(swarm, msg, done.now, retries=result.retries))
        return True

    def _follow_handover(self, swarm: Swarm, msg: m.MasterHandover | None, now: float, **detail: Any) -> list[Action]:
        """Take the new order of a handover as a member (the old master, or a member told or learning it)."""
        chain = msg.chain if msg is not None else (swarm.master, *swarm.members)
        old_chain = (swarm.master, *swarm.members) if msg is not None else detail.pop("old_chain")
        old_master = old_chain[0]
        self._former_masters = (self._former_masters | {old_master}) - {chain[0]}
        self._unaccepted = None
        swarm.master, swarm.members, swarm.number = chain[0], chain[1:], chain.index(self.me)
        self._misses = {}
        self._deadline = now + self.config.master_silence_s
        handover = {"session": swarm.session, "frm": old_master, "to": chain[0], "number": swarm.number, **detail}
        actions: list[Action] = [Log("handover", handover)]
        if self.sequence.state == RobotState.MASTER_DRIVING:
            actions.append(
                self.sequence.enter(RobotState.SLAVE_DRIVING, cause="handover", master=chain[0], number=swarm.number)
            )
        return [*actions, SwarmChanged.of(swarm), HandedOver(old_chain, msg)]

    def _take_over(self, swarm: Swarm, msg: m.MasterHandover) -> list[Action]:
        """Become the swarm's master: its rosters, member tracking and dispersal are ours from now."""
        old_chain = (swarm.master, *swarm.members)
        # the transition first: if Fig. 4 refused it, the swarm view must stay as it was
        change = self.sequence.enter(
            RobotState.MASTER_DRIVING, cause="handover", old_master=old_chain[0], members=list(msg.chain[1:])
        )
        self._former_masters = (self._former_masters | {swarm.master}) - {self.me}
        swarm.master, swarm.members, swarm.number = self.me, msg.chain[1:], 0
        self._misses = {}
        # dispersal returns the new master to the driving mode the user has just chosen
        self.sequence.previous_driving = RobotState.LEADING if msg.mode == "leading" else RobotState.FOLLOWING
        handover = {"session": swarm.session, "frm": old_chain[0], "to": self.me, "number": 0}
        return [change, Log("handover", handover), SwarmChanged.of(swarm), HandedOver(old_chain, msg), StartRoster()]

    def disperse(self, protocol: str | None, now: float) -> Procedure[dict[str, Any]]:
        """End the swarm: every member back to waiting, this robot back to its driving state."""
        swarm = self.swarm
        if swarm is None or self.sequence.state != RobotState.MASTER_DRIVING:
            raise FormationError(f"robot is {self.sequence.state.label}, not the master of a swarm")
        slot = self.config.slot(protocol)

        def requests(missing: set[int] | None) -> list[Send]:
            return [
                Send(addr, m.Disperse(swarm.session, slot), dst_pan=BROADCAST)
                for addr in swarm.members
                if missing is None or addr in missing
            ]

        step = Step(swarm.session, (m.Dispersed,), set(swarm.members), self._timing(slot, len(swarm.members)))
        try:
            result = yield from self._exchange(Exchange("disperse", step, requests))
        except GeneratorExit:  # the runtime dropped the procedure: nothing is carried out any more
            raise
        except BaseException:
            yield from _each(self._end_swarm(swarm)[1])  # whatever happened on the air
            raise
        restored, ending = self._end_swarm(swarm)
        yield from _each(ending)
        done = yield ConfigurePan(self.config.waiting_pan)
        figures = {
            "session": swarm.session,
            "disperse_time_s": round(done.now - now, 6),
            "retries": result.retries,
            "members": list(swarm.members),
            "unconfirmed": sorted(result.missing),
            "restored": restored.to.label,
        }
        yield Log("dispersed", figures)
        return figures

    def _end_swarm(self, swarm: Swarm) -> tuple[StateChange, list[Action]]:
        """A dispersing master is a master no more: the way back to driving, and the actions that say so."""
        self.swarm = None
        restored = self.sequence.restore(session=swarm.session)
        return restored, [SwarmChanged(None), StopRoster(), restored]

    def note_answers(self, answered: set[int], silent: set[int]) -> list[Action]:
        """Master side: who answered our IR start sign. A member silent for ``MEMBER_MISSES`` of our
        rounds in a row is gone (dead, or out of reach): the roster drops it and the token skips it.
        The actions never wait (records, swarm changes, a ``Dissolve``)."""
        swarm = self.swarm
        if swarm is None or swarm.number:
            return []
        for addr in answered:
            self._misses.pop(addr, None)
        actions: list[Action] = []
        for addr in silent & set(swarm.members):
            self._misses[addr] = self._misses.get(addr, 0) + 1
            if self._misses[addr] >= MEMBER_MISSES:
                actions += self._drop_member(addr, "member_lost")
        return actions

    def _drop_member(self, addr: int, why: str) -> list[Action]:
        swarm = self.swarm
        if swarm is None or addr not in swarm.members:
            return []
        swarm.members = tuple(a for a in swarm.members if a != addr)
        self._misses.pop(addr, None)
        record = Log(why, {"session": swarm.session, "member": addr})
        if swarm.members:
            return [record, SwarmChanged.of(swarm)]
        # the last member is gone: the swarm is over, the master drives with its user again
        return [record, self._dissolve_later(swarm, "every member is gone")]

    def _dissolve_later(self, swarm: Swarm, reason: str) -> Dissolve:
        self._dissolving += 1
        return Dissolve(swarm, reason)

    def dissolve(self, swarm: Swarm, reason: str, now: float) -> list[Action]:
        """Carry out a ``Dissolve`` (the runtime calls it when no request runs): give the swarm up."""
        self._dissolving = max(self._dissolving - 1, 0)
        if self.swarm is not swarm:
            return []
        self.swarm = None
        change = self.sequence.restore(session=swarm.session, reason=reason)
        # the hub may be away; the wanted PAN applies when it is back
        return [SwarmChanged(None), StopRoster(), change, ConfigurePan(self.config.waiting_pan, where="dissolve")]

    # == member side ==================================================================================

    @staticmethod
    def handles(message: m.SwarmMessage) -> bool:
        """True for the messages ``receive`` acts on."""
        return type(message) in _HANDLERS

    def receive(self, incoming: Incoming, now: float) -> list[Action]:
        """Act on a formation message received at ``now``."""
        handler = _HANDLERS.get(type(incoming.message))
        return [] if handler is None else handler(self, incoming, now)

    def _on_member_left(self, incoming: Incoming, now: float) -> list[Action]:
        """Master side: a member that gave up on us (it heard no roster) says so; stop counting it."""
        swarm = self.swarm
        if swarm is None or swarm.number or swarm.session != incoming.message.session_id:
            return []
        return self._drop_member(incoming.sender, "member_left")

    def _on_scan(self, incoming: Incoming, now: float) -> list[Action]:
        msg: m.Scan = incoming.message  # type: ignore[assignment]
        reply = m.ScanReply(msg.session, int(self.sequence.state), self.pan_id, self._user_now())
        return self._answer(incoming, reply, reply_delay_s(self.me, msg.slot_ms))

    def _on_query(self, incoming: Incoming, now: float) -> list[Action]:
        msg: m.JoinQuery = incoming.message  # type: ignore[assignment]
        if msg.pending and self.me not in msg.pending:
            return []
        if not msg.pending and self.candidate_of is None and self.sequence.state != RobotState.WAITING:
            return []  # an unlisted query asks the free robots only
        answer, actions = self._judge_query(msg, incoming, now)
        return [*actions, *self._answer(incoming, answer, reply_delay_s(self.me, msg.slot_ms, msg.pending))]

    def _judge_query(self, msg: m.JoinQuery, incoming: Incoming, now: float) -> tuple[m.SwarmMessage, list[Action]]:
        """Table 1 with the project's states: the answer, and the transition when this robot becomes a candidate."""
        rssi = round(incoming.rx.rssi_dbm)
        state = self.sequence.state
        if self.candidate_of == (msg.session, incoming.sender):
            return m.JoinAvailable(msg.session, rssi), []  # a retried query: same answer
        refusal = may_join(self._user_now(), rssi, msg.min_rssi_dbm)
        if refusal != m.Refusal.CONNECTED_TO_USER and state != RobotState.WAITING:
            refusal = m.Refusal.BUSY  # taken by another master, or already in a swarm
        if refusal is not None:
            return m.JoinUnavailable(msg.session, int(refusal)), []
        self.candidate_of = (msg.session, incoming.sender)
        self._deadline = now + self.config.candidate_timeout_s
        change = self.sequence.enter(RobotState.ORGANIZING, session=msg.session, master=incoming.sender)
        return m.JoinAvailable(msg.session, rssi), [change]

    def _on_notice(self, incoming: Incoming, now: float) -> list[Action]:
        msg: m.JoinNotice = incoming.message  # type: ignore[assignment]
        swarm = self.swarm
        if swarm is not None and swarm.session == msg.session:
            return self._joined(swarm, msg.slot_ms)  # our Joined was lost: say it again
        if self.candidate_of != (msg.session, incoming.sender) or self.sequence.state != RobotState.ORGANIZING:
            return []  # not our master's notice (or we gave up waiting): no answer, the master will release
        self.candidate_of = None
        self.swarm = swarm = Swarm(msg.session, msg.pan_id, incoming.sender, msg.number)
        self._deadline = now + self.config.master_silence_s
        change = self.sequence.enter(
            RobotState.SLAVE_DRIVING, session=msg.session, pan_id=msg.pan_id, number=msg.number
        )
        return [change, ConfigurePan(msg.pan_id), SwarmChanged.of(swarm), *self._joined(swarm, msg.slot_ms)]

    @staticmethod
    def _joined(swarm: Swarm, slot_ms: int) -> list[Action]:
        # the pause is there even when it is 0: the runtime yields to the loop once, as it always did
        joined = Send(swarm.master, m.Joined(swarm.session, swarm.number), dst_pan=swarm.pan_id)
        return [Pause(reply_delay_s(swarm.number, slot_ms)), joined]

    def _on_not_participating(self, incoming: Incoming, now: float) -> list[Action]:
        session = incoming.message.session_id
        if self.candidate_of is not None and self.candidate_of[0] == session:
            return self._leave(reason="not selected")
        if self.swarm is not None and self.swarm.session == session and self.swarm.number:
            return self._leave(reason="released by the master")
        return []

    def _on_roster(self, incoming: Incoming, now: float) -> list[Action]:
        msg: m.Roster = incoming.message  # type: ignore[assignment]
        swarm = self.swarm
        if swarm is None or swarm.session != msg.session:
            return []
        actions: list[Action] = []
        if not swarm.number:
            followed, actions = self._on_rival_roster(swarm, incoming.sender, msg, now)
            if not followed:
                return actions  # our own roster, or a master this robot need not follow: it stays the master
        if incoming.sender != swarm.master:
            if incoming.sender in self._former_masters or incoming.sender not in swarm.members:
                return actions  # a late roster of a master that handed over, or not of this swarm's robots
            # the master's role moved while we missed the handover: the roster's sender has it now
            old_chain = (swarm.master, *swarm.members)
            swarm.master = incoming.sender
            swarm.members = tuple(a for a in msg.members)
            if self.me not in msg.members:
                return [*actions, *self._leave(reason="not in the new master's roster")]
            return [*actions, *self._follow_handover(swarm, None, now, old_chain=old_chain, learned="roster")]
        if self.me not in msg.members:
            return [*actions, *self._leave(reason="not in the master's roster")]
        changed = swarm.members != msg.members
        swarm.members = msg.members
        swarm.number = msg.members.index(self.me) + 1
        if changed:
            actions.append(SwarmChanged.of(swarm))
        self._deadline = now + self.config.master_silence_s
        return actions

    def _on_rival_roster(self, swarm: Swarm, sender: int, roster: m.Roster, now: float) -> tuple[bool, list[Action]]:
        """Master side: another robot announces a roster of our session, so the swarm has two masters
        (``rival_master`` decides which one stays). True when this robot gave up the role for the sender's
        and is now a member that takes the roster as any member does."""
        if self._dissolving:
            return False, []  # already giving the role up
        unaccepted = self._unaccepted
        attempt = unaccepted if unaccepted is not None and unaccepted.session == swarm.session else None
        target = attempt.chain[0] if attempt else None
        listed = self.me in roster.members
        verdict = rival_master(self.me, sender, swarm.members, self._former_masters, target, listed)
        if verdict is Rival.IGNORE or (verdict is Rival.KEEP and (swarm.session, sender) in self._outranked):
            return False, []
        since = round(now - self._attempted_at, 3) if attempt else None
        detail = {"session": swarm.session, "rival": sender, "verdict": verdict.value, "since_handover_s": since}
        actions: list[Action] = [Log("two_masters", detail)]
        if verdict is Rival.KEEP:
            self._outranked.add((swarm.session, sender))
            return False, actions
        actions.append(StopRoster())
        if verdict is Rival.LEAVE:
            return False, [*actions, self._dissolve_later(swarm, "a rival master")]
        if attempt is not None and verdict is Rival.FOLLOW:
            return True, [*actions, *self._follow_handover(swarm, attempt, now, learned="roster")]
        old_chain = (swarm.master, *swarm.members)
        swarm.master, swarm.members = sender, roster.members
        return True, [*actions, *self._follow_handover(swarm, None, now, old_chain=old_chain, learned="rival_roster")]

    def _on_handover(self, incoming: Incoming, now: float) -> list[Action]:
        """Member side: the master hands its role over (to us: take it and accept; to another: follow)."""
        msg: m.MasterHandover = incoming.message  # type: ignore[assignment]
        swarm = self.swarm
        if swarm is None or swarm.session != msg.session or self.me not in msg.chain:
            return []
        if msg.chain[0] != self.me:
            if swarm.number and incoming.sender == swarm.master:
                return self._follow_handover(swarm, msg, now)
            return []
        actions = self._take_over(swarm, msg) if swarm.number and incoming.sender == swarm.master else []
        if not swarm.number and not incoming.rx.frame.is_broadcast:
            actions.append(Send(incoming.sender, m.HandoverAccepted(msg.session), dst_pan=swarm.pan_id))
        return actions

    def _on_disperse(self, incoming: Incoming, now: float) -> list[Action]:
        msg: m.Disperse = incoming.message  # type: ignore[assignment]
        swarm = self.swarm
        if swarm is not None and swarm.session == msg.session and swarm.number:
            number = swarm.number
            actions = self._leave(reason="dispersed")
        elif self._last_left == msg.session:
            number, actions = 1, []  # already home: the master missed our answer
        else:
            return []
        return [*actions, *self._answer(incoming, m.Dispersed(msg.session), reply_delay_s(number, msg.slot_ms))]

    def _leave(self, reason: str) -> list[Action]:
        session = self.swarm.session if self.swarm else (self.candidate_of or (None,))[0]
        actions: list[Action] = [] if self.swarm is None else [SwarmChanged(None)]
        self.swarm = None
        self.candidate_of = None
        self._last_left = session
        if self.sequence.state in (RobotState.ORGANIZING, RobotState.SLAVE_DRIVING):
            actions.append(self.sequence.enter(RobotState.WAITING, session=session, reason=reason))
        if self.pan_id != self.config.waiting_pan:
            actions.append(ConfigurePan(self.config.waiting_pan))
        return actions

    def _answer(self, incoming: Incoming, reply: m.SwarmMessage, delay_s: float) -> list[Action]:
        answer = Answer(incoming.sender, reply, incoming.rx.frame.src_pan)
        return [Pause(delay_s), answer] if delay_s else [answer]

    def answer_sent(self, answer: Answer, result: TxResult) -> list[Action]:
        """The MAC's report on an ``Answer``: nothing when it went out, else another attempt after a pause at a
        random moment, or, after ``ANSWER_ATTEMPTS``, the give-up recorded."""
        if result.ok:
            return []
        name, status = type(answer.message).__name__, result.status.value
        if answer.attempt == ANSWER_ATTEMPTS - 1:
            # no retry follows the last attempt: record the give-up, not a retry, and do not pause for nothing
            return [Log("answer_failed", {"type": name, "status": status, "attempts": ANSWER_ATTEMPTS})]
        # the MAC gave up (a crowded channel: many answer one broadcast); an open step such as the
        # scan is not retried by the master for us, so try again a little later, at a random moment
        retry = Log("answer_retry", {"type": name, "status": status, "attempt": answer.attempt})
        return [retry, Pause(float(self.rng.uniform(0.002, 0.02))), replace(answer, attempt=answer.attempt + 1)]

    def _user_now(self) -> int:
        return self.user if self.sequence.user_connected else 0

    # == timers ========================================================================================

    def get_timer(self) -> float | None:
        """When this robot gives up waiting for its master (None: it waits for none)."""
        waiting_for_master = self.candidate_of is not None or (self.swarm is not None and self.swarm.number)
        return self._deadline if waiting_for_master else None

    def hub_absent(self, now: float) -> None:
        """No air at all (the hub died or restarts): the master's silence means nothing yet."""
        self._deadline = max(self._deadline, now + self.config.master_silence_s)

    def handle_timer(self, now: float) -> list[Action]:
        """The timer fired: a candidate never told the result, or a member whose master went silent, leaves."""
        if self.candidate_of is not None:
            return self._leave(reason="no result notice")
        swarm = self.swarm
        if swarm is None or not swarm.number or now <= self._deadline:
            return []
        # tell the master, in case only its rosters were lost: it must stop counting us
        gone = Send(swarm.master, m.Dispersed(swarm.session), dst_pan=BROADCAST)
        return [*self._leave(reason="master silent"), gone]


_HANDLERS: dict[type[m.SwarmMessage], Callable[[FormationCore, Incoming, float], list[Action]]] = {
    m.Scan: FormationCore._on_scan,
    m.JoinQuery: FormationCore._on_query,
    m.JoinNotice: FormationCore._on_notice,
    m.NotParticipating: FormationCore._on_not_participating,
    m.Roster: FormationCore._on_roster,
    m.Disperse: FormationCore._on_disperse,
    m.Dispersed: FormationCore._on_member_left,
    m.MasterHandover: FormationCore._on_handover,
}
RESPONSES = (m.ScanReply, m.JoinAvailable, m.JoinUnavailable, m.Joined, m.Dispersed, m.HandoverAccepted)
"""Messages that only ever answer a master's step; outside a step they are late."""


def _each(actions: Iterable[Action], first: Done | None = None) -> Procedure[Done | None]:
    """Yield ``actions`` one by one inside a procedure; returns the last ``Done`` (``first`` when none)."""
    done = first
    for action in actions:
        done = yield action
    return done


def _may_join(incoming: Incoming, region_dbm: int) -> bool:
    """A scan reply of a robot that Table 1 (``may_join``, as the robot will judge the query) lets join, and that
    is waiting (any other state answers busy): the link's loss is the same both ways, up to its fading."""
    msg = incoming.message
    if not isinstance(msg, m.ScanReply) or msg.state != RobotState.WAITING:
        return False
    return may_join(msg.user, round(incoming.rx.rssi_dbm), region_dbm) is None


def _free_reply(message: m.SwarmMessage) -> bool:
    """A scan reply of a robot not in a swarm: a candidate for the joining query."""
    return isinstance(message, m.ScanReply) and message.state in _FREE


def _releases(session: int, robots: set[int]) -> list[Action]:
    # sent as answers are: a notice the MAC failed to deliver goes again after a random pause (``answer_sent``).
    # Nothing else tells a candidate it was not chosen; in a crowded channel (50 robots) a lost one left a robot
    # organizing for its whole candidate timeout, after the swarm had formed and even been dispersed
    return [Answer(addr, m.NotParticipating(session), BROADCAST) for addr in sorted(robots)]


def _answers(step: StepResult) -> tuple[dict[int, float], dict[str, list[int]]]:
    """Available robots with the master's closeness estimate, and refusals by reason."""
    available: dict[int, float] = {}
    refused: dict[str, list[int]] = {}
    for addr, incoming in step.responses.items():
        msg = incoming.message
        if isinstance(msg, m.JoinAvailable):
            # both directions of the link, averaged: less shadowing noise in the ranking
            available[addr] = (incoming.rx.rssi_dbm + msg.rssi_dbm) / 2
        elif isinstance(msg, m.JoinUnavailable):
            reason = m.Refusal(msg.reason).name.lower() if msg.reason in iter(m.Refusal) else "unknown"
            refused.setdefault(reason, []).append(addr)
    return available, {reason: sorted(addrs) for reason, addrs in refused.items()}  # not in arrival order


def _last_arrival(step: StepResult, t0: float) -> float:
    """Seconds from the request to the last member's Joined (the last member switched)."""
    return max(i.received_at for i in step.responses.values()) - t0
