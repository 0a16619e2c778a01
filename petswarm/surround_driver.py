"""The surround formation in the robot process: beacons and echoes in, the surround law, motor commands out.

The asyncio shell over ``surround_sensing`` (what the robot senses) and ``surround.SurroundController``
(the law). The robot senses only through the hub: its IR module in ``beacon`` mode demodulates every other
beacon (robots and the human's) separately, 20 sweeps a second; its ultrasonic ring and wheel odometry
come with its own-body sensors. No radio message is involved: the paper's swarm needs none.

Every new beacon sweep is one control step: the law is stepped with the model time between sweeps as dt
(the rate the law differences its centroid with), and the command goes out as (vx, vy, 0): the law
assumes a fixed heading, so the robot never turns. A robot that sees no beacon at all for
``STALE_AFTER_S`` (alone, or the hub's sweeps stopped) steps on its echoes alone at its own pace, so it
still keeps off walls and slows to a stop rather than coasting on its last command.

The formation forms round a person: a robot holds still (sends no command) until it first sees the
human's beacon, then runs the law from then on, whether it sees him or not (without him, f_G is zero and
the local forces keep it with its neighbours). Robots started before their human would otherwise gather
on the spot where he is about to stand.
"""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from petswarm.relative_location import IrModuleManager
from petswarm.sequence import EventLog
from petswarm.surround import SurroundConfig, SurroundController
from petswarm.surround_sensing import SensingConfig, beacon_points, echo_points, sense
from radio_hub.interface import HubUnavailable, IrConfig, RadioClient, RadioError

BEACON_PERIOD_S = 0.05
"""The hub sweeps beacons at 20 Hz: the control period."""
POLL_S = 0.01
"""How often to look for a sweep that is late (scheduling jitter on a busy machine)."""
STALE_AFTER_S = 0.2
"""Four sweep periods without a new sweep: nothing is seen any more."""
TELEMETRY_EVERY = 10
"""Control steps between telemetry messages (2 Hz, as the swarm driver's)."""


@dataclass(frozen=True)
class SurroundDriverConfig:
    """The law's gains, how the robot reads its sensors, and whose beacon is the human's."""

    law: SurroundConfig = field(default_factory=SurroundConfig)
    human_id: str = "user"
    """The node id of the human's beacon (the user process's id)."""
    ir: IrConfig = field(default_factory=IrConfig)
    """The IR module's calibration (the estimator's, never the hub's truth)."""
    estimator: str = "lsq"
    person_radius_m: float = SensingConfig.person_radius_m

    @property
    def sensing(self) -> SensingConfig:
        """The sensing settings: the robot's radius is the law's."""
        return SensingConfig(robot_radius_m=self.law.robot_radius_m, person_radius_m=self.person_radius_m)


class SurroundDriver:
    """One robot in the surround formation."""

    def __init__(self, radio: RadioClient, ir: IrModuleManager, log: EventLog, config: SurroundDriverConfig) -> None:
        self.radio = radio
        self.ir = ir
        self.log = log
        self.config = config
        self.controller = SurroundController(config.law)
        self.command = np.zeros(2)
        self.counters = {"steps": 0, "stale_steps": 0, "human_seen": 0, "echoes_dropped": 0, "beacons": 0}
        self.engaged = False
        """True once the human's beacon was seen: the robot drives from then on."""
        self._sweep_t_us = 0
        self._last_step = time.monotonic()

    def tasks(self) -> list[Any]:
        """The coroutines the robot runs in surround mode."""
        return [self._control_loop()]

    def status(self) -> dict[str, Any]:
        """Counters and the last command, for the robot's status."""
        return {"engaged": self.engaged, "command": [round(float(v), 3) for v in self.command], **self.counters}

    async def _control_loop(self) -> None:
        await self._beacon_mode()
        tick = 0
        while True:
            t_us, beacons = self.radio.beacons
            now = time.monotonic()
            fresh = t_us != self._sweep_t_us
            if not fresh and now - self._last_step < STALE_AFTER_S:
                await asyncio.sleep(POLL_S)
                continue
            dt = (t_us - self._sweep_t_us) / 1e6 if fresh and self._sweep_t_us else now - self._last_step
            self._sweep_t_us, self._last_step = t_us, now
            self._step(beacons if fresh else {}, max(dt, 1e-3))
            self.counters["stale_steps"] += not fresh
            tick += 1
            if tick % TELEMETRY_EVERY == 0:
                self._telemetry()
            # the next sweep is due a period after this one; wake just after it
            await asyncio.sleep(max(POLL_S, BEACON_PERIOD_S - (time.monotonic() - now)))

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

    def _step(self, beacons: dict[str, np.ndarray], dt: float) -> None:
        sensors = self.radio.sensors
        if sensors is None:
            return  # no body sensors yet: the hub has not ticked the world for us
        config = self.config
        points = beacon_points(beacons, config.ir, config.estimator)
        echoes = echo_points(sensors.ranges_m, sensors.angles_rad, config.law.robot_radius_m)
        seen = sense(points, echoes, config.human_id, config.sensing)
        if not self.engaged:
            if seen.human is None:
                return
            self.engaged = True
            self.log.record("surround_engaged", beacons=len(points))
        velocity = np.array(sensors.odometry[:2], dtype=float)
        self.command = self.controller.step(seen.neighbours, seen.obstacles, seen.human, velocity, dt)
        self.radio.drive(float(self.command[0]), float(self.command[1]), 0.0)
        self.counters["steps"] += 1
        self.counters["human_seen"] += seen.human is not None
        self.counters["echoes_dropped"] += seen.echoes_dropped
        self.counters["beacons"] = len(points)

    def _telemetry(self) -> None:
        try:
            self.radio.telemetry("surround", mode="surround")
        except Exception as err:  # telemetry is for viewers: never let it stop the controller
            self.log.record("error", where="telemetry", error=str(err))
