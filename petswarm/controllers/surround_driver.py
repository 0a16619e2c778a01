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
from typing import Any

from petswarm import clock
from petswarm.controllers.driving import sleep_until
from petswarm.controllers.driving_core import Drive, Log, Telemetry
from petswarm.controllers.surround_core import TELEMETRY_EVERY, SetIrMode, SurroundAction, SurroundCore
from petswarm.controllers.surround_pilot import SurroundDriverConfig
from petswarm.managers.relative_location import IrModuleManager
from petswarm.managers.sequence import EventLog
from radio_hub.interface import HubUnavailable, RadioClient, RadioError

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
        fresh = asyncio.Event()
        self.radio.on_sensors.append(lambda _sensors: fresh.set())
        while True:
            await fresh.wait()
            fresh.clear()
            sensors = self.radio.sensors
            if sensors is None:
                continue
            # read when the task runs, not when the sample came: a sweep of the same instant may be newer
            self.core.sensors_sample(sensors, self.radio.beacons, clock.now())
            await self._carry_out()

    async def _carry_out(self) -> None:
        for action in self.core.actions():
            await self._execute(action)

    async def _execute(self, action: SurroundAction) -> None:
        if isinstance(action, Drive):
            self.radio.drive(action.command.vx, action.command.vy, action.command.omega)
        elif isinstance(action, Log):
            self.log.record(action.kind, **action.detail)
        elif isinstance(action, Telemetry):
            try:
                self.radio.telemetry(action.state, mode=action.mode)
            except Exception as err:  # telemetry is for viewers: never let it stop the controller
                self.log.record("error", where="telemetry", error=str(err))
        elif isinstance(action, SetIrMode):
            try:
                await self.ir.set_mode(action.mode)
            except (HubUnavailable, RadioError) as err:  # a hub still starting or restarting: try again
                self.ir.mode = "idle"
                self.core.ir_mode_failed(str(err), clock.now())
            else:
                self.core.ir_mode_set(clock.now())
            await self._carry_out()
