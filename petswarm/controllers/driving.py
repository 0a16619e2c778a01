"""Driving with the user: owner detection over LF/BLE, the single robot's modes, and swarm driving.

The thin asyncio runtime over ``driving_core.DriverCore``, which decides everything (see its module): this
shell feeds it the robot's BLE messages, own-body samples, DriveStates and the formation's notifications with
``clock.now()``, wakes it when its timers are due, and carries out the actions it returns:

- waiting for a user, the robot fires an LF wake-up burst every 3 s; a belt holding its pattern within
  1 m answers over BLE and becomes the robot's owner (command-waiting);
- tracking (following, leading, master-driving), it fires LF every 350 ms from each antenna in turn; the
  belt answers with the two distances, which ``locate`` turns into the user's distance and bearing;
- the watch's requests select the operation (follow, lead, remote), cancel it, organize or disperse a
  swarm, change the driving mode, steer by gestures in remote control, or return from an exception;
- every 50 ms the controller of the current state produces a motor command; the master broadcasts
  ``DriveState`` every 100 ms on the swarm's PAN; a slave steers to its formation slot from its IR fix of
  the master, dead-reckoned between token rounds with its own odometry and the master's broadcast speed.

Each of the core's timers has its own waiter on the loop (``loop.call_at`` at exactly the core's deadline),
so at an instant the driver's steps interleave with the other managers' timers in the order they were set,
as the loops they replace did; an action is carried out the moment the core makes it.
"""

from __future__ import annotations

import asyncio
from typing import Any

from petswarm import clock
from petswarm.clock import sleep_until
from petswarm.controllers.driving_core import (
    BROADCAST_TIMER,
    CONTROL,
    LF,
    BleSend,
    Disperse,
    Drive,
    DriverAction,
    DriverCore,
    DrivingConfig,
    EchoRanges,
    HandOver,
    LfBurst,
    Log,
    Organize,
    SendSwarm,
    SetUser,
    Telemetry,
)
from petswarm.controllers.formation_shapes import Mode
from petswarm.controllers.motion import MotorCommand
from petswarm.managers import messages as m
from petswarm.managers.actions import Incoming
from petswarm.managers.event_log import EventLog
from petswarm.managers.formation import FormationError, NetworkFormation
from petswarm.managers.relative_location import RelativeLocationManager
from petswarm.managers.rf import RfCommunicationManager
from petswarm.managers.sequence import SequenceManager, TransitionError
from radio_hub.values import HubUnavailable, OwnSensors, RadioError

__all__ = ["Driver", "DrivingConfig", "EchoRanges", "sleep_until"]

FORMATION_ERRORS = (FormationError, RadioError, HubUnavailable, TransitionError)
"""How a formation request the driver asked for can fail (recorded, never fatal)."""


class Driver:
    """One robot's driving on the event loop: the core's events in, its actions out."""

    def __init__(
        self,
        robot_id: int,
        rf: RfCommunicationManager,
        sequence: SequenceManager,
        formation: NetworkFormation,
        locations: RelativeLocationManager,
        log: EventLog,
        config: DrivingConfig | None = None,
        pairing_seed: int = 0,
    ) -> None:
        self.rf = rf
        self.radio = rf.radio
        self.formation = formation
        self.log = log
        self.core = DriverCore(
            robot_id, sequence, formation, locations, clock.now(), config, self._execute, pairing_seed=pairing_seed
        )
        if self.radio.sensors is not None:  # a sample that came while the robot attached
            self.core.sensors_sample(self.radio.sensors, clock.now())
        self.radio.on_sensors.append(self._on_sensors)
        self._sends: list[SendSwarm] = []
        self._tasks: set[asyncio.Task[Any]] = set()

    # -- what the robot reads ----------------------------------------------------------------------

    @property
    def counters(self) -> dict[str, int]:
        """LF bursts, fixes and DriveStates heard."""
        return self.core.counters

    @property
    def owner(self) -> str | None:
        """The owner's belt node, if any."""
        return self.core.owner

    @property
    def mode(self) -> Mode:
        """Following or leading."""
        return self.core.mode

    @property
    def command(self) -> MotorCommand:
        """The last motor command."""
        return self.core.command

    # -- tasks -----------------------------------------------------------------------------------

    def tasks(self) -> list[Any]:
        """The coroutines the robot runs for driving."""
        self.core.start(clock.now())
        return [self._timer_loop(LF), self._ble_loop(), self._timer_loop(CONTROL), self._timer_loop(BROADCAST_TIMER)]

    async def _timer_loop(self, name: str) -> None:
        while True:
            when = self.core.timer(name)
            if when is None:  # never after an action: the sends it asked for are awaited below
                raise RuntimeError(f"driver timer {name} not armed")
            await sleep_until(when)
            self.core.fire(name, clock.now())
            await self._send_pending()

    async def _send_pending(self) -> None:
        """The DriveState a broadcast step made, awaited as the step's own (the next one is a period after)."""
        while self._sends:
            action = self._sends.pop(0)
            error = None
            try:
                await self.rf.send(action.dst, action.message, ack=action.ack)
            except (RadioError, HubUnavailable) as err:
                error = str(err)
            self.core.drive_state_sent(clock.now(), error)

    async def _ble_loop(self) -> None:
        while True:
            message = await self.radio.ble_receive()
            self.core.ble_message(message.src, message.payload, clock.now())

    def _on_sensors(self, sensors: OwnSensors) -> None:
        self.core.sensors_sample(sensors, clock.now())

    @staticmethod
    def handles(message: m.SwarmMessage) -> bool:
        """True for the messages this manager takes."""
        return isinstance(message, m.DriveState)

    def on_message(self, incoming: Incoming) -> None:
        """A DriveState heard on the air."""
        self.core.drive_state(incoming.sender, incoming.message, clock.now())

    def on_handover(self, old_chain: tuple[int, ...], msg: m.MasterHandover | None) -> None:
        """The formation moved the master's role (its callback)."""
        self.core.handover(old_chain, msg, clock.now())

    # -- actions -----------------------------------------------------------------------------------

    def _execute(self, action: DriverAction) -> None:
        radio = self.radio
        if isinstance(action, Log):
            self.log.record(action.kind, **action.detail)
        elif isinstance(action, Drive):
            radio.drive(action.command.vx, action.command.vy, action.command.omega)
        elif isinstance(action, LfBurst):
            radio.lf_burst(action.antenna, action.pattern, action.data)
        elif isinstance(action, BleSend):
            radio.ble_send(action.to, action.payload)
        elif isinstance(action, Telemetry):
            self._telemetry(action)
        elif isinstance(action, SetUser):
            self.formation.user = action.user
        elif isinstance(action, SendSwarm):
            self._sends.append(action)
        elif isinstance(action, Organize):
            self._spawn(self._organize(action.count))
        elif isinstance(action, Disperse):
            self._spawn(self._disperse())
        elif isinstance(action, HandOver):
            self._spawn(self._hand_over(action))

    def _telemetry(self, action: Telemetry) -> None:
        try:
            self.radio.telemetry(action.state, action.role, action.master, action.slot, action.mode)
        except Exception as err:  # telemetry is for viewers: never let it stop the controller
            self.log.record("error", where="telemetry", error=str(err))

    def _spawn(self, coro: Any) -> None:
        task = asyncio.get_running_loop().create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _organize(self, count: int) -> None:
        try:
            result = await self.formation.organize(count)
        except FORMATION_ERRORS as err:
            self.core.organized(None, str(err), clock.now())
            return
        self.core.organized(result.get("members"), None, clock.now())

    async def _disperse(self) -> None:
        error = None
        try:
            await self.formation.disperse()
        except FORMATION_ERRORS as err:
            error = str(err)
        self.core.dispersed(error, clock.now())

    async def _hand_over(self, action: HandOver) -> None:
        """The old master's side of Table 3's Change column; the formation does the radio part and calls
        ``on_handover`` back once the new master has accepted."""
        try:
            done = await self.formation.hand_over(
                action.chain, action.mode, action.shape, action.spacing, action.mirrored, action.kept, action.owner
            )
        except FORMATION_ERRORS as err:
            self.core.handed_over(False, f"{type(err).__name__}: {err}", clock.now())
            return
        self.core.handed_over(done, None, clock.now())
