"""The surround formation in the robot process: the thin asyncio runtime over ``surround_core.SurroundCore``.

The robot senses only through the hub: its IR module in ``beacon`` mode demodulates every other beacon
(robots and the human's) separately, 20 sweeps a second, each at its channel's AGC gain; its ultrasonic
ring and wheel odometry come with its own-body sensors at 25 Hz. No radio message is involved: the paper's
swarm needs none. The core decides (beacon mode, then on every body-sensor sample the pilot's step and its
command); this shell wakes on each sample, hands the core the radio's latest sample and beacon sweep with
``clock.now()``, and carries out what it asks: the IR mode request, the motors, the record, the telemetry.
"""

from __future__ import annotations

import asyncio
import contextvars
import weakref
from collections.abc import Callable
from typing import Any

from petswarm import clock
from petswarm.clock import sleep_until
from petswarm.controllers.driving_core import Drive, Log, Telemetry
from petswarm.controllers.surround_core import TELEMETRY_EVERY, SetIrMode, SurroundAction, SurroundCore
from petswarm.controllers.surround_pilot import SurroundDriverConfig, SurroundPilot
from petswarm.controllers.surround_sensing import SweepJob, beacon_fixes_batch
from petswarm.managers.event_log import EventLog
from petswarm.managers.relative_location import IrModuleManager
from radio_hub.datasheet import IrConfig
from radio_hub.interface import RadioClient
from radio_hub.values import BeaconSweep, HubUnavailable, OwnSensors, RadioError

__all__ = ["TELEMETRY_EVERY", "SurroundDriver"]


class SurroundDriver:
    """One robot in the surround formation."""

    def __init__(self, radio: RadioClient, ir: IrModuleManager, log: EventLog, config: SurroundDriverConfig) -> None:
        self.radio = radio
        self.ir = ir
        self.log = log
        self.config = config
        self.core = SurroundCore(config)
        self.pilot = self.core.pilot

    def tasks(self) -> list[Any]:
        """The coroutines the robot runs in surround mode."""
        return [self._control_loop()]

    def status(self) -> dict[str, Any]:
        """Counters and the last command, for the robot's status."""
        pilot = self.pilot
        return {"engaged": pilot.engaged, "command": [round(float(v), 3) for v in pilot.command], **pilot.counters}

    async def _control_loop(self) -> None:
        self.core.start(clock.now())
        while not self.core.beaconing:
            await self._carry_out()
            when = self.core.next_timer()
            if when is not None:
                await sleep_until(when)
                self.core.handle_timer(clock.now())
        # from here on every sample is stepped by the loop's one surround task, with every other robot's
        surround = SurroundTask.of_loop(asyncio.get_running_loop())
        stepped = surround.join(self)
        try:
            await stepped  # only an error of this robot's step ends it
        finally:
            surround.leave(self)

    def step(self, batch: SweepBatch, now: float) -> None:
        """Step the core on the radio's latest sample and sweep at ``now``, and carry out what it asks
        (beaconing only brings motor commands, records and telemetry: nothing to wait for)."""
        sensors = self.radio.sensors
        if sensors is None:
            return
        # read when the step runs, not when the sample came: a sweep of the same instant may be newer
        sweep = self.radio.beacons
        batch.prepare(self.pilot, sweep)
        self.core.sensors_sample(sensors, sweep, now)
        for action in self.core.actions():
            self._execute_now(action)

    def _execute_now(self, action: SurroundAction) -> None:
        if isinstance(action, Drive):
            self.radio.drive(action.command.vx, action.command.vy, action.command.omega)
        elif isinstance(action, Log):
            self.log.record(action.kind, **action.detail)
        elif isinstance(action, Telemetry):
            try:
                self.radio.telemetry(action.state, mode=action.mode)
            except Exception as err:  # telemetry is for viewers: never let it stop the controller
                self.log.record("error", where="telemetry", error=str(err))
        else:
            raise TypeError(f"a beaconing surround core asked for {action!r}")

    async def _carry_out(self) -> None:
        for action in self.core.actions():
            await self._execute(action)

    async def _execute(self, action: SurroundAction) -> None:
        if isinstance(action, SetIrMode):
            try:
                await self.ir.set_mode(action.mode)
            except (HubUnavailable, RadioError) as err:  # a hub still starting or restarting: try again
                self.ir.mode = "idle"
                self.core.ir_mode_failed(str(err), clock.now())
            else:
                self.core.ir_mode_set(clock.now())
            await self._carry_out()
        else:
            self._execute_now(action)


class SurroundTask:
    """The one task that steps every beaconing surround robot on an event loop.

    In model time every robot of a run shares the loop and their samples come at the same instants: one task
    woken once per round steps each robot whose sample came, in the order the samples came, instead of a
    task per robot woken each time (20 robots at 25 Hz: 500 task wakes a second). Each robot's own task
    waits on what ``join`` gives, which fails with its step's error, as its own loop would have. The task
    belongs to no robot (a killed robot's tasks end; the others' steps go on) and ends with its last member.
    In a robot process (wall or lockstep time) it steps one robot.
    """

    _of_loop: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, SurroundTask] = weakref.WeakKeyDictionary()
    together = True
    """Step the robots of one instant together (``surround_batch``); False: one by one (tests hold both equal)."""
    observer: Callable[[float, list[SurroundDriver]], None] | None = None
    """Called with the instant and the drivers just stepped together (model time): a bench reads their pilots
    (``surround_snapshots``); it must change nothing."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        self._members: dict[SurroundDriver, asyncio.Future[None]] = {}
        """Each member's future: its robot's task awaits it, so a killed robot's (cancelled with the task) is done."""
        self._fresh: dict[SurroundDriver, None] = {}
        """The members whose sample came since the last step, in the order they came."""
        self._wake = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self.sweeps = SweepBatch()

    @classmethod
    def of_loop(cls, loop: asyncio.AbstractEventLoop) -> SurroundTask:
        """The task stepping the surround robots on ``loop``."""
        task = cls._of_loop.get(loop)
        if task is None:
            task = cls._of_loop[loop] = cls(loop)
        return task

    def join(self, driver: SurroundDriver) -> asyncio.Future[None]:
        """Step ``driver`` on every sample its radio gets from now on; the future fails with its step's error."""
        stepped = self._loop.create_future()
        self._members[driver] = stepped
        self.sweeps.join(driver.pilot, driver.radio)
        driver.radio.on_sensors.append(lambda _sensors: self._came(driver))
        if self._task is None or self._task.done():
            # in a context of its own: not one of the robot's tasks (a model run ends those with the robot)
            self._task = self._loop.create_task(self._run(), context=contextvars.Context())
            self._task.add_done_callback(self._ended)
        return stepped

    def leave(self, driver: SurroundDriver) -> None:
        """``driver`` steps no more."""
        self._members.pop(driver, None)
        self._fresh.pop(driver, None)
        self.sweeps.leave(driver.pilot)
        if not self._members:
            self._wake.set()  # the task ends

    def _came(self, driver: SurroundDriver) -> None:
        if driver in self._members:
            self._fresh[driver] = None
            self._wake.set()

    async def _run(self) -> None:
        while self._members:
            await self._wake.wait()
            self._wake.clear()
            fresh, self._fresh = list(self._fresh), {}
            now = clock.now()
            if self.together and len(fresh) > 1:
                self._step_together(fresh, now)
                continue
            for driver in fresh:
                self._step(driver, now)

    def _ended(self, task: asyncio.Task[None]) -> None:
        """The task is over: forget the loop (the entry holds it, so a process doing run after run would keep
        every loop), and fail any member left (the task cancelled as its loop closes): none waits for good."""
        if task is not self._task:
            return  # an earlier task, ended before a member joined and started the current one
        if self._of_loop.get(self._loop) is self and not self._members:
            del self._of_loop[self._loop]
        for stepped in self._members.values():
            if not stepped.done():
                stepped.set_exception(RuntimeError("the surround robots' stepping task ended"))

    def _step_together(self, fresh: list[SurroundDriver], now: float) -> None:
        """``_step`` of each driver in ``fresh``, their cores stepped together (``SurroundCore.sensors_samples``),
        then each one's actions carried out in the order the samples came, as one by one: nothing a robot's
        actions do reaches another robot within the instant (a model run holds every message until all are idle)."""
        ready: list[tuple[SurroundDriver, OwnSensors, BeaconSweep]] = []
        for driver in fresh:
            stepped = self._members.get(driver)
            sensors = driver.radio.sensors
            if stepped is None or stepped.done() or sensors is None:
                continue
            sweep = driver.radio.beacons
            try:
                self.sweeps.prepare(driver.pilot, sweep)
            except Exception as err:
                stepped.set_exception(err)
                continue
            ready.append((driver, sensors, sweep))
        samples = [(sensors, sweep) for _, sensors, sweep in ready]
        try:
            errors: list[Exception | None] = SurroundCore.sensors_samples(
                [driver.core for driver, _, _ in ready], samples, now
            )
        except Exception as err:  # a fault of the shared step: this round's robots fail, the task steps on
            errors = [err] * len(ready)
        for (driver, _, _), error in zip(ready, errors, strict=True):
            try:
                if error is not None:
                    raise error
                for action in driver.core.actions():
                    driver._execute_now(action)
            except Exception as err:  # this robot's error ends this robot's surround task, not the others'
                self._members[driver].set_exception(err)
        if SurroundTask.observer is not None:
            SurroundTask.observer(now, [driver for driver, _, _ in ready])

    def _step(self, driver: SurroundDriver, now: float) -> None:
        stepped = self._members.get(driver)
        if stepped is None or stepped.done():
            return  # its robot is ending (killed, stopping): it steps no more, as its own loop would not
        try:
            driver.step(self.sweeps, now)
        except Exception as err:  # this robot's error ends this robot's surround task, not the others'
            stepped.set_exception(err)


class SweepBatch:
    """The surround robots running on one event loop, whose new beacon sweeps are estimated together.

    In model time every robot of a run shares the loop, and their control steps fall at the same instants:
    the first robot to step works out the fixes of every member's new sweep in one estimate
    (``surround_sensing.beacon_fixes_batch``, equal bit for bit to each robot's own), and hands each pilot its
    own (``SurroundPilot.give_fixes``), instead of twenty small estimates. In a robot process (wall or lockstep
    time) the loop has one robot, and this is its own estimate.
    """

    def __init__(self) -> None:
        self._members: dict[SurroundPilot, tuple[RadioClient, int]] = {}
        """Each member's radio and calibration (an index into ``_calibrations``)."""
        self._calibrations: list[tuple[IrConfig, str]] = []
        """The IR calibrations and estimators of the members, each once: sweeps of one are estimated together."""

    def join(self, pilot: SurroundPilot, radio: RadioClient) -> None:
        """``pilot`` steps on the sweeps that come to ``radio`` (its latest, ``radio.beacons``)."""
        calibration = (pilot.config.ir, pilot.config.estimator)
        if calibration not in self._calibrations:  # compared once here, not on every round
            self._calibrations.append(calibration)
        self._members[pilot] = (radio, self._calibrations.index(calibration))

    def leave(self, pilot: SurroundPilot) -> None:
        """``pilot`` steps no more."""
        self._members.pop(pilot, None)

    def prepare(self, pilot: SurroundPilot, sweep: BeaconSweep) -> None:
        """Before ``pilot`` steps on ``sweep``: if that sweep is new to it, estimate it together with every
        member's latest sweep that is new to its pilot, and give each pilot its fixes."""
        if not pilot.wants(sweep):
            return
        groups: dict[int, list[tuple[SurroundPilot, BeaconSweep, SweepJob]]] = {}
        for member, (radio, calibration) in self._members.items():
            latest = sweep if member is pilot else radio.beacons
            job = member.sweep_job(latest)
            if job is not None:
                groups.setdefault(calibration, []).append((member, latest, job))
        for calibration, group in groups.items():
            ir, estimator = self._calibrations[calibration]
            fixes = beacon_fixes_batch([job for _, _, job in group], ir, estimator)
            for (member, latest, _), (seen, xy) in zip(group, fixes, strict=True):
                member.give_fixes(latest, seen, xy)
