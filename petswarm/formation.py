"""Forming and dispersing the swarm network (paper section 3.4, Fig. 8), both sides of it.

Master side: ``organize(count)`` runs scan -> joining query -> result notices over the emulated radio,
each a step of the message-processing manager with deadlines and retries, then announces the roster
on the new PAN; ``disperse()`` sends every member home. Member side: ``on_message`` answers the
master's requests per Table 1 and switches PAN when chosen. A member that hears no roster for a while,
or that is left out of one, returns to waiting: membership is never believed by a robot that the master
does not count. A master that hears a roster of its own swarm from another robot settles which of the
two stays master (``decisions.rival_master``).

Frames to a particular robot use the broadcast PAN ID (0xFFFF) with its short address, so they reach it
whether it is still on the waiting PAN or already on the swarm's; answers go to the sender's PAN.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from petswarm import clock
from petswarm import messages as m
from petswarm.decisions import Rival, choose_pan, may_join, reply_delay_s, rival_master, select_members
from petswarm.exchange import MessageProcessingManager, StepResult, StepTiming
from petswarm.rf import Incoming, RfCommunicationManager
from petswarm.sequence import DRIVING, EventLog, RobotState, SequenceManager
from radio_hub.interface import BROADCAST
from radio_hub.mac import max_payload

PROTOCOLS = ("paper", "slotted")
MAX_MEMBERS = 32
"""Members of one swarm besides the master: the roster lists them all in one frame."""
MAX_LISTED = 30
MEMBER_MISSES = 3
"""Rounds of the master in a row a member may leave its start sign unanswered before it is dropped."""
ANSWER_ATTEMPTS = 3

"""Sends of one answer when the MAC reports a failure (channel access failure or no ACK)."""

"""Robots a joining query can list as pending in one frame."""

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


class NetworkFormation:
    """Organizes (as master) or joins (as a waiting robot) a swarm network."""

    def __init__(
        self,
        rf: RfCommunicationManager,
        sequence: SequenceManager,
        mpm: MessageProcessingManager,
        log: EventLog,
        config: FormationConfig,
        rng: np.random.Generator,
        user: int = 0,
        on_change: Callable[[Swarm | None], None] = lambda swarm: None,
    ) -> None:
        self.rf, self.sequence, self.mpm, self.log = rf, sequence, mpm, log
        self.config = config
        self.rng = rng
        self.user = user
        self.swarm: Swarm | None = None
        self.on_change = on_change
        """Called with the swarm whenever this robot joins one, its members change, or it leaves (None)."""
        self.on_handover: Callable[[tuple[int, ...], m.MasterHandover | None], None] = lambda chain, msg: None
        """Called after the master's role moved within this robot's swarm (this robot gave it, took it, or
        saw it move), with the chain before the handover and the handover message (None when a missed
        handover was learned from the new master's roster)."""
        self._former_masters: set[int] = set()
        """Masters of this swarm that handed over: their late rosters must not take the role back."""
        self._unaccepted: m.MasterHandover | None = None
        """The last handover this master sent and saw no acceptance of (yet): if its target's roster comes,
        the target took the role and only the acceptance was lost, so this robot follows it after all."""
        self._attempted_at = 0.0
        self._outranked: set[tuple[int, int]] = set()
        """(session, rival) of rival masters this master outranks and has already recorded."""
        self.candidate_of: tuple[int, int] | None = None
        """(session, master) while this robot said 'available' and waits for the result."""
        self.organizations: list[dict[str, Any]] = []
        self._last_left: int | None = None
        self._deadline = 0.0
        self._roster_task: asyncio.Task[None] | None = None
        self._busy = asyncio.Lock()
        self._member_lock = asyncio.Lock()
        self._misses: dict[int, int] = {}
        self._dissolving: asyncio.Task[None] | None = None

    @property
    def me(self) -> int:
        """This robot's short address."""
        return self.rf.radio.identity.short_addr

    # == master side ==================================================================================

    async def organize(self, count: int, protocol: str | None = None) -> dict[str, Any]:
        """Form a swarm of up to ``count`` other robots; returns the organization's figures."""
        if not 1 <= count <= MAX_MEMBERS:
            raise FormationError(
                f"a swarm has 1 to {MAX_MEMBERS} members besides the master (its roster fills a frame)"
            )
        if self._busy.locked():
            raise FormationError("already organizing or dispersing")
        async with self._busy:
            if self.sequence.state == RobotState.MASTER_DRIVING:
                raise FormationError("this robot already leads a swarm: disperse it first")
            if self.sequence.state not in DRIVING:
                raise FormationError(
                    f"robot is {self.sequence.state.label}: only a robot driving with its user can organize"
                )
            return await self._organize(count, protocol or self.config.protocol)

    async def _organize(self, count: int, protocol: str) -> dict[str, Any]:
        session = int(self.rng.integers(1, 0xFFFF))
        slot = self.config.slot(protocol)
        t0 = clock.now()
        self.sequence.transition(RobotState.ORGANIZING, session=session, requested=count, protocol=protocol)
        steps: dict[str, StepResult] = {}
        try:
            steps["scan"] = await self._scan(session, slot)
            replies = {a: i.message for a, i in steps["scan"].responses.items() if isinstance(i.message, m.ScanReply)}
            # everyone not already in a swarm is asked: each decides with Table 1 (a robot connected
            # to another user refuses on its own)
            candidates = {a for a, r in replies.items() if r.state in _FREE}

            pan = choose_pan(self.rng, {r.pan_id for r in replies.values()} | {self.config.waiting_pan})
            steps["query"] = await self._query(session, slot, candidates)
            available, refused = _answers(steps["query"])
            chosen = select_members(available, count)
            await self.rf.radio.configure(pan_id=pan)
            await self._release(session, set(available) - set(chosen))
            steps["notice"] = await self._notify(session, slot, pan, chosen)
            members = tuple(a for a in chosen if a in steps["notice"].responses)
            await self._release(session, set(chosen) - set(members))
        except BaseException:
            await self._abandon(session)
            raise
        elapsed = _last_arrival(steps["notice"], t0) if members else clock.now() - t0
        if not members:
            await self.rf.radio.configure(pan_id=self.config.waiting_pan)
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
        self._settle(session, pan, members, figures)
        return figures

    def _settle(self, session: int, pan: int, members: tuple[int, ...], figures: dict[str, Any]) -> None:
        self.organizations.append(figures)
        if not members:
            self.log.record("organized", **figures)
            self.sequence.restore_driving(session=session, reason="no robot joined")
            return

        self.swarm = Swarm(session, pan, self.me, 0, members)
        self._misses = {}

        self.sequence.transition(RobotState.MASTER_DRIVING, session=session, members=list(members))
        self.log.record("organized", **figures)
        self.on_change(self.swarm)
        self._roster_task = asyncio.get_running_loop().create_task(self._announce_roster())

    async def _abandon(self, session: int) -> None:
        self.log.record("organize_failed", session=session)
        if self.sequence.state == RobotState.ORGANIZING:
            self.sequence.restore_driving(session=session, reason="organizing failed")
        try:
            await self.rf.radio.configure(pan_id=self.config.waiting_pan)
        except Exception as err:  # the hub may be the reason organizing failed
            self.log.record("error", where="abandon", error=str(err))

    async def _scan(self, session: int, slot: int) -> StepResult:
        async def send(_: set[int] | None) -> None:
            await self.rf.send(BROADCAST, m.Scan(session, self.user, slot), dst_pan=BROADCAST, ack=False)

        timing = self._timing(slot, 8)
        return await self.mpm.step("scan", session, (m.ScanReply,), send, None, timing)

    async def _query(self, session: int, slot: int, candidates: set[int]) -> StepResult:
        async def send(missing: set[int] | None) -> None:
            pending = tuple(sorted(missing or candidates))
            if len(pending) > MAX_LISTED:
                pending = ()  # too many to list in one frame: every free robot answers
            query = m.JoinQuery(session, self.user, self.config.min_rssi_dbm, slot, pending)
            await self.rf.send(BROADCAST, query, dst_pan=BROADCAST, ack=False)

        timing = self._timing(slot, len(candidates))
        return await self.mpm.step("query", session, (m.JoinAvailable, m.JoinUnavailable), send, candidates, timing)

    async def _notify(self, session: int, slot: int, pan: int, chosen: list[int]) -> StepResult:
        async def send(missing: set[int] | None) -> None:
            for number, addr in enumerate(chosen, start=1):
                if missing is None or addr in missing:
                    notice = m.JoinNotice(session, pan, len(chosen) + 1, number, slot)
                    await self.rf.send(addr, notice, dst_pan=BROADCAST)

        timing = self._timing(slot, len(chosen))
        return await self.mpm.step("notice", session, (m.Joined,), send, set(chosen), timing)

    async def _release(self, session: int, robots: set[int]) -> None:
        for addr in sorted(robots):
            await self.rf.send(addr, m.NotParticipating(session), dst_pan=BROADCAST)

    def _timing(self, slot: int, responders: int) -> StepTiming:
        # the slotted protocol's deadline grows with the slots it asked responders to use; since every
        # answer has a slot, an open step (the scan) can end once all eight slots and a margin have
        # passed without a new answer, instead of always waiting out the deadline
        base = self.config.step
        if not slot:
            return base
        slots_s = min(responders, 8) * slot / 1000.0
        return StepTiming(base.deadline_s + slots_s, base.max_retries, quiet_s=8 * slot / 1000.0 + 0.01)

    async def _announce_roster(self) -> None:
        while self.swarm is not None and self.sequence.state == RobotState.MASTER_DRIVING:
            swarm = self.swarm
            try:
                await self.rf.send(BROADCAST, m.Roster(swarm.session, swarm.members), ack=False)
            except Exception as err:  # keep announcing: members leave after 2 s without a roster
                self.log.record("error", where="roster", error=f"{type(err).__name__}: {err}")
            await asyncio.sleep(self.config.roster_interval_s)

    async def hand_over(
        self, chain: tuple[int, ...], mode: str, shape: str, spacing: float, mirrored: int, kept: int, owner: str
    ) -> bool:
        """Table 3's Change column, the old master's side: make ``chain[0]`` the master of this swarm, with
        ``chain[1:]`` as its members in order. A step of the message-processing manager takes the handover
        to the new master (deadline, retries, recorded) and waits for its acceptance; then a broadcast tells
        every member (one that misses it learns from the new master's rosters) and this robot becomes a
        slave. False when the new master never accepted: this robot is still the master; if the new master
        took the role all the same (only its acceptance was lost), its first roster heard here makes this
        robot follow the handover after all (``_on_rival_roster``)."""
        async with self._busy:
            swarm = self.swarm
            if swarm is None or swarm.number or self.sequence.state != RobotState.MASTER_DRIVING:
                raise FormationError(f"robot is {self.sequence.state.label}, not the master of a swarm")
            if sorted(chain) != sorted((swarm.master, *swarm.members)) or chain[0] == self.me:
                raise FormationError(f"handover chain {list(chain)} is not a reordering of the swarm with a new master")
            msg = m.MasterHandover(swarm.session, swarm.pan_id, chain, mode, shape, spacing, mirrored, kept, owner)
            if len(msg.encode()) > max_payload(pan_compressed=False):
                raise FormationError(f"a handover of {len(chain)} robots does not fit one frame")
            new = chain[0]

            async def send(_: set[int] | None) -> None:
                await self.rf.send(new, msg, dst_pan=BROADCAST)

            # remembered before the first send: the target may take the role however the step ends
            self._unaccepted, self._attempted_at = msg, clock.now()
            step = await self.mpm.step("handover", swarm.session, (m.HandoverAccepted,), send, {new}, self.config.step)
            if swarm.number:
                return True  # the new master's roster came before its acceptance: followed already
            if self.swarm is not swarm:
                return False  # a rival master made this robot give the swarm up meanwhile
            if new not in step.responses:
                self.log.record("handover_failed", session=swarm.session, to=new, retries=step.retries)
                return False
            if self._roster_task is not None:
                self._roster_task.cancel()
            try:
                await self.rf.send(BROADCAST, msg, ack=False)
            except Exception as err:  # the members will learn it from the new master's rosters
                self.log.record("error", where="handover_broadcast", error=f"{type(err).__name__}: {err}")
            if not swarm.number:  # the new master's roster may have come while the broadcast was on the air
                self._follow_handover(swarm, msg, retries=step.retries)
            return True

    def _follow_handover(self, swarm: Swarm, msg: m.MasterHandover | None, **detail: Any) -> None:
        """Take the new order of a handover as a member (the old master, or a member told or learning it)."""
        chain = msg.chain if msg is not None else (swarm.master, *swarm.members)
        old_chain = (swarm.master, *swarm.members) if msg is not None else detail.pop("old_chain")
        old_master = old_chain[0]
        self._former_masters = (self._former_masters | {old_master}) - {chain[0]}
        self._unaccepted = None
        swarm.master, swarm.members, swarm.number = chain[0], chain[1:], chain.index(self.me)
        self._misses = {}
        self._deadline = clock.now() + self.config.master_silence_s
        self.log.record("handover", session=swarm.session, frm=old_master, to=chain[0], number=swarm.number, **detail)
        if self.sequence.state == RobotState.MASTER_DRIVING:
            self.sequence.transition(RobotState.SLAVE_DRIVING, cause="handover", master=chain[0], number=swarm.number)
        self.on_change(swarm)
        self.on_handover(old_chain, msg)

    async def _on_handover(self, incoming: Incoming) -> None:
        """Member side: the master hands its role over (to us: take it and accept; to another: follow)."""
        msg: m.MasterHandover = incoming.message  # type: ignore[assignment]
        swarm = self.swarm
        if swarm is None or swarm.session != msg.session or self.me not in msg.chain:
            return
        if msg.chain[0] == self.me:
            if swarm.number and incoming.sender == swarm.master:
                self._take_over(swarm, msg)
            if not swarm.number and not incoming.rx.frame.is_broadcast:
                await self.rf.send(incoming.sender, m.HandoverAccepted(msg.session), dst_pan=swarm.pan_id)
        elif swarm.number and incoming.sender == swarm.master:
            self._follow_handover(swarm, msg)

    def _take_over(self, swarm: Swarm, msg: m.MasterHandover) -> None:
        """Become the swarm's master: its rosters, member tracking and dispersal are ours from now."""
        old_chain = (swarm.master, *swarm.members)
        # the transition first: if Fig. 4 refused it, the swarm view must stay as it was
        self.sequence.transition(
            RobotState.MASTER_DRIVING, cause="handover", old_master=old_chain[0], members=list(msg.chain[1:])
        )
        self._former_masters = (self._former_masters | {swarm.master}) - {self.me}
        swarm.master, swarm.members, swarm.number = self.me, msg.chain[1:], 0
        self._misses = {}
        # dispersal returns the new master to the driving mode the user has just chosen
        self.sequence.previous_driving = RobotState.LEADING if msg.mode == "leading" else RobotState.FOLLOWING
        self.log.record("handover", session=swarm.session, frm=old_chain[0], to=self.me, number=0)
        self.on_change(swarm)
        self.on_handover(old_chain, msg)
        self._roster_task = asyncio.get_running_loop().create_task(self._announce_roster())

    async def disperse(self, protocol: str | None = None) -> dict[str, Any]:
        """End the swarm: every member back to waiting, this robot back to its driving state."""
        async with self._busy:
            swarm = self.swarm
            if swarm is None or self.sequence.state != RobotState.MASTER_DRIVING:
                raise FormationError(f"robot is {self.sequence.state.label}, not the master of a swarm")
            slot = self.config.slot(protocol)
            t0 = clock.now()

            async def send(missing: set[int] | None) -> None:
                for addr in swarm.members:
                    if missing is None or addr in missing:
                        await self.rf.send(addr, m.Disperse(swarm.session, slot), dst_pan=BROADCAST)

            timing = self._timing(slot, len(swarm.members))
            try:
                step = await self.mpm.step("disperse", swarm.session, (m.Dispersed,), send, set(swarm.members), timing)
            finally:
                # whatever happened on the air, this robot is no longer a master
                self.swarm = None
                self.on_change(None)
                if self._roster_task is not None:
                    self._roster_task.cancel()
                restored = self.sequence.restore_driving(session=swarm.session)
            await self.rf.radio.configure(pan_id=self.config.waiting_pan)
            figures = {
                "session": swarm.session,
                "disperse_time_s": round(clock.now() - t0, 6),
                "retries": step.retries,
                "members": list(swarm.members),
                "unconfirmed": sorted(step.missing),
                "restored": restored.label,
            }
            self.log.record("dispersed", **figures)
            return figures

    # == member side ==================================================================================

    @staticmethod
    def handles(message: m.SwarmMessage) -> bool:
        """True for the messages ``on_message`` acts on."""
        return type(message) in _MEMBER_HANDLERS

    async def on_message(self, incoming: Incoming) -> None:
        """Act on a formation message. One at a time: a handler's state change and the PAN switch it
        implies complete before the next message is looked at, so no interleaving can leave a robot on
        the wrong PAN."""
        handler = _MEMBER_HANDLERS.get(type(incoming.message))
        if handler is not None:
            async with self._member_lock:
                await handler(self, incoming)

    async def _on_member_left(self, incoming: Incoming) -> None:
        """Master side: a member that gave up on us (it heard no roster) says so; stop counting it."""
        swarm = self.swarm
        if swarm is None or swarm.number or swarm.session != incoming.message.session_id:
            return
        self._drop_member(incoming.sender, "member_left")

    def note_answers(self, answered: set[int], silent: set[int]) -> None:
        """Master side: who answered our IR start sign. A member silent for ``MEMBER_MISSES`` of our
        rounds in a row is gone (dead, or out of reach): the roster drops it and the token skips it."""
        swarm = self.swarm
        if swarm is None or swarm.number:
            return
        for addr in answered:
            self._misses.pop(addr, None)
        for addr in silent & set(swarm.members):
            self._misses[addr] = self._misses.get(addr, 0) + 1
            if self._misses[addr] >= MEMBER_MISSES:
                self._drop_member(addr, "member_lost")

    def _drop_member(self, addr: int, why: str) -> None:
        swarm = self.swarm
        if swarm is None or addr not in swarm.members:
            return
        swarm.members = tuple(a for a in swarm.members if a != addr)
        self._misses.pop(addr, None)
        self.log.record(why, session=swarm.session, member=addr)
        if swarm.members:
            self.on_change(swarm)
        else:  # the last member is gone: the swarm is over, the master drives with its user again
            self._dissolving = asyncio.get_running_loop().create_task(self._dissolve(swarm, "every member is gone"))

    async def _dissolve(self, swarm: Swarm, reason: str) -> None:
        async with self._busy:
            if self.swarm is not swarm:
                return
            self.swarm = None
            self.on_change(None)
            if self._roster_task is not None:
                self._roster_task.cancel()
            self.sequence.restore_driving(session=swarm.session, reason=reason)
            try:
                await self.rf.radio.configure(pan_id=self.config.waiting_pan)
            except Exception as err:  # the hub may be away; the wanted PAN applies when it is back
                self.log.record("error", where="dissolve", error=f"{type(err).__name__}: {err}")

    async def _on_scan(self, incoming: Incoming) -> None:
        msg: m.Scan = incoming.message  # type: ignore[assignment]
        reply = m.ScanReply(msg.session, int(self.sequence.state), self.rf.radio.identity.pan_id, self._user_now())
        await self._answer(incoming, reply, reply_delay_s(self.me, msg.slot_ms))

    async def _on_query(self, incoming: Incoming) -> None:
        msg: m.JoinQuery = incoming.message  # type: ignore[assignment]
        if msg.pending and self.me not in msg.pending:
            return
        if not msg.pending and self.candidate_of is None and self.sequence.state != RobotState.WAITING:
            return  # an unlisted query asks the free robots only
        answer = self._judge_query(msg, incoming)
        await self._answer(incoming, answer, reply_delay_s(self.me, msg.slot_ms, msg.pending))

    def _judge_query(self, msg: m.JoinQuery, incoming: Incoming) -> m.SwarmMessage:
        rssi = round(incoming.rx.rssi_dbm)
        state = self.sequence.state
        if self.candidate_of == (msg.session, incoming.sender):
            return m.JoinAvailable(msg.session, rssi)  # a retried query: same answer
        refusal = may_join(self._user_now(), rssi, msg.min_rssi_dbm)
        if refusal != m.Refusal.CONNECTED_TO_USER and state != RobotState.WAITING:
            refusal = m.Refusal.BUSY  # taken by another master, or already in a swarm
        if refusal is not None:
            return m.JoinUnavailable(msg.session, int(refusal))
        self.candidate_of = (msg.session, incoming.sender)
        self._deadline = clock.now() + self.config.candidate_timeout_s
        self.sequence.transition(RobotState.ORGANIZING, session=msg.session, master=incoming.sender)
        return m.JoinAvailable(msg.session, rssi)

    async def _on_notice(self, incoming: Incoming) -> None:
        msg: m.JoinNotice = incoming.message  # type: ignore[assignment]
        swarm = self.swarm
        if swarm is not None and swarm.session == msg.session:
            await self._send_joined(swarm, msg.slot_ms)  # our Joined was lost: say it again
            return
        if self.candidate_of != (msg.session, incoming.sender) or self.sequence.state != RobotState.ORGANIZING:
            return  # not our master's notice (or we gave up waiting): no answer, the master will release
        self.candidate_of = None
        self.swarm = Swarm(msg.session, msg.pan_id, incoming.sender, msg.number)
        self._deadline = clock.now() + self.config.master_silence_s
        self.sequence.transition(RobotState.SLAVE_DRIVING, session=msg.session, pan_id=msg.pan_id, number=msg.number)
        await self.rf.radio.configure(pan_id=msg.pan_id)
        self.on_change(self.swarm)
        await self._send_joined(self.swarm, msg.slot_ms)

    async def _send_joined(self, swarm: Swarm, slot_ms: int) -> None:
        await asyncio.sleep(reply_delay_s(swarm.number, slot_ms))
        await self.rf.send(swarm.master, m.Joined(swarm.session, swarm.number), dst_pan=swarm.pan_id)

    async def _on_not_participating(self, incoming: Incoming) -> None:
        session = incoming.message.session_id
        if self.candidate_of is not None and self.candidate_of[0] == session:
            await self._leave(reason="not selected")
        elif self.swarm is not None and self.swarm.session == session and self.swarm.number:
            await self._leave(reason="released by the master")

    async def _on_roster(self, incoming: Incoming) -> None:
        msg: m.Roster = incoming.message  # type: ignore[assignment]
        swarm = self.swarm
        if swarm is None or swarm.session != msg.session:
            return
        if not swarm.number and not self._on_rival_roster(swarm, incoming.sender, msg):
            return  # our own roster, or a master this robot need not follow: it stays the master
        if incoming.sender != swarm.master:
            if incoming.sender in self._former_masters or incoming.sender not in swarm.members:
                return  # a late roster of a master that handed over, or not of this swarm's robots
            # the master's role moved while we missed the handover: the roster's sender has it now
            old_chain = (swarm.master, *swarm.members)
            swarm.master = incoming.sender
            swarm.members = tuple(a for a in msg.members)
            if self.me not in msg.members:
                await self._leave(reason="not in the new master's roster")
                return
            self._follow_handover(swarm, None, old_chain=old_chain, learned="roster")
            return
        if self.me not in msg.members:
            await self._leave(reason="not in the master's roster")
            return
        changed = swarm.members != msg.members
        swarm.members = msg.members
        swarm.number = msg.members.index(self.me) + 1
        if changed:
            self.on_change(swarm)
        self._deadline = clock.now() + self.config.master_silence_s

    def _on_rival_roster(self, swarm: Swarm, sender: int, roster: m.Roster) -> bool:
        """Master side: another robot announces a roster of our session, so the swarm has two masters
        (``rival_master`` decides which one stays). True when this robot gave up the role for the sender's
        and is now a member that takes the roster as any member does."""
        if self._dissolving is not None and not self._dissolving.done():
            return False  # already giving the role up
        unaccepted = self._unaccepted
        attempt = unaccepted if unaccepted is not None and unaccepted.session == swarm.session else None
        target = attempt.chain[0] if attempt else None
        listed = self.me in roster.members
        verdict = rival_master(self.me, sender, swarm.members, self._former_masters, target, listed)
        if verdict is Rival.IGNORE or (verdict is Rival.KEEP and (swarm.session, sender) in self._outranked):
            return False
        since = round(clock.now() - self._attempted_at, 3) if attempt else None
        self.log.record(
            "two_masters", session=swarm.session, rival=sender, verdict=verdict.value, since_handover_s=since
        )
        if verdict is Rival.KEEP:
            self._outranked.add((swarm.session, sender))
            return False
        if self._roster_task is not None:
            self._roster_task.cancel()
        if verdict is Rival.LEAVE:
            self._dissolving = asyncio.get_running_loop().create_task(self._dissolve(swarm, "a rival master"))
            return False
        if attempt is not None and verdict is Rival.FOLLOW:
            self._follow_handover(swarm, attempt, learned="roster")
        else:
            old_chain = (swarm.master, *swarm.members)
            swarm.master, swarm.members = sender, roster.members
            self._follow_handover(swarm, None, old_chain=old_chain, learned="rival_roster")
        return True

    async def _on_disperse(self, incoming: Incoming) -> None:
        msg: m.Disperse = incoming.message  # type: ignore[assignment]
        swarm = self.swarm
        if swarm is not None and swarm.session == msg.session and swarm.number:
            number = swarm.number
            await self._leave(reason="dispersed")
        elif self._last_left == msg.session:
            number = 1  # already home: the master missed our answer
        else:
            return
        await self._answer(incoming, m.Dispersed(msg.session), reply_delay_s(number, msg.slot_ms))

    async def _leave(self, reason: str) -> None:
        session = self.swarm.session if self.swarm else (self.candidate_of or (None,))[0]
        if self.swarm is not None:
            self.on_change(None)
        self.swarm = None
        self.candidate_of = None
        self._last_left = session
        if self.sequence.state in (RobotState.ORGANIZING, RobotState.SLAVE_DRIVING):
            self.sequence.transition(RobotState.WAITING, session=session, reason=reason)
        if self.rf.radio.identity.pan_id != self.config.waiting_pan:
            await self.rf.radio.configure(pan_id=self.config.waiting_pan)

    async def _answer(self, incoming: Incoming, reply: m.SwarmMessage, delay_s: float) -> None:
        if delay_s:
            await asyncio.sleep(delay_s)
        for attempt in range(ANSWER_ATTEMPTS):
            result = await self.rf.send(incoming.sender, reply, dst_pan=incoming.rx.frame.src_pan)
            if result.ok:
                return
            if attempt == ANSWER_ATTEMPTS - 1:
                # no retry follows the last attempt: record the give-up, not a retry, and do not pause for nothing
                self.log.record(
                    "answer_failed", type=type(reply).__name__, status=result.status.value, attempts=ANSWER_ATTEMPTS
                )
                return
            # the MAC gave up (a crowded channel: many answer one broadcast); an open step such as the
            # scan is not retried by the master for us, so try again a little later, at a random moment
            self.log.record("answer_retry", type=type(reply).__name__, status=result.status.value, attempt=attempt)
            await asyncio.sleep(float(self.rng.uniform(0.002, 0.02)))

    def _user_now(self) -> int:
        return self.user if self.sequence.user_connected else 0

    async def watch(self) -> None:
        """Member-side timeouts: a candidate never told the result, a member whose master went silent."""
        while True:
            await asyncio.sleep(0.05)
            waiting_for_master = self.candidate_of is not None or (self.swarm is not None and self.swarm.number)
            if not self.rf.radio.hub_present:
                # no air at all (the hub died or restarts): the master's silence means nothing yet
                self._deadline = max(self._deadline, clock.now() + self.config.master_silence_s)
                continue
            if not waiting_for_master or clock.now() <= self._deadline:
                continue

            try:
                async with self._member_lock:
                    await self._give_up()
            except Exception as err:  # a hub hiccup must not end the robot; the next tick tries again
                self.log.record("error", where="watch", error=f"{type(err).__name__}: {err}")

    async def _give_up(self) -> None:
        if self.candidate_of is not None:
            await self._leave(reason="no result notice")
            return
        swarm = self.swarm
        if swarm is None or not swarm.number or clock.now() <= self._deadline:
            return
        await self._leave(reason="master silent")
        # tell the master, in case only its rosters were lost: it must stop counting us
        await self.rf.send(swarm.master, m.Dispersed(swarm.session), dst_pan=BROADCAST)


_MEMBER_HANDLERS = {
    m.Scan: NetworkFormation._on_scan,
    m.JoinQuery: NetworkFormation._on_query,
    m.JoinNotice: NetworkFormation._on_notice,
    m.NotParticipating: NetworkFormation._on_not_participating,
    m.Roster: NetworkFormation._on_roster,
    m.Disperse: NetworkFormation._on_disperse,
    m.Dispersed: NetworkFormation._on_member_left,
    m.MasterHandover: NetworkFormation._on_handover,
}
RESPONSES = (m.ScanReply, m.JoinAvailable, m.JoinUnavailable, m.Joined, m.Dispersed, m.HandoverAccepted)
"""Messages that only ever answer a master's step; outside a step they are late."""


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
    return available, refused


def _last_arrival(step: StepResult, t0: float) -> float:
    """Seconds from the request to the last member's Joined (the last member switched)."""
    return max(i.received_at for i in step.responses.values()) - t0
