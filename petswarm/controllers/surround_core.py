"""The surround driver's logic as a sans-IO object: sensor samples and ``now`` in, actions out.

Around the pure ``surround_pilot.SurroundPilot`` (whose numerics it does not touch), ``SurroundCore`` decides
what the robot process does in the surround formation: first ask for the IR module's ``beacon`` mode
(``SetIrMode``; retried every 0.5 s while the hub refuses or is away, ``handle_timer``), then on every
own-body sample step the pilot and command the motors (``Drive``), record when the robot first engages
(``Log``) and tell viewers every ``TELEMETRY_EVERY`` steps (``Telemetry``). No clock, no radio, no asyncio:
``petswarm.controllers.surround_driver.SurroundDriver`` runs it on the loop.
"""

from __future__ import annotations

from petswarm.controllers.driving_core import Drive, Telemetry
from petswarm.controllers.motion import MotorCommand
from petswarm.controllers.surround_batch import step_pilots
from petswarm.controllers.surround_pilot import SurroundDriverConfig, SurroundPilot
from petswarm.managers.actions import Log, SetIrMode
from radio_hub.values import BeaconSweep, OwnSensors

TELEMETRY_EVERY = 12
"""Control steps between telemetry messages (about 2 Hz, as the swarm driver's)."""
BEACON_RETRY_S = 0.5
"""A refused or unanswered request for beacon mode goes again this much later."""


SurroundAction = SetIrMode | Drive | Log | Telemetry


class SurroundCore:
    """One robot in the surround formation: beacon mode first, then the pilot on every body-sensor sample."""

    def __init__(self, config: SurroundDriverConfig) -> None:
        self.config = config
        self.pilot = SurroundPilot(config)
        self.beaconing = False
        """True once the IR module is in beacon mode: samples before that are not stepped on."""
        self._asking = False
        self._retry_at: float | None = None
        self._steps = 0
        self._outbox: list[SurroundAction] = []

    def actions(self) -> list[SurroundAction]:
        """The actions made since the last call, in order."""
        out, self._outbox = self._outbox, []
        return out

    def start(self, now: float) -> None:
        """Ask for beacon mode."""
        self._ask()

    def next_timer(self) -> float | None:
        """When a refused beacon-mode request goes again (None: none waiting)."""
        return self._retry_at

    def handle_timer(self, now: float) -> None:
        """Ask for beacon mode again if the retry is due."""
        if self._retry_at is not None and now >= self._retry_at:
            self._retry_at = None
            self._ask()

    def ir_mode_set(self, now: float) -> None:
        """The IR module is in beacon mode: the robot starts sensing its neighbours and its human."""
        self._asking, self.beaconing = False, True
        self._outbox.append(Log("surround_start", {"human": self.config.human_id}))

    def ir_mode_failed(self, error: str, now: float) -> None:
        """The hub refused beacon mode or is away: record it and try again ``BEACON_RETRY_S`` on."""
        self._asking = False
        self._outbox.append(Log("error", {"where": "surround_beacon_mode", "error": error}))
        self._retry_at = now + BEACON_RETRY_S

    def sensors_sample(self, sensors: OwnSensors, beacons: BeaconSweep, now: float) -> None:
        """A fresh own-body sample with the latest beacon sweep: step the pilot, command the motors."""
        if not self.beaconing:
            return
        engaged = self.pilot.engaged
        self._commanded(engaged, self.pilot.step(sensors, beacons, now))

    @staticmethod
    def sensors_samples(
        cores: list[SurroundCore], samples: list[tuple[OwnSensors, BeaconSweep]], now: float
    ) -> list[Exception | None]:
        """``sensors_sample`` of many cores at one instant, their pilots stepped together
        (``surround_batch.step_pilots``); each core's error (its pilot's step's), or None."""
        stepping = [k for k, core in enumerate(cores) if core.beaconing]
        engaged = [cores[k].pilot.engaged for k in stepping]
        pilots = [cores[k].pilot for k in stepping]
        results = step_pilots(pilots, [samples[k] for k in stepping], now)
        errors: list[Exception | None] = [None] * len(cores)
        for k, was, result in zip(stepping, engaged, results, strict=True):
            if isinstance(result, Exception):
                errors[k] = result
            else:
                cores[k]._commanded(was, result)
        return errors

    def _commanded(self, engaged: bool, command: tuple[float, float] | None) -> None:
        """The pilot's step gave ``command`` (None: nothing to send); it had engaged before if ``engaged``."""
        if command is None:
            return
        if not engaged:
            self._outbox.append(Log("surround_engaged", {"beacons": self.pilot.counters["beacons"]}))
        self._outbox.append(Drive(MotorCommand(command[0], command[1], 0.0)))
        self._steps += 1
        if self._steps % TELEMETRY_EVERY == 0:
            self._outbox.append(Telemetry("surround", "", "", None, "surround"))

    def _ask(self) -> None:
        if not self._asking:
            self._asking = True
            self._outbox.append(SetIrMode("beacon"))
