"""One surround robot's brain, pure: a body-sensor sample and the latest beacon sweep in, a motor command out.

The robot process's ``surround_driver`` feeds it from the hub (real time); ``petswarm/bench/surround.py`` feeds it
from the hub's world and IR models stepped in model time. Both run this very code, so what the model-time
bench shows is what a robot process does, less its scheduling.

Each step (on every body-sensor sample, 25 Hz, with the model time between samples as dt; the hub sweeps
beacons with the body sensors, ``radio_hub.environment.BEACONS_EVERY``, so a step takes in the sweep of its own
instant, and steps on without one when a sample comes alone):
1. the beacon tracker (``surround_sensing.BeaconTracker``) moves every tracked beacon on by dt, and takes
   in a new sweep's fixes when one came (a robot that gets no sweep for ``STALE_AFTER_S`` forgets them all,
   and steps on its echoes alone, so it still keeps off walls and slows to a stop);
2. the tracked beacons and the ultrasonic echoes become neighbours, obstacles and the human
   (``surround_sensing.sense``);
3. the surround law (``surround.SurroundController``, or ``surround_improved.ImprovedSurroundController`` when
   the config's ``law`` is ``improved``, which also takes the human's tracked velocity and the wall points of
   its echo memory, ``surround_memory.EchoMemory``) turns them into a velocity, with the fresh odometry as the
   law's own velocity;
4. the Pet-Bot's safety stage on the ultrasonic ring (``SAFETY``) has the last word.

Why every sensor sample: stepping only per sweep (50 ms) made the swarm bounce (the repulsion Q / d^2 is
stiff near contact, and a 50 ms step behind it oscillates); stepping faster than odometry comes (50 Hz on
often stale samples) lost the velocity increments of the stale steps; stepping on the last command instead of
the odometry let the law's velocity drift from the real one (pushes, the drive's ramp) into contacts.

The formation forms round a person: the pilot sends nothing until it first sees the human's beacon, then runs
the law from then on, whether it sees him or not (without him, f_G is zero and the local forces keep it
with its neighbours). Robots started before their human would otherwise gather where he is about to stand.
The command is (vx, vy): the law assumes a fixed heading, so the robot never turns.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from petswarm.controllers.driving_core import EchoRanges
from petswarm.controllers.motion import DriveLimits
from petswarm.controllers.pet_controller import PetControllerConfig, SafetyStage
from petswarm.controllers.surround import SurroundConfig, SurroundController
from petswarm.controllers.surround_improved import ImprovedSurroundController
from petswarm.controllers.surround_memory import EchoMemory
from petswarm.controllers.surround_safe import SafeSurroundController
from petswarm.controllers.surround_sensing import (
    BeaconTracker,
    SensingConfig,
    SweepJob,
    beacon_fixes,
    echo_list,
    explained_echoes,
    sense_lists,
)
from radio_hub.datasheet import IrConfig
from radio_hub.values import BeaconSweep, OwnSensors, lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

STALE_AFTER_S = 0.2
"""No new sweep for this long (five periods of the hub's 25 Hz beacon sweeps): nothing is seen any more."""
SENSOR_PERIOD_S = 0.04
"""The hub sends body sensors at 25 Hz: the first step's dt."""

SAFETY = PetControllerConfig(stop_distance_m=0.04, limits=DriveLimits(max_speed=1.5, max_omega=1.5))
"""The safety stage for a swarm packed a few cm apart: stop 4 cm short (the Pet-Bot's 25 cm would freeze it).
Measured (corridor, seed 1): contacts 21 without it, 1 with it; 2 cm with a harder brake gave 9."""
SAFETY_IMPROVED = PetControllerConfig(
    stop_distance_m=0.04, k_approach=4.0, limits=DriveLimits(max_speed=1.5, max_omega=1.5)
)
"""The improved law's safety stage: closing on an echo at up to 4 /s times the gap beyond 4 cm (1.5 /s in
``SAFETY``), still within braking at 1 m/s^2. The law itself holds its speed toward each tracked neighbour and
the human to what stops short of them; at 1.5 /s the ring also slowed a robot the walking human was about to
reach from behind to 0.7 m/s, 3 cm in front of a neighbour going his pace (cylinder seeds 8, 9: he walked
into it). Measured: cylinder seeds 8 and 9 from one robot-human contact each to none."""

TRACKED_NEARER_M = 0.03
"""``safety_tracked``: an echo nearer than a tracked body's estimated surface by more than this is not taken to move
with it (it may be a wall's end the body stands next to; the IR estimate is a few cm off)."""


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


class SurroundPilot:
    """One robot in the surround formation, without I/O: ``step`` per body-sensor sample."""

    def __init__(self, config: SurroundDriverConfig) -> None:
        self.config = config
        improved = config.law.law == "improved"
        safe = config.law.law == "safe"
        self.controller: SurroundController
        if improved:
            self.controller = ImprovedSurroundController(config.law)
        elif safe:
            self.controller = SafeSurroundController(config.law, config.person_radius_m)
        else:
            self.controller = SurroundController(config.law)
        self.tracker = BeaconTracker()
        self._command = (0.0, 0.0)
        self.engaged = False
        """True once the human's beacon was seen: the robot drives from then on."""
        self.counters = {"steps": 0, "stale_steps": 0, "human_seen": 0, "echoes_dropped": 0, "beacons": 0}
        self._echoes = EchoRanges()
        self._memory = EchoMemory()
        self._safety = SafetyStage(SAFETY_IMPROVED if improved or safe else SAFETY)
        self._sensing = config.sensing
        self._last_us: int | None = None
        self._sweep_t_us = 0
        self._sweep_at = -float("inf")
        self._ring_angles: np.ndarray | None = None
        self._ring_trig: tuple[list[float], list[float]] = ([], [])
        self._given: tuple[BeaconSweep, list[str], np.ndarray] | None = None
        """A sweep's fixes worked out for it ahead of its step (``give_fixes``)."""
        self._batched_with: SurroundDriverConfig | None = None
        """A config found equal to this pilot's (``_batchable``): compared once, not on every step."""

    @property
    def command(self) -> np.ndarray:
        """The last motor command (vx, vy) sent, (0, 0) before the first."""
        return np.array(self._command)

    def wants(self, sweep: BeaconSweep) -> bool:
        """Whether the next step would estimate ``sweep`` (it is new, and its fixes were not given)."""
        return sweep.t_us != self._sweep_t_us and (self._given is None or self._given[0] is not sweep)

    def sweep_job(self, sweep: BeaconSweep) -> SweepJob | None:
        """What the next step would estimate from ``sweep`` (None: nothing, the sweep is not new or its fixes
        were given): so that a runtime can estimate many robots' sweeps at once (``beacon_fixes_batch``)."""
        if not self.wants(sweep):
            return None
        names, readings, gains = sweep.arrays()
        return SweepJob(names, readings, gains, self.config.human_id)

    def give_fixes(self, sweep: BeaconSweep, seen: list[str], xy: np.ndarray) -> None:
        """The fixes of ``sweep``, worked out elsewhere exactly as ``step`` would (``beacon_fixes_batch`` of its
        ``sweep_job``): the step that takes it in uses them."""
        self._given = (sweep, seen, xy)

    def step(self, sensors: OwnSensors, sweep: BeaconSweep, now_s: float) -> tuple[float, float] | None:
        """The motor command (vx, vy) for this sample, or None to send nothing (no human seen yet, or a sample
        from before the last one: the hub restarted and its clock began again). ``sweep`` is the latest beacon
        sweep (a new one when its time changed); ``now_s`` the receiver's clock, to tell when sweeps stopped."""
        dt = SENSOR_PERIOD_S if self._last_us is None else (sensors.t_us - self._last_us) / 1e6
        self._last_us = sensors.t_us
        if dt <= 0:
            return None
        self._track(sensors, sweep, dt, now_s)
        return self._drive(sensors, dt)

    def batchable(self, sensors: OwnSensors, config: SurroundDriverConfig, ring: int) -> bool:
        """Whether this pilot's step may go with others' (``surround_batch``): the paper's law without the
        centroid filter, ``config`` as the rest, and a ring of ``ring`` sensors that reads as a robot's does
        (no negative range, finite odometry: the others fail alone, as they would), whose ring holds no sample of
        this instant already (its safety stage would read that one's ranges: another ring's, or a negative one)."""
        if type(self.controller) is not SurroundController or config.law.centroid_filter_s != 0:
            return False
        if config is not self._batched_with:  # the configs of a run's robots are equal, not one object
            # equal to the bit: == takes -0.0 for 0.0 (and 1 for 1.0), and the batch steps all with one config
            if self.config != config or repr(self.config) != repr(config):
                return False
            self._batched_with = config
        odometry = sensors.odometry
        return (
            len(sensors.angles_rad) == ring
            and not self._echoes.holds(sensors.t_us)
            and len(odometry) == 3
            and math.isfinite(odometry[0])
            and math.isfinite(odometry[1])
            and math.isfinite(odometry[2])
        )

    def _track(self, sensors: OwnSensors, sweep: BeaconSweep, dt: float, now_s: float) -> None:
        own_velocity = np.array(sensors.odometry[:2], dtype=float)
        self.tracker.predict(own_velocity, dt)
        fixes = self._new_fixes(sweep, now_s)
        if fixes is not None:
            self.tracker.update_many(*fixes, own_velocity)

    def _new_fixes(self, sweep: BeaconSweep, now_s: float) -> tuple[list[str], np.ndarray] | None:
        """The fixes of ``sweep`` if it is new (given, or estimated now), else None; a robot whose sweeps
        stopped ``STALE_AFTER_S`` ago forgets its tracks."""
        if sweep.t_us != self._sweep_t_us:
            self._sweep_t_us, self._sweep_at = sweep.t_us, now_s
            given, self._given = self._given, None
            if given is not None and given[0] is sweep:
                return given[1], given[2]
            config = self.config
            names, readings, gains = sweep.arrays()
            return beacon_fixes(names, readings, gains, config.ir, config.estimator, config.human_id)
        if now_s - self._sweep_at > STALE_AFTER_S:
            self.tracker.clear()
            self.counters["stale_steps"] += 1
        return None

    def _drive(self, sensors: OwnSensors, dt: float) -> tuple[float, float] | None:
        config = self.config
        tracker = self.tracker
        ranges = sensors.ranges_list()
        echoes = echo_list(ranges, *self._ring(sensors.angles_rad), config.law.robot_radius_m)
        neighbours, obstacles, human, dropped = sense_lists(
            tracker.names, tracker.positions, echoes, config.human_id, self._sensing
        )
        if not self.engaged and human is None:
            return None
        self.engaged = True
        velocity = (float(sensors.odometry[0]), float(sensors.odometry[1]))
        controller = self.controller
        if isinstance(controller, ImprovedSurroundController):
            names, moving = tracker.names, tracker.velocities.tolist()
            others = [v for name, v in zip(names, moving, strict=True) if name != config.human_id]
            own = tracker.velocity_of(config.human_id)
            # the improved law keeps off the human's body itself (his centre and velocity): his surface point,
            # which sensing put last among the obstacles, is left out
            echoes = obstacles if human is None else obstacles[:-1]
            walls = self._remember(sensors, tracker.names, tracker.positions, velocity, dt)
            vx, vy = controller.step_plain(neighbours, echoes, human, velocity, dt, own, others, walls)
        elif isinstance(controller, SafeSurroundController):
            names, moving = tracker.names, tracker.velocities.tolist()
            others = [v for name, v in zip(names, moving, strict=True) if name != config.human_id]
            own = tracker.velocity_of(config.human_id)
            walls = self._remember(sensors, tracker.names, tracker.positions, velocity, dt)
            vx, vy = controller.step_plain(neighbours, obstacles, human, velocity, dt, own, others, walls)
        else:
            vx, vy = controller.step_plain(neighbours, obstacles, human, velocity, dt)
        # the law's repulsion acts on IR estimates up to a sweep old; the ultrasonic ring is the last word
        angles, echo_ranges, receding = self._echoes.floats(sensors, ranges)
        filtered = isinstance(controller, ImprovedSurroundController | SafeSurroundController)
        if filtered and config.law.safety_tracked > 0:
            receding = self._tracked_receding(sensors, receding)
        vx, vy = self._safety.translation(vx, vy, angles, echo_ranges, receding)
        self._command = (vx, vy)
        self.counters["steps"] += 1
        self.counters["human_seen"] += human is not None
        self.counters["echoes_dropped"] += dropped
        self.counters["beacons"] = len(tracker.names)
        return vx, vy

    def _tracked_receding(self, sensors: OwnSensors, receding: tuple[float, ...]) -> tuple[float, ...]:
        """The safety stage's receding speeds, each echo a tracked body explains (within its radius and
        ``echo_match_m``: as ``explained_echoes`` decides) raised to that body's tracked speed away along the beam,
        less what it may have lost since its track saw it (``brake_mps2`` times ``track_lag_s``). The ring's own
        rate is over ~0.2 s and an echo that was not there then (a neighbour stepping into the cone) has none: the
        stage took it to stand still, and slowed a robot just ahead of the walking human behind neighbours going
        his pace (corridor seed 5: to 0.4 m/s, and he walked into it)."""
        law = self.config.law
        ranges = sensors.ranges_list()
        cos, sin = self._ring(sensors.angles_rad)
        tracker = self.tracker
        names, rows, moving = tracker.names, tracker.positions.tolist(), tracker.velocities.tolist()
        if not names:
            return receding
        match = self._sensing.echo_match_m
        radii = [
            self._sensing.person_radius_m if name == self.config.human_id else law.robot_radius_m for name in names
        ]
        lost = law.brake_mps2 * law.track_lag_s
        out = list(receding) if receding else [0.0] * len(ranges)
        for k, (r, c, s) in enumerate(zip(ranges, cos, sin, strict=True)):
            if not math.isfinite(r):
                continue
            reach = law.robot_radius_m + r
            px, py = c * reach, s * reach
            for (bx, by), (ux, uy), radius in zip(rows, moving, radii, strict=True):
                # within the body, and not nearer than its surface by more than TRACKED_NEARER_M (a wall's end
                # next to a neighbour: its echo comes from in front of the neighbour's surface)
                if math.hypot(px - bx, py - by) <= radius + match and reach >= math.hypot(bx, by) - radius - (
                    TRACKED_NEARER_M
                ):
                    away = ux * c + uy * s - lost
                    if away > out[k]:
                        out[k] = away
                    break
        return tuple(out)

    def _remember(
        self, sensors: OwnSensors, names: list[str], positions: np.ndarray, velocity: tuple[float, float], dt: float
    ) -> list[tuple[float, float]]:
        """The echo memory's step (``surround_memory``): the wall points the law must stop short of or pass."""
        ranges = sensors.ranges_list()
        cos, sin = self._ring(sensors.angles_rad)
        radius = self.config.law.robot_radius_m
        points = [(c * (radius + r), s * (radius + r)) for r, c, s in zip(ranges, cos, sin, strict=True)]
        explained = explained_echoes(points, names, positions, self.config.human_id, self._sensing)
        return self._memory.step(ranges, cos, sin, explained, velocity, dt, radius)

    def _ring(self, angles_rad: np.ndarray) -> tuple[list[float], list[float]]:
        """The cosines and sines of the ultrasonic sensors' angles, worked out again only when the ring changes."""
        if self._ring_angles is not angles_rad:
            self._ring_angles = angles_rad
            self._ring_trig = (np.cos(angles_rad).tolist(), np.sin(angles_rad).tolist())
        return self._ring_trig
