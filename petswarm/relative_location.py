"""Relative location by infrared: the IR module manager, the token schedule and the neighbour table.

Only one robot may shine at a time, and robots share no clock, so transmission passes round the swarm
with a token carried by the radio (paper Fig. 7). One *round* belongs to one holder:

1. the holder broadcasts the transmission-start sign (``IrStart``) and waits for every member's answer
   (a message-processing step: deadline, retries of the missing); members switch to receive and open a
   measurement window; the holder's neighbours send it their heading;
2. the holder transmits IR for ``slot_s``, then switches its module off;
3. it broadcasts the token (``Token``) naming the next holder and waits for the answers; each member
   closes its window, estimates bearing and distance of the holder from the mean readings, and answers;
4. it broadcasts ``Sync`` for the next round; the robot it names starts that round at step 1.

A holder only starts after the previous one has switched off and said so, so two modules never shine
at once while the radio works. When the token is lost (a Sync lost, the holder killed), nothing happens
for ``regen_timeout_s``; then the master regenerates it with a higher round number, skipping members that
stopped answering. A holder that hears the start sign of a higher round stops at once.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from petswarm import clock
from petswarm import messages as m
from petswarm.decisions import reply_delay_s
from petswarm.exchange import MessageProcessingManager, StepTiming
from petswarm.ir_estimator import IrEstimate, estimate
from petswarm.rf import Incoming, RfCommunicationManager
from petswarm.sequence import EventLog
from radio_hub.interface import BROADCAST, IrConfig, RadioClient

ANSWER_SLOT_MS = 3
"""Members answer the holder's start sign and token in slots of this length, in member order."""


@dataclass
class NeighbourFix:
    """What a robot knows of another: bearing (rad, from its own heading), distance, heading, age."""

    bearing_rad: float | None = None
    distance_m: float | None = None
    heading_deg: float | None = None
    fixed_at: float | None = None
    heading_at: float | None = None
    fixes: int = 0


class RelativeLocationManager:
    """Per neighbour, the latest IR fix and heading, for the controllers to read."""

    def __init__(self) -> None:
        self.table: dict[int, NeighbourFix] = {}

    def record_fix(self, addr: int, fix: IrEstimate) -> None:
        """A new bearing and distance of ``addr``."""
        entry = self.table.setdefault(addr, NeighbourFix())
        entry.bearing_rad, entry.distance_m = float(fix.bearing_rad), float(fix.distance_m)
        entry.fixed_at = clock.now()
        entry.fixes += 1

    def record_heading(self, addr: int, heading_deg: float) -> None:
        """``addr`` told us its heading."""
        entry = self.table.setdefault(addr, NeighbourFix())
        entry.heading_deg, entry.heading_at = heading_deg, clock.now()

    def clear(self) -> None:
        """Forget everyone (the swarm ended)."""
        self.table.clear()

    def snapshot(self) -> dict[str, dict[str, Any]]:
        """The table with ages in seconds, bearings in degrees; keys are short addresses as text."""
        now = clock.now()
        out = {}
        for addr, e in self.table.items():
            out[str(addr)] = {
                "bearing_deg": None if e.bearing_rad is None else round(math.degrees(e.bearing_rad), 4),
                "distance_m": None if e.distance_m is None else round(e.distance_m, 5),
                "heading_deg": e.heading_deg,
                "age_s": None if e.fixed_at is None else round(now - e.fixed_at, 3),
                "heading_age_s": None if e.heading_at is None else round(now - e.heading_at, 3),
                "fixes": e.fixes,
            }
        return out


class IrModuleManager:
    """Switches the IR module and gathers the sweeps of one measurement window."""

    def __init__(self, radio: RadioClient) -> None:
        self.radio = radio
        self.mode = "idle"
        self._window: list[np.ndarray] | None = None

    async def set_mode(self, mode: str) -> None:
        """Switch the module (a no-op when it is already in ``mode``)."""
        if mode != self.mode:
            # noted before the await: the request is on its way, and the hub applies one node's requests
            # in order, so a later switch (say to idle after a cancellation) is never skipped
            self.mode = mode
            await self.radio.set_ir_mode(mode)

    def open_window(self) -> None:
        """Start collecting sweeps."""
        self._window = []

    def close_window(self) -> tuple[np.ndarray | None, int]:
        """Stop collecting; the mean readings (None when no sweep came) and the number of sweeps."""
        window, self._window = self._window, None
        if not window:
            return None, 0
        return np.mean(window, axis=0), len(window)

    async def run(self) -> None:
        """Take every sweep the hub sends; keep those inside an open window."""
        while True:
            sweep = await self.radio.ir_sample()
            if self._window is not None:
                self._window.append(sweep.readings)


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


class IrTokenSchedule:
    """The relative-location identification manager's schedule, run by every member of a swarm."""

    def __init__(
        self,
        rf: RfCommunicationManager,
        mpm: MessageProcessingManager,
        ir: IrModuleManager,
        locations: RelativeLocationManager,
        log: EventLog,
        config: TokenConfig,
        heading_deg: Callable[[], float],
        on_answers: Callable[[set[int], set[int]], None] = lambda answered, silent: None,
    ) -> None:
        self.rf, self.mpm, self.ir, self.locations, self.log = rf, mpm, ir, locations, log
        self.config = config
        self.heading_deg = heading_deg
        self.on_answers = on_answers
        """Told, after each start sign this robot sent, who answered and who stayed silent."""
        self.ir_config = IrConfig()  # the module's calibration (its datasheet), not the hub's truth
        self.session = 0
        self.chain: tuple[int, ...] = ()
        self.neighbours: tuple[int, ...] = ()
        self.is_master = False
        self.round = 0
        self.rounds_held = 0
        self.fixes = 0
        self.regenerations = 0
        self.last_activity = clock.now()
        self._window_of: tuple[int, int] | None = None
        self._holding: asyncio.Task[None] | None = None

    @property
    def me(self) -> int:
        """This robot's short address."""
        return self.rf.radio.identity.short_addr

    @property
    def active(self) -> bool:
        """True while this robot belongs to a swarm."""
        return bool(self.session)

    def join(self, session: int, chain: tuple[int, ...], neighbours: tuple[int, ...], is_master: bool) -> None:
        """Take part in the schedule of a swarm (the master starts the first round)."""
        self.session, self.chain, self.neighbours, self.is_master = session, chain, neighbours, is_master
        self.round = 0
        self.last_activity = clock.now()
        self.log.record("ir_schedule", session=session, chain=list(chain), master=is_master)
        if is_master:
            self._hold(1)

    def update_members(self, chain: tuple[int, ...], neighbours: tuple[int, ...]) -> None:
        """The roster changed."""
        self.chain, self.neighbours = chain, neighbours

    def rejoin(self, chain: tuple[int, ...], neighbours: tuple[int, ...], is_master: bool) -> None:
        """The master's role moved within the running swarm (a handover): the new chain and master flag.
        The round count is kept (members ignore start signs of older rounds) and the token keeps passing
        where it is; only who regenerates a lost token changes."""
        self.chain, self.neighbours, self.is_master = chain, neighbours, is_master
        self.last_activity = clock.now()
        self.log.record("ir_schedule", session=self.session, chain=list(chain), master=is_master, rejoined=True)

    async def leave(self) -> None:
        """The swarm is over: stop holding, module off, forget the table."""
        self.session = 0
        if self._holding is not None:
            self._holding.cancel()
        self.ir.close_window()
        self._window_of = None
        self.locations.clear()
        await self.ir.set_mode("idle")

    # -- holding the token ------------------------------------------------------------------------

    def _hold(self, round_: int) -> None:
        if self._holding is not None and not self._holding.done():
            self._holding.cancel()
        self.round = round_
        self._holding = asyncio.get_running_loop().create_task(self._round(round_))
        self._holding.add_done_callback(self._round_ended)

    def _round_ended(self, task: asyncio.Task[None]) -> None:
        if not task.cancelled() and task.exception() is not None:
            err = task.exception()
            self.log.record("error", where="ir_round", error=f"{type(err).__name__}: {err}")

    async def _round(self, round_: int) -> None:
        session, others = self.session, set(self.chain) - {self.me}
        self.last_activity = clock.now()

        async def start(_: set[int] | None) -> None:
            await self.rf.send(BROADCAST, m.IrStart(session, round_), ack=False)

        begun = await self.mpm.step("ir_start", session, (m.IrStartAck,), start, others, self.config.step)
        if self.round != round_ or not self.active:
            return  # overtaken by a higher round while we waited
        alive = set(begun.responses)
        self.on_answers(alive, others - alive)
        if others and not alive:
            # nobody heard us: we may be the deaf one while the others pass the token; never shine blind
            self.log.record("ir_unheard", round=round_)
            self.last_activity = clock.now()
            return
        try:
            await self.ir.set_mode("transmit")
            await asyncio.sleep(self.config.slot_s)
        finally:
            await asyncio.shield(self.ir.set_mode("idle"))
        self.rounds_held += 1
        nxt = next_holder(self.chain, self.me, alive)

        async def token(_: set[int] | None) -> None:
            await self.rf.send(BROADCAST, m.Token(session, round_, nxt), ack=False)

        await self.mpm.step("token", session, (m.TokenAck,), token, alive, self.config.step)
        if self.round != round_ or not self.active:
            return
        await self.rf.send(BROADCAST, m.Sync(session, round_ + 1, nxt), ack=False)
        self.last_activity = clock.now()
        if nxt == self.me:
            self._hold(round_ + 1)

    # -- as a member --------------------------------------------------------------------------------

    @staticmethod
    def handles(message: m.SwarmMessage) -> bool:
        """True for the schedule's messages (requests only; answers go to the steps)."""
        return isinstance(message, (m.IrStart, m.Token, m.Sync, m.Heading))

    async def on_message(self, incoming: Incoming) -> None:
        """React to the holder's messages and neighbours' headings."""
        msg = incoming.message
        if not self.active or msg.session_id != self.session:
            return
        self.last_activity = clock.now()
        if isinstance(msg, m.IrStart):
            await self._on_start(incoming, msg)
        elif isinstance(msg, m.Token):
            await self._on_token(incoming, msg)
        elif isinstance(msg, m.Sync):
            if msg.holder == self.me and msg.round > self.round:
                self._hold(msg.round)
            self.round = max(self.round, msg.round)
        elif isinstance(msg, m.Heading):
            self.locations.record_heading(incoming.sender, msg.centideg / 100.0)

    async def _on_start(self, incoming: Incoming, msg: m.IrStart) -> None:
        if msg.round < self.round and self._window_of != (incoming.sender, msg.round):
            return  # a stale start sign
        holding = self._holding is not None and not self._holding.done()
        if holding and (msg.round, incoming.sender) > (self.round, self.me):
            self._holding.cancel()  # type: ignore[union-attr]  # a higher round holds: never shine together
            self.log.record("ir_overtaken", round=msg.round, by=incoming.sender)
        elif holding:
            return  # the same round with a lower address yields to us: ties go to the higher address
        self.round = max(self.round, msg.round)
        if self._window_of != (incoming.sender, msg.round):
            self._window_of = (incoming.sender, msg.round)
            self.ir.open_window()
            await self.ir.set_mode("receive")
            if not self.active:
                return
        await asyncio.sleep(self._answer_slot(incoming.sender))
        await self.rf.send(incoming.sender, m.IrStartAck(self.session, msg.round))
        if incoming.sender in self.neighbours:
            centideg = round(self.heading_deg() * 100) % 36000
            await self.rf.send(incoming.sender, m.Heading(self.session, centideg))

    async def _on_token(self, incoming: Incoming, msg: m.Token) -> None:
        if self._window_of == (incoming.sender, msg.round):
            self._measure(incoming.sender)
        if msg.next == self.me and msg.round >= self.round:
            self._expect_sync(msg.round + 1)
        await asyncio.sleep(self._answer_slot(incoming.sender))
        await self.rf.send(incoming.sender, m.TokenAck(self.session, msg.round))

    def _expect_sync(self, round_: int) -> None:
        """Named next: if the sync is lost, start our round anyway once the holder's token step is surely
        over (it has stopped shining before it sent the token, so this never overlaps it)."""
        wait = (self.config.step.max_retries + 2) * self.config.step.deadline_s

        def fallback() -> None:
            if self.active and self.round < round_:
                self.log.record("sync_missed", round=round_)
                self._hold(round_)

        asyncio.get_running_loop().call_later(wait, fallback)

    def _answer_slot(self, holder: int) -> float:
        # every member answers the holder's broadcast at once otherwise, and their CSMA backoffs collide
        others = tuple(a for a in self.chain if a != holder)
        return reply_delay_s(self.me, ANSWER_SLOT_MS, others)

    def _measure(self, holder: int) -> None:
        readings, sweeps = self.ir.close_window()
        self._window_of = None
        fix = None if readings is None else estimate(readings, self.ir_config, self.config.estimator)
        if fix is None:
            self.log.record("ir_no_fix", holder=holder, sweeps=sweeps)
            return
        self.locations.record_fix(holder, fix)
        self.fixes += 1
        self.log.record(
            "ir_fix",
            holder=holder,
            round=self.round,
            sweeps=sweeps,
            bearing_deg=round(math.degrees(fix.bearing_rad), 4),
            distance_m=round(fix.distance_m, 5),
        )

    # -- a lost token -------------------------------------------------------------------------------

    async def watch(self) -> None:
        """The master regenerates the token after ``regen_timeout_s`` of silence."""
        while True:
            await asyncio.sleep(0.05)
            if not self.rf.radio.hub_present:
                self.last_activity = clock.now()  # no air, no token to lose
                continue
            silent = clock.now() - self.last_activity > self.config.regen_timeout_s

            if self.active and self.is_master and silent:
                self.regenerations += 1
                self.log.record("token_regenerated", round=self.round + 1)
                self._hold(self.round + 1)

    def status(self) -> dict[str, Any]:
        """For the robot's status answer."""
        return {
            "round": self.round,
            "rounds_held": self.rounds_held,
            "fixes": self.fixes,
            "regenerations": self.regenerations,
            "ir_mode": self.ir.mode,
            "chain": list(self.chain),
        }
