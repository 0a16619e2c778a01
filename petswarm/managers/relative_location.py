"""Relative location by infrared, the robot's side: the IR module manager, the token schedule's runtime and
the neighbour table.

The schedule's rules live in ``petswarm.managers.token_schedule.TokenSchedule``, a sans-IO core (events and ``now``
in, actions out; its docstring tells the rounds, the answer slots and the regeneration of a lost token).
``IrTokenSchedule`` here is the thin asyncio runtime around it: it feeds the core the radio's messages, the
formation's changes and its timers, and carries out the actions it returns (sends, IR mode switches, the
measurement window, the table). It reads time only through ``petswarm.clock.now()`` and the loop's timers.
``RelativeLocationManager`` (the table) and ``IrWindow`` (one measurement window) are plain objects too.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Coroutine
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from petswarm import clock
from petswarm.managers import messages as m
from petswarm.managers import token_schedule as ts
from petswarm.managers.actions import Incoming
from petswarm.managers.event_log import EventLog
from petswarm.managers.ir_estimator import IrEstimate
from petswarm.managers.message_processing import MessageProcessingManager
from petswarm.managers.rf import RfCommunicationManager
from petswarm.managers.token_schedule import ANSWER_SLOT_MS, TokenConfig, TokenSchedule, next_holder
from radio_hub.datasheet import IrConfig
from radio_hub.interface import RadioClient
from radio_hub.values import lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

__all__ = [
    "ANSWER_SLOT_MS",
    "IrModuleManager",
    "IrTokenSchedule",
    "IrWindow",
    "NeighbourFix",
    "RelativeLocationManager",
    "TokenConfig",
    "next_holder",
]


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
    """Per neighbour, the latest IR fix and heading, for the controllers to read. A plain object: every
    change says when it happened."""

    def __init__(self) -> None:
        self.table: dict[int, NeighbourFix] = {}

    def record_fix(self, addr: int, fix: IrEstimate, now: float) -> None:
        """A new bearing and distance of ``addr``, taken at ``now``."""
        entry = self.table.setdefault(addr, NeighbourFix())
        entry.bearing_rad, entry.distance_m = float(fix.bearing_rad), float(fix.distance_m)
        entry.fixed_at = now
        entry.fixes += 1

    def record_heading(self, addr: int, heading_deg: float, now: float) -> None:
        """``addr`` told us its heading at ``now``."""
        entry = self.table.setdefault(addr, NeighbourFix())
        entry.heading_deg, entry.heading_at = heading_deg, now

    def clear(self) -> None:
        """Forget everyone (the swarm ended)."""
        self.table.clear()

    def snapshot(self, now: float) -> dict[str, dict[str, Any]]:
        """The table with ages at ``now`` in seconds, bearings in degrees; keys are short addresses as text."""
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


class IrWindow:
    """One measurement window: the sweeps that arrive while it is open, and their mean once it closes."""

    def __init__(self) -> None:
        self._sweeps: list[np.ndarray] | None = None

    @property
    def is_open(self) -> bool:
        """True while sweeps are being collected."""
        return self._sweeps is not None

    def open(self) -> None:
        """Start collecting (afresh)."""
        self._sweeps = []

    def add(self, readings: np.ndarray) -> None:
        """A sweep arrived: kept only while the window is open."""
        if self._sweeps is not None:
            self._sweeps.append(readings)

    def close(self) -> tuple[np.ndarray | None, int]:
        """Stop collecting; the mean readings (None when no sweep came) and the number of sweeps."""
        sweeps, self._sweeps = self._sweeps, None
        if not sweeps:
            return None, 0
        return np.mean(sweeps, axis=0), len(sweeps)


class IrModuleManager:
    """Switches the IR module and gathers the sweeps of one measurement window."""

    def __init__(self, radio: RadioClient) -> None:
        self.radio = radio
        self.mode = "idle"
        self.window = IrWindow()

    def note(self, mode: str) -> bool:
        """Take ``mode`` as the module's; True when the hub must be told (it was in another mode)."""
        if mode == self.mode:
            return False
        # noted before the request goes: the hub applies one node's requests in order, so a later switch
        # (say to idle after a cancellation) is never skipped
        self.mode = mode
        return True

    async def set_mode(self, mode: str) -> None:
        """Switch the module (a no-op when it is already in ``mode``)."""
        if self.note(mode):
            await self.radio.set_ir_mode(mode)

    def open_window(self) -> None:
        """Start collecting sweeps."""
        self.window.open()

    def close_window(self) -> tuple[np.ndarray | None, int]:
        """Stop collecting; the mean readings (None when no sweep came) and the number of sweeps."""
        return self.window.close()

    async def run(self) -> None:
        """Take every sweep the hub sends; keep those inside an open window."""
        while True:
            sweep = await self.radio.ir_sample()
            self.window.add(sweep.readings)


IoStep = Coroutine[Any, Any, None]


class IrTokenSchedule:
    """The token schedule's asyncio runtime, run by every member of a swarm: the shell of a ``TokenSchedule``.

    Each event goes to the core with ``clock.now()``; the actions it returns are carried out in order. An
    action that does I/O (a send, a mode switch) runs as a coroutine that reports its end to the core and
    carries out what that brings on in the same task, as one sequential coroutine would; the first such
    action of a batch runs in the caller's task, later ones in tasks of their own. Every wakeup the core
    wants gets a loop timer of its own (cancelled when the core drops it), and a timer's wakeup is handled
    in a task, one hop after the timer, as a coroutine's ``asyncio.sleep`` would be.
    """

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
        self.core = TokenSchedule(rf.radio.identity.short_addr, config, clock.now(), IrConfig())
        self._timers: dict[int, asyncio.TimerHandle] = {}
        self._tasks: set[asyncio.Task[None]] = set()
        self._counted = (0, 0)
        """The core's retries and duplicates already added to the message-processing manager's counts."""

    # -- the core's state, read by the robot and the tests --------------------------------------------

    @property
    def me(self) -> int:
        """This robot's short address."""
        return self.core.me

    @property
    def active(self) -> bool:
        """True while this robot belongs to a swarm."""
        return self.core.active

    @property
    def session(self) -> int:
        """The swarm's session (0: none)."""
        return self.core.session

    @property
    def chain(self) -> tuple[int, ...]:
        """The members in token order, master first."""
        return self.core.chain

    @property
    def is_master(self) -> bool:
        """True when this robot regenerates a lost token."""
        return self.core.is_master

    @property
    def round(self) -> int:
        """The highest round seen."""
        return self.core.round

    @property
    def last_activity(self) -> float:
        """When the schedule was last heard or moved (the master's silence clock)."""
        return self.core.last_activity

    # -- the formation's events -----------------------------------------------------------------------

    def join(self, session: int, chain: tuple[int, ...], neighbours: tuple[int, ...], is_master: bool) -> None:
        """Take part in the schedule of a swarm (the master starts the first round)."""
        self._start(self.core.join(session, chain, neighbours, is_master, clock.now()))

    def update_members(self, chain: tuple[int, ...], neighbours: tuple[int, ...]) -> None:
        """The roster changed."""
        self._start(self.core.update_members(chain, neighbours))

    def rejoin(self, chain: tuple[int, ...], neighbours: tuple[int, ...], is_master: bool) -> None:
        """The master's role moved within the running swarm (a handover); see ``TokenSchedule.rejoin``."""
        self._start(self.core.rejoin(chain, neighbours, is_master, clock.now()))

    async def leave(self) -> None:
        """The swarm is over: stop holding, module off, forget the table."""
        await self._run(self.core.leave(clock.now()))

    # -- the radio's events ---------------------------------------------------------------------------

    @staticmethod
    def handles(message: m.SwarmMessage) -> bool:
        """True for the schedule's messages (requests only; answers go to ``offer``)."""
        return TokenSchedule.handles(message)

    async def on_message(self, incoming: Incoming) -> None:
        """React to the holder's messages and neighbours' headings."""
        await self._run(self.core.receive(incoming.sender, incoming.message, clock.now()))

    def offer(self, incoming: Incoming) -> bool:
        """An answer to this robot's start sign or token; False when no step of the schedule wants it."""
        actions = self.core.offer(incoming, clock.now())
        if actions is None:
            return False
        # the round goes on in a task of its own, as a step woken by its answer does
        self._start(actions, later=True)
        return True

    # -- time -----------------------------------------------------------------------------------------

    async def watch(self) -> None:
        """Run the core's timers (its watch for a lost token among them) until cancelled."""
        try:
            self._start(self.core.start(clock.now()))
            await asyncio.Event().wait()
        finally:
            for timer in self._timers.values():
                timer.cancel()
            for task in list(self._tasks):
                task.cancel()

    def status(self) -> dict[str, Any]:
        """For the robot's status answer."""
        return {**self.core.status(), "ir_mode": self.ir.mode}

    # -- carrying out actions -------------------------------------------------------------------------

    def _start(self, actions: list[ts.Action], later: bool = False) -> None:
        """Carry out ``actions`` from plain code: I/O in tasks (all of it in one task, ``later``)."""
        if later:
            self._spawn(self._run(actions))
            return
        for step in self._do(actions):
            self._spawn(step)

    async def _run(self, actions: list[ts.Action]) -> None:
        """Carry out ``actions``; the first I/O in this task, the rest in tasks of their own."""
        steps = self._do(actions)
        for step in steps[1:]:
            self._spawn(step)
        if steps:
            await steps[0]

    def _do(self, actions: list[ts.Action]) -> list[IoStep]:
        """Carry out what needs no waiting, in order; the I/O as coroutines, in order."""
        self._after_core()
        steps: list[IoStep] = []
        for action in actions:
            steps += self._do_one(action)
        return steps

    def _do_one(self, action: ts.Action) -> list[IoStep]:
        if isinstance(action, ts.Send):
            return [self._send(action)]
        if isinstance(action, ts.SendHeading):
            return [self._send_heading(action)]
        if isinstance(action, ts.SetIrMode):
            if self.ir.note(action.mode):
                return [self._switch(action)]
            return [] if action.ref is None else self._do(self.core.mode_set(action.ref, clock.now()))
        if isinstance(action, ts.CloseWindow):
            readings, sweeps = self.ir.close_window()
            return self._do(self.core.measured(action.holder, readings, sweeps, clock.now()))
        self._apply(action)
        return []

    def _apply(self, action: ts.Action) -> None:
        if isinstance(action, ts.OpenWindow):
            self.ir.open_window()
        elif isinstance(action, ts.DropWindow):
            self.ir.close_window()
        elif isinstance(action, ts.RecordFix):
            self.locations.record_fix(action.addr, action.fix, action.at)
        elif isinstance(action, ts.RecordHeading):
            self.locations.record_heading(action.addr, action.heading_deg, action.at)
        elif isinstance(action, ts.ForgetTable):
            self.locations.clear()
        elif isinstance(action, ts.Answers):
            self.on_answers(action.answered, action.silent)
        elif isinstance(action, ts.Log):
            self.log.record(action.kind, **action.detail)

    async def _send(self, action: ts.Send) -> None:
        try:
            await self.rf.send(action.dst, action.message, ack=action.ack)
        except Exception as err:  # the hub went away mid-send: what waited for it is given up, never crashes
            await self._failed(action.ref, "ir_send", err)
            return
        if action.ref is not None:
            await self._run(self.core.sent(action.ref, clock.now()))

    async def _send_heading(self, action: ts.SendHeading) -> None:
        centideg = round(self.heading_deg() * 100) % 36000
        try:
            await self.rf.send(action.dst, m.Heading(action.session, centideg))
        except Exception as err:  # as in _send
            await self._failed(None, "ir_heading", err)

    async def _switch(self, action: ts.SetIrMode) -> None:
        try:
            await self.ir.radio.set_ir_mode(action.mode)
        except Exception as err:  # as in _send
            await self._failed(action.ref, "ir_mode", err)
            return
        if action.ref is not None:
            await self._run(self.core.mode_set(action.ref, clock.now()))

    async def _failed(self, ref: int | None, where: str, err: Exception) -> None:
        self.log.record("error", where=where, error=f"{type(err).__name__}: {err}")
        if ref is not None:
            await self._run(self.core.failed(ref, clock.now()))

    # -- timers and tasks -----------------------------------------------------------------------------

    def _after_core(self) -> None:
        """Bring the loop's timers in line with the core's wakeups; add its new counts to the manager's."""
        wanted = self.core.timers()
        for wid in [wid for wid in self._timers if wid not in wanted]:
            self._timers.pop(wid).cancel()
        loop = asyncio.get_running_loop()
        for wid, when in wanted.items():
            if wid not in self._timers:
                self._timers[wid] = loop.call_at(when, self._fire, wid, when)
        retries, duplicates = self.core.retries, self.core.duplicates
        self.mpm.retries += retries - self._counted[0]
        self.mpm.duplicates += duplicates - self._counted[1]
        self._counted = (retries, duplicates)

    def _fire(self, wid: int, when: float) -> None:
        self._timers.pop(wid, None)
        self._spawn(self._wake(when))

    async def _wake(self, when: float) -> None:
        self.core.air = self.rf.radio.hub_present
        # a lockstep loop may run a timer within its clock resolution before it is due: it is due
        await self._run(self.core.handle_timer(max(clock.now(), when)))

    def _spawn(self, step: IoStep) -> None:
        task = asyncio.get_running_loop().create_task(step)
        self._tasks.add(task)
        task.add_done_callback(self._task_done)

    def _task_done(self, task: asyncio.Task[None]) -> None:
        self._tasks.discard(task)
        if not task.cancelled() and task.exception() is not None:
            err = task.exception()
            self.log.record("error", where="ir_schedule", error=f"{type(err).__name__}: {err}")
