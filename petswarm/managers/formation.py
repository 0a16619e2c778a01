"""Forming and dispersing the swarm network (paper section 3.4, Fig. 8): the asyncio runtime around the
sans-IO core (``petswarm.managers.formation_core``, which holds the protocol and its docs).

``NetworkFormation`` keeps the public face the robot and the driver use (``organize``, ``disperse``,
``hand_over``, ``on_message``, ``note_answers``, ``watch``, ``swarm``, ``user``) and does the I/O the core
asks for: it sends on the RF communication manager, switches the radio's PAN, records events, runs the
core's request/response steps on the message-processing manager, announces the roster, calls the robot's
callbacks. It reads time only through ``petswarm.clock.now()`` and the loop's timers.

Two locks keep the order the core assumes: one request (organize, disperse, hand-over, a dissolution) at a
time, and one member-side event at a time, its actions carried out (the PAN switch included) before the
next message is looked at, so no interleaving can leave a robot on the wrong PAN.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

from petswarm import clock
from petswarm.grid import next_on_grid
from petswarm.managers import messages as m
from petswarm.managers.actions import Incoming, Log, Send
from petswarm.managers.event_log import EventLog
from petswarm.managers.formation_core import (
    ANSWER_ATTEMPTS,
    MAX_LISTED,
    MAX_MEMBERS,
    MEMBER_MISSES,
    PROTOCOLS,
    RESPONSES,
    Action,
    Answer,
    ConfigurePan,
    Dissolve,
    Done,
    Exchange,
    FormationConfig,
    FormationCore,
    FormationError,
    HandedOver,
    Pause,
    Procedure,
    StartRoster,
    StopRoster,
    Swarm,
    SwarmChanged,
    check_count,
)
from petswarm.managers.message_processing import MessageProcessingManager
from petswarm.managers.rf import RfCommunicationManager
from petswarm.managers.sequence import SequenceManager, StateChange
from radio_hub.values import BROADCAST, lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

__all__ = [
    "ANSWER_ATTEMPTS",
    "MAX_LISTED",
    "MAX_MEMBERS",
    "MEMBER_MISSES",
    "PROTOCOLS",
    "RESPONSES",
    "WATCH_PERIOD_S",
    "FormationConfig",
    "FormationError",
    "NetworkFormation",
    "Swarm",
]

WATCH_PERIOD_S = 0.05
"""How often the runtime looks at the core's timer. A tick, not a timer at the core's deadline: a robot gives
up at the first tick after its deadline, as it always has (runs stay the same, digests included)."""

T = TypeVar("T")


class NetworkFormation:
    """Organizes (as master) or joins (as a waiting robot) a swarm network: the core's asyncio runtime."""

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
        self.core = FormationCore(rf.radio.identity.short_addr, sequence, config, rng, user)
        self.on_change = on_change
        """Called with the swarm whenever this robot joins one, its members change, or it leaves (None)."""
        self.on_handover: Callable[[tuple[int, ...], m.MasterHandover | None], None] = lambda chain, msg: None
        """Called after the master's role moved within this robot's swarm (this robot gave it, took it, or
        saw it move), with the chain before the handover and the handover message (None when a missed
        handover was learned from the new master's roster)."""
        self._roster_task: asyncio.Task[None] | None = None
        self._dissolving: set[asyncio.Task[None]] = set()
        """Dissolutions waiting for the request lock (kept: the loop holds only weak references to tasks)."""
        self._busy = asyncio.Lock()
        self._member_lock = asyncio.Lock()
        self.rests = False
        """Let the watch stop waking while there is nothing to watch (a surround robot's: see ``watch``)."""
        self._stirred = asyncio.Event()

    # -- what the robot and the driver read and set ------------------------------------------------

    @property
    def me(self) -> int:
        """This robot's short address."""
        return self.rf.radio.identity.short_addr

    @property
    def swarm(self) -> Swarm | None:
        """The swarm this robot belongs to (None: none)."""
        return self.core.swarm

    @property
    def user(self) -> int:
        """The user this robot serves (0: none); the driver sets it when a user connects."""
        return self.core.user

    @user.setter
    def user(self, user: int) -> None:
        self.core.user = user

    @property
    def organizations(self) -> list[dict[str, Any]]:
        """The figures of every organization this robot ran as master."""
        return self.core.organizations

    @property
    def candidate_of(self) -> tuple[int, int] | None:
        """(session, master) while this robot said 'available' and waits for the result."""
        return self.core.candidate_of

    def _core(self) -> FormationCore:
        """The core, told what the radio is now (its address and PAN may have been configured meanwhile)."""
        identity = self.rf.radio.identity
        self.core.me, self.core.pan_id = identity.short_addr, identity.pan_id
        self._stirred.set()  # the core may start a timer: a resting watch looks again
        return self.core

    # -- master side -------------------------------------------------------------------------------

    async def organize(self, count: int, protocol: str | None = None) -> dict[str, Any]:
        """Form a swarm of up to ``count`` other robots; returns the organization's figures."""
        check_count(count)
        if self._busy.locked():
            raise FormationError("already organizing or dispersing")
        async with self._busy:
            return await self._drive(self._core().organize(count, protocol or self.config.protocol, clock.now()))

    async def disperse(self, protocol: str | None = None) -> dict[str, Any]:
        """End the swarm: every member back to waiting, this robot back to its driving state."""
        async with self._busy:
            return await self._drive(self._core().disperse(protocol, clock.now()))

    async def hand_over(
        self, chain: tuple[int, ...], mode: str, shape: str, spacing: float, mirrored: int, kept: int, owner: str
    ) -> bool:
        """Table 3's Change column, the old master's side (``FormationCore.hand_over``): False when the new
        master never accepted and this robot is still the master."""
        async with self._busy:
            core = self._core()
            return await self._drive(core.hand_over(chain, mode, shape, spacing, mirrored, kept, owner, clock.now()))

    def note_answers(self, answered: set[int], silent: set[int]) -> None:
        """Master side: who answered our IR start sign (the IR schedule's callback); see the core's."""
        for action in self._core().note_answers(answered, silent):
            self._apply(action)

    async def _dissolve(self, order: Dissolve) -> None:
        async with self._busy:
            await self._run(self._core().dissolve(order.swarm, order.reason, clock.now()))

    async def _announce_roster(self) -> None:
        while (roster := self.core.roster()) is not None:
            try:
                await self.rf.send(BROADCAST, roster, ack=False)
            except Exception as err:  # keep announcing: members leave after 2 s without a roster
                self._error("roster", err)
            await asyncio.sleep(self.config.roster_interval_s)

    # -- member side -------------------------------------------------------------------------------

    @staticmethod
    def handles(message: m.SwarmMessage) -> bool:
        """True for the messages ``on_message`` acts on."""
        return FormationCore.handles(message)

    async def on_message(self, incoming: Incoming) -> None:
        """Act on a formation message, one at a time (see the module's docstring)."""
        if not self.handles(incoming.message):
            return
        async with self._member_lock:
            await self._run(self._core().receive(incoming, clock.now()))

    async def watch(self) -> None:
        """Member-side timeouts: a candidate never told the result, a member whose master went silent.

        With ``rests`` (a surround robot, which never organizes) the watch stops waking while the core has no
        timer and the hub is there: a tick then does nothing (the hub's absence only moves a deadline that
        is set afresh whenever a timer starts), and these ticks were 20 a second per robot. Whatever the core
        is told wakes it (``_core``), and it takes up its ticks again on the same grid of instants."""
        while True:
            await asyncio.sleep(WATCH_PERIOD_S)
            if self.rests and self.rf.radio.hub_present and self.core.get_timer() is None:
                await self._rest()
            await self._tick()

    async def _tick(self) -> None:
        if not self.rf.radio.hub_present:
            self.core.hub_absent(clock.now())
            return
        timer = self.core.get_timer()
        if timer is None or clock.now() <= timer:
            return
        try:
            async with self._member_lock:
                await self._run(self._core().handle_timer(clock.now()))
        except Exception as err:  # a hub hiccup must not end the robot; the next tick tries again
            self._error("watch", err)

    async def _rest(self) -> None:
        """Until the core is told something, then until the next tick of the grid the watch was on (a tick at
        this instant has been: ticks are timers, which run before the instant's messages)."""
        last = clock.now()
        self._stirred.clear()
        await self._stirred.wait()
        await clock.sleep_until(next_on_grid(last, WATCH_PERIOD_S, clock.now()))

    # -- carrying actions out ----------------------------------------------------------------------

    async def _drive(self, procedure: Procedure[T]) -> T:
        """Run a master's procedure: carry out each action it yields and resume it with the outcome; an
        exception from an action (or a cancellation) is thrown into it, as at an ``await`` of its own."""
        done: Done | None = None
        error: BaseException | None = None
        while True:
            try:
                action = procedure.send(done) if error is None else procedure.throw(error)  # type: ignore[arg-type]
            except StopIteration as stop:
                return stop.value  # type: ignore[no-any-return]
            error = None
            try:
                done = Done(clock.now(), await self._perform(action))
            except BaseException as err:  # handed to the procedure, which re-raises it
                error = err

    async def _run(self, actions: list[Action]) -> None:
        for action in actions:
            await self._perform(action)

    async def _perform(self, action: Action) -> Any:
        if isinstance(action, Send):
            try:
                return await self.rf.send(action.dst, action.message, dst_pan=action.dst_pan, ack=action.ack)
            except Exception as err:
                if action.where is None:
                    raise
                self._error(action.where, err)
        elif isinstance(action, Answer):
            result = await self.rf.send(action.dst, action.message, dst_pan=action.dst_pan)
            await self._run(self.core.answer_sent(action, result))
        elif isinstance(action, Pause):
            await asyncio.sleep(action.seconds)
        elif isinstance(action, ConfigurePan):
            try:
                await self.rf.radio.configure(pan_id=action.pan_id)
            except Exception as err:
                if action.where is None:
                    raise
                self._error(action.where, err)
        elif isinstance(action, Exchange):
            requests = action.requests

            async def send(missing: set[int] | None) -> None:
                await self._run(list(requests(missing)))

            return await self.mpm.run(action.name, action.step, send)
        else:
            self._apply(action)
        return None

    def _apply(self, action: Action) -> None:
        """Carry out an action that never waits."""
        if isinstance(action, Log):
            self.log.record(action.kind, **action.detail)
        elif isinstance(action, StateChange):
            self.log.record("state", **action.fields())
        elif isinstance(action, SwarmChanged):
            self.on_change(action.swarm)
        elif isinstance(action, HandedOver):
            self.on_handover(action.old_chain, action.message)
        elif isinstance(action, StartRoster):
            self._roster_task = asyncio.get_running_loop().create_task(self._announce_roster())
        elif isinstance(action, StopRoster):
            if self._roster_task is not None:
                self._roster_task.cancel()
        elif isinstance(action, Dissolve):
            task = asyncio.get_running_loop().create_task(self._dissolve(action))
            self._dissolving.add(task)
            task.add_done_callback(self._dissolving.discard)
        else:
            raise TypeError(f"{type(action).__name__} waits: it cannot be carried out here")

    def _error(self, where: str, err: Exception) -> None:
        self.log.record("error", where=where, error=f"{type(err).__name__}: {err}")
