"""The surround formation in the robot process: the asyncio shell over ``surround_pilot.SurroundPilot``.

The robot senses only through the hub: its IR module in ``beacon`` mode demodulates every other beacon
(robots and the human's) separately, 20 sweeps a second, each at its channel's AGC gain; its ultrasonic
ring and wheel odometry come with its own-body sensors at 25 Hz. No radio message is involved: the paper's
swarm needs none. On every body-sensor sample the pilot steps (see its module for why) and the command goes
to the hub's motors.
"""

from __future__ import annotations

import asyncio
from typing import Any

from petswarm import clock
from petswarm.relative_location import IrModuleManager
from petswarm.sequence import EventLog
from petswarm.surround_pilot import SurroundDriverConfig, SurroundPilot
from radio_hub.interface import HubUnavailable, RadioClient, RadioError

TELEMETRY_EVERY = 12
"""Control steps between telemetry messages (about 2 Hz, as the swarm driver's)."""


class SurroundDriver:
    """One robot in the surround formation."""

    def __init__(self, radio: RadioClient, ir: IrModuleManager, log: EventLog, config: SurroundDriverConfig) -> None:
        self.radio = radio
        self.ir = ir
        self.log = log
        self.config = config
        self.pilot = SurroundPilot(config)

    def tasks(self) -> list[Any]:
        """The coroutines the robot runs in surround mode."""
        return [self._control_loop()]

    def status(self) -> dict[str, Any]:
        """Counters and the last command, for the robot's status."""
        pilot = self.pilot
        return {"engaged": pilot.engaged, "command": [round(float(v), 3) for v in pilot.command], **pilot.counters}

    async def _control_loop(self) -> None:
        await self._beacon_mode()
        fresh = asyncio.Event()
        self.radio.on_sensors.append(lambda _sensors: fresh.set())
        tick = 0
        while True:
            await fresh.wait()
            fresh.clear()
            sensors = self.radio.sensors
            if sensors is None:
                continue
            engaged = self.pilot.engaged
            command = self.pilot.step(sensors, self.radio.beacons, clock.now())
            if command is None:
                continue
            if not engaged:
                self.log.record("surround_engaged", beacons=self.pilot.counters["beacons"])
            self.radio.drive(command[0], command[1], 0.0)
            tick += 1
            if tick % TELEMETRY_EVERY == 0:
                self._telemetry()

    async def _beacon_mode(self) -> None:
        while True:
            try:
                await self.ir.set_mode("beacon")
                self.log.record("surround_start", human=self.config.human_id)
                return
            except (HubUnavailable, RadioError) as err:  # a hub still starting or restarting: try again
                self.log.record("error", where="surround_beacon_mode", error=str(err))
                self.ir.mode = "idle"
                await asyncio.sleep(0.5)

    def _telemetry(self) -> None:
        try:
            self.radio.telemetry("surround", mode="surround")
        except Exception as err:  # telemetry is for viewers: never let it stop the controller
            self.log.record("error", where="telemetry", error=str(err))
