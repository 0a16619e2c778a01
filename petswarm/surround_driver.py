"""The surround formation in the robot process: beacons and echoes in, the surround law, motor commands out.

The asyncio shell over ``surround_sensing`` (what the robot senses) and ``surround.SurroundController``
(the law). The robot senses only through the hub: its IR module in ``beacon`` mode demodulates every other
beacon (robots and the human's) separately, 20 sweeps a second; its ultrasonic ring and wheel odometry
come with its own-body sensors. No radio message is involved: the paper's swarm needs none.

The law steps on every body-sensor sample (25 Hz: fresh odometry and echoes), with the model time
between samples as dt, not only on the 20 Hz beacon sweeps: between sweeps the beacons' points are
dead-reckoned with the robot's own odometry (they are taken to stand still; their motion shows at the
next sweep). Why: stepping the law only at each sweep made the swarm bounce (the repulsion Q / d^2 is
stiff near contact, and a 50 ms step behind it oscillates): in a process-like simulation (the hub's world
and beacon model, this driver's sensing) the corridor had 35 contacts at 20 Hz without any sensing noise,
about 5 with IR noise when stepped on every sensor sample. The law's own velocity is the fresh odometry
of that sample. Stepping faster than odometry comes (at 50 Hz on the latest, often stale, sample) lost
the velocity increments of the stale steps and the swarm never kept up with its human; stepping on the
last command instead let the law's velocity drift from the real one (pushes, the drive's ramp) and the
robots collided. The command goes out as (vx, vy, 0): the law assumes a fixed heading, so the robot never
turns. A robot that gets no new sweep for ``STALE_AFTER_S`` (alone, or the hub's sweeps stopped) forgets
the beacons and steps on its echoes alone, so it still keeps off walls and slows to a stop.

The formation forms round a person: a robot holds still (sends no command) until it first sees the
human's beacon, then runs the law from then on, whether it sees him or not (without him, f_G is zero and
the local forces keep it with its neighbours). Robots started before their human would otherwise gather
on the spot where he is about to stand.
"""

from __future__ import annotations

import asyncio
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from petswarm.driving import EchoRanges
from petswarm.motion import DriveLimits, MotorCommand
from petswarm.pet_controller import PetControllerConfig, safety
from petswarm.relative_location import IrModuleManager
from petswarm.sequence import EventLog
from petswarm.surround import SurroundConfig, SurroundController
from petswarm.surround_sensing import SensingConfig, beacon_points, dead_reckon, echo_points, sense
from radio_hub.interface import HubUnavailable, IrConfig, OwnSensors, RadioClient, RadioError

STALE_AFTER_S = 0.2
"""Four sweep periods (the hub sweeps beacons at 20 Hz) without a new sweep: nothing is seen any more."""
SENSOR_PERIOD_S = 0.04
"""The hub sends body sensors at 25 Hz: the first step's dt."""
TELEMETRY_EVERY = 12
"""Control steps between telemetry messages (about 2 Hz, as the swarm driver's)."""


SAFETY = PetControllerConfig(stop_distance_m=0.04, limits=DriveLimits(max_speed=1.5, max_omega=1.5))
"""The safety stage for a swarm packed a few cm apart: stop 4 cm short (the Pet-Bot's 25 cm would freeze it).
Measured (corridor, seed 1): contacts 21 without it, 1 with it; 2 cm with a harder brake gave 9."""


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
        self._echoes = EchoRanges()
        self.counters = {"steps": 0, "stale_steps": 0, "human_seen": 0, "echoes_dropped": 0, "beacons": 0}
        self.engaged = False
        """True once the human's beacon was seen: the robot drives from then on."""
        self._sweep_t_us = 0
        self._sweep_at = -math.inf

    def tasks(self) -> list[Any]:
        """The coroutines the robot runs in surround mode."""
        return [self._control_loop()]

    def status(self) -> dict[str, Any]:
        """Counters and the last command, for the robot's status."""
        return {"engaged": self.engaged, "command": [round(float(v), 3) for v in self.command], **self.counters}

    async def _control_loop(self) -> None:
        await self._beacon_mode()
        fresh = asyncio.Event()
        self.radio.on_sensors.append(lambda _sensors: fresh.set())
        tick = 0
        points: dict[str, np.ndarray] = {}
        last_us: int | None = None
        while True:
            await fresh.wait()
            fresh.clear()
            sensors = self.radio.sensors
            if sensors is None:
                continue
            dt = SENSOR_PERIOD_S if last_us is None else (sensors.t_us - last_us) / 1e6
            last_us = sensors.t_us
            if dt <= 0:
                continue  # the hub restarted (its clock began again): wait for the next sample
            now = time.monotonic()
            t_us, beacons = self.radio.beacons
            if t_us != self._sweep_t_us:
                self._sweep_t_us, self._sweep_at = t_us, now
                points = beacon_points(beacons, self.config.ir, self.config.estimator, self.config.human_id)
            elif now - self._sweep_at > STALE_AFTER_S:
                points = {}
                self.counters["stale_steps"] += 1
            else:
                points = dead_reckon(points, np.array(sensors.odometry[:2]), dt)
            self._step(points, sensors, dt)
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

    def _step(self, points: dict[str, np.ndarray], sensors: OwnSensors, dt: float) -> None:
        config = self.config
        echoes = echo_points(sensors.ranges_m, sensors.angles_rad, config.law.robot_radius_m)
        seen = sense(points, echoes, config.human_id, config.sensing)
        if not self.engaged:
            if seen.human is None:
                return
            self.engaged = True
            self.log.record("surround_engaged", beacons=len(points))
        velocity = np.array(sensors.odometry[:2], dtype=float)
        wanted = self.controller.step(seen.neighbours, seen.obstacles, seen.human, velocity, dt)
        # the law's repulsion acts on IR estimates a sweep old; the ultrasonic ring is the last word
        safe = safety(MotorCommand(float(wanted[0]), float(wanted[1]), 0.0), self._echoes.ranges(sensors), SAFETY)
        self.command = np.array([safe.vx, safe.vy])
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
