"""The robot process: its radio, its managers as asyncio tasks, and its control channel.

For now a robot answers pings (and can ping its neighbours periodically) so the emulated air can be
exercised end to end; the swarm managers build on the same RF communication manager.
"""

from __future__ import annotations

import asyncio
import importlib
import math
import os
import resource
import signal
import sys
import threading
from collections import Counter, deque
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import msgpack
import zenoh

from petswarm import clock
from petswarm.control import all_robots_key, answer_relayed, guarded_handle, robot_key
from petswarm.controllers.driving import Driver
from petswarm.controllers.surround_driver import SurroundDriver
from petswarm.controllers.surround_pilot import SurroundDriverConfig
from petswarm.draws import Draws
from petswarm.managers.actions import Incoming
from petswarm.managers.decisions import WAITING_PAN
from petswarm.managers.event_log import EventLog
from petswarm.managers.formation import RESPONSES, FormationConfig, FormationError, NetworkFormation, Swarm
from petswarm.managers.message_processing import MessageProcessingManager
from petswarm.managers.messages import Blob, Ping, Pong, SwarmMessage
from petswarm.managers.relative_location import IrModuleManager, IrTokenSchedule, RelativeLocationManager, TokenConfig
from petswarm.managers.rf import RfCommunicationManager
from petswarm.managers.sequence import RobotState, SequenceManager, TransitionError
from petswarm.managers.serial_link import SerialLink
from petswarm.profiles import DEFAULT_PROFILE, check_profile, robot_profile
from petswarm.wearables.user_link import robot_node
from radio_hub.interface import DEFAULT_ENDPOINT, DEFAULT_WORLD, HubLink, Keys, LinkSecurity, RadioClient, open_session
from radio_hub.values import BROADCAST, FrameError, HubUnavailable, RadioError, RadioIdentity

DEFAULT_PAN = WAITING_PAN
"""The PAN every waiting robot starts on."""
EXT_ADDR_BASE = 0x00124B0000000000
"""Robot extended addresses: a fixed OUI-like prefix plus the robot id."""
COMMANDS = ("status", "ping", "send", "configure", "received", "organize", "disperse", "connect", "events", "stop")
AUTO_ID = 0
"""``--id auto``: claim the lowest id no live robot of the world uses."""
FORMATIONS = ("swarm", "surround")
"""``swarm``: the leader-follower middleware (organize, token IR, master and slaves); ``surround``: every
robot runs the surround law on its own beacons and echoes (docs/SURROUND.md)."""
LINK_STREAM = 0x5E7A
"""Third seed word of the serial link's draws."""
_GRID_SPACING_M = 1.5
_GRID_ROW = 5


def default_position(robot_id: int) -> tuple[float, float]:
    """Where a robot stands unless told: a grid 1.5 m apart, five to a row, so every robot hears every other."""
    index = robot_id - 1
    return (index % _GRID_ROW * _GRID_SPACING_M, index // _GRID_ROW * _GRID_SPACING_M)


@dataclass(frozen=True)
class RobotConfig:
    """What a robot process is started with."""

    robot_id: int
    endpoint: str = DEFAULT_ENDPOINT
    world: str = DEFAULT_WORLD
    pan_id: int = DEFAULT_PAN
    channel: int = 11
    position: tuple[float, float] | None = None
    """None: the default grid position of the robot's id."""
    ping_interval: float = 0.0
    """Seconds between broadcast pings (0: never ping on its own)."""
    seed: int = 0
    user: int = 0
    """The user this robot is connected to at start (0: none, the robot waits)."""
    formation: FormationConfig = field(default_factory=FormationConfig)
    token: TokenConfig = field(default_factory=TokenConfig)
    heading_deg: float = 0.0
    """Until the world model: the robot's fixed heading."""
    record: str | None = None
    """A JSON-lines file that gets every event as it happens (the run record)."""
    attach_timeout: float = 15.0
    """How long a robot waits for its hub at start (a hub started at the same moment needs a second)."""
    formation_mode: str = "swarm"
    """One of ``FORMATIONS``: which controller drives the robot."""
    surround: SurroundDriverConfig = field(default_factory=SurroundDriverConfig)
    """The surround law's gains and the human's beacon id (used in ``surround`` mode)."""
    profile: str = DEFAULT_PROFILE
    """The testbed profile (``petswarm.profiles``): the robot's MCU and UART between middleware and radio."""
    link_key: str | None = None
    """802.15.4 link security's network key, 32 hex digits (docs/SECURITY.md); None: off (plain frames)."""
    link_mic: int = 4
    """Bytes of a secured frame's MIC (4 or 8)."""

    def __post_init__(self) -> None:
        if self.formation_mode not in FORMATIONS:
            raise ValueError(f"formation_mode must be one of {FORMATIONS}, not {self.formation_mode!r}")
        check_profile(self.profile)

    def identity(self) -> RadioIdentity:
        """The robot's radio at start-up: short address = robot id."""
        if not 1 <= self.robot_id <= 0xFFFD:
            raise ValueError(f"robot id {self.robot_id} must be 1..65533 (it is the 16-bit short address)")
        position = self.position if self.position is not None else default_position(self.robot_id)
        return RadioIdentity(
            robot_node(self.robot_id),
            EXT_ADDR_BASE + self.robot_id,
            self.robot_id,
            self.pan_id,
            self.channel,
            position,
            self.heading_deg,
        )


EVENTS_ANSWER_BYTES = 3 << 20
"""The longest ``events`` answer: zenoh carries nothing over 4 MB to or from a petswarm process
(``radio_hub.interface.MAX_TRANSPORT_BYTES``); the record file keeps every event."""


def events_answer(events: list[dict[str, Any]]) -> dict[str, Any]:
    """The ``events`` command's answer: the latest events that fit in ``EVENTS_ANSWER_BYTES`` (``left_out``: the
    number of older ones that did not)."""
    kept = events
    while kept and len(msgpack.packb(kept, use_bin_type=True, default=str)) > EVENTS_ANSWER_BYTES:
        kept = kept[len(kept) // 2 :]
    return {"events": kept, "left_out": len(events) - len(kept)} if len(kept) < len(events) else {"events": kept}


class Robot:
    """One robot's middleware on top of its radio."""

    def __init__(self, config: RobotConfig, radio: RadioClient) -> None:
        self.config = config
        timing = robot_profile(config.profile).link
        # the link's own stream of draws: the robot's other draws stay what they are without a link
        link = None if timing.ideal else SerialLink(timing, Draws([config.seed, config.robot_id, LINK_STREAM]))
        if config.link_key is not None:
            radio.security = LinkSecurity(bytes.fromhex(config.link_key), config.link_mic)
        self.rf = RfCommunicationManager(radio, link)
        # numpy's default_rng draws, without loading numpy.random into every robot process
        self.rng = Draws([config.seed, config.robot_id])
        self.log = EventLog(sink=open(config.record, "a", encoding="utf-8") if config.record else None)  # noqa: SIM115
        self.sequence = SequenceManager(self.log, RobotState.FOLLOWING if config.user else RobotState.WAITING)
        self.mpm = MessageProcessingManager(self.log)
        formation_config = replace(config.formation, waiting_pan=config.pan_id)
        self.formation = NetworkFormation(
            self.rf, self.sequence, self.mpm, self.log, formation_config, self.rng, config.user, self._swarm_changed
        )
        self.formation.rests = config.formation_mode == "surround"
        self.ir = IrModuleManager(radio)
        self.locations = RelativeLocationManager()
        self.schedule = IrTokenSchedule(
            self.rf,
            self.mpm,
            self.ir,
            self.locations,
            self.log,
            config.token,
            self._heading_deg,
            self.formation.note_answers,
        )

        self.driver = Driver(
            config.robot_id, self.rf, self.sequence, self.formation, self.locations, self.log, pairing_seed=config.seed
        )
        self.formation.on_handover = self.driver.on_handover
        self.surround = (
            SurroundDriver(radio, self.ir, self.log, config.surround) if config.formation_mode == "surround" else None
        )
        radio.on_reattach.append(self._reattached)
        radio.on_relayed = answer_relayed(self.handle, radio, self._spawn)
        pan, pan_at_us = radio.pan_on_air or (radio.identity.pan_id, 0)
        self.log.record(
            "start",
            robot_id=config.robot_id,
            state=self.sequence.state.label,
            user=config.user,
            seed=config.seed,
            pan=pan,
            pan_at_us=pan_at_us,
        )
        # the hub's PAN for us and since when (its model time): what a frame handed up late is judged by
        radio.on_pan_change.append(lambda pan, at_us: self.log.record("pan", pan=pan, at_us=at_us))

        self.started = clock.now()
        self.pings_sent = 0
        self.pings_answered = 0
        self.heard_from: Counter[int] = Counter()
        self.recent: deque[dict[str, Any]] = deque(maxlen=200)
        self.stopping = asyncio.Event()
        self._nonce = 0
        self._waiting: dict[int, asyncio.Queue[tuple[int, float]]] = {}
        self._tasks: set[asyncio.Task[Any]] = set()

    # -- tasks -----------------------------------------------------------------------------------

    async def run(self) -> None:
        """Serve until ``stopping`` is set."""
        workers = [
            asyncio.create_task(coro)
            for coro in (
                self._receive_loop(),
                self.formation.watch(),
                self.ir.run(),
                self.schedule.watch(),
                *(self.driver.tasks() if self.surround is None else self.surround.tasks()),
            )
        ]
        if self.config.ping_interval > 0:
            workers.append(asyncio.create_task(self._ping_loop()))
        stop = asyncio.create_task(self.stopping.wait())
        done, _ = await asyncio.wait([*workers, stop], return_when=asyncio.FIRST_COMPLETED)
        for task in [*workers, stop, *self._tasks]:
            task.cancel()
        for task in done:
            if task is not stop and task.exception() is not None:
                raise task.exception()  # type: ignore[misc]

    async def _receive_loop(self) -> None:
        while True:
            incoming = await self.rf.receive()
            try:
                self._check_pan(incoming)
                self._remember(incoming)
                await self._on_message(incoming)
            except Exception as err:  # one message must not stop the robot hearing the next
                self.rf.radio.faults.record("receive", err, type(incoming.message).__name__)

    def _check_pan(self, incoming: Incoming) -> None:
        """Note a frame whose destination PAN is neither the one we asked for nor the broadcast PAN
        (``foreign_pan``, with its air time): one the hub's MAC took on the PAN we had before a change (applied a
        round trip after we ask), or held up by a delay fault or the UART, is fine; one for a PAN we were not on
        when it was on the air means a filter went wrong. ``petswarm explore`` tells the two apart from the
        ``pan`` events' times (``pan_hearing``), by what was on the air, not by how late the frame came."""
        frame = incoming.rx.frame
        pan = self.rf.radio.identity.pan_id
        if frame.dst_pan in (pan, BROADCAST):
            return
        self.log.record(
            "foreign_pan",
            dst_pan=frame.dst_pan,
            pan=pan,
            src=incoming.sender,
            seq=frame.seq,
            air_end_us=incoming.rx.end_us,
        )

    async def _on_message(self, incoming: Incoming) -> None:
        msg = incoming.message
        if self.mpm.offer(incoming) or self.schedule.offer(incoming):
            return
        if self.formation.handles(msg):
            self._spawn(self.formation.on_message(incoming))
        elif self.schedule.handles(msg):
            self._spawn(self.schedule.on_message(incoming))
        elif self.driver.handles(msg):
            self.driver.on_message(incoming)
        elif isinstance(msg, RESPONSES):
            self.mpm.count_late()
        elif isinstance(msg, Ping):
            self._spawn(self._answer(incoming.sender, msg.nonce))
        elif isinstance(msg, Pong):
            self.heard_from[incoming.sender] += 1
            waiter = self._waiting.get(msg.nonce)
            if waiter is not None:
                waiter.put_nowait((incoming.sender, clock.now()))

    async def _answer(self, dst: int, nonce: int) -> None:
        result = await self.rf.send(dst, Pong(nonce))
        if result.ok:
            self.pings_answered += 1

    async def _ping_loop(self) -> None:
        interval = self.config.ping_interval
        await asyncio.sleep(float(self.rng.uniform(0, interval)))
        while True:
            try:
                await self.ping(BROADCAST, wait=0.0)
            except (HubUnavailable, RadioError) as err:  # the hub may be restarting: keep pinging
                self.log.record("error", where="ping", error=str(err))
            await asyncio.sleep(float(self.rng.uniform(0.5, 1.5)) * interval)

    def _heading_deg(self) -> float:
        """The AHRS yaw (the heading exchange's value), or the attach heading before the first reading."""
        sensors = self.rf.radio.sensors
        return math.degrees(sensors.yaw_rad) if sensors is not None else self.rf.radio.identity.heading_deg

    def _reattached(self) -> None:
        """The radio attached again to a restarted hub: tell it the IR module's mode too."""
        self.log.record("reattached", pan_id=self.rf.radio.identity.pan_id, ir_mode=self.ir.mode)
        if self.ir.mode != "idle":
            self._spawn(self.rf.radio.set_ir_mode(self.ir.mode))

    def _swarm_changed(self, swarm: Swarm | None) -> None:
        """Formation tells us the swarm changed: the IR schedule follows."""
        if swarm is None:
            if self.schedule.active:
                self._spawn(self.schedule.leave())
            return
        chain = (swarm.master, *swarm.members)
        if self.schedule.session != swarm.session:
            self.schedule.join(swarm.session, chain, swarm.neighbours, swarm.number == 0)
        elif self.schedule.is_master != (swarm.number == 0):
            self.schedule.rejoin(chain, swarm.neighbours, swarm.number == 0)
        else:
            self.schedule.update_members(chain, swarm.neighbours)

    def _spawn(self, coro: Any) -> None:
        task = asyncio.create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._task_done)

    def _task_done(self, task: asyncio.Task[Any]) -> None:
        # a handler that failed (the hub went away mid-answer, say) is recorded, never lost silently
        self._tasks.discard(task)
        if not task.cancelled() and task.exception() is not None:
            err = task.exception()
            self.log.record("error", where=task.get_coro().__qualname__, error=f"{type(err).__name__}: {err}")

    def _remember(self, incoming: Incoming) -> None:
        rx = incoming.rx
        self.recent.append(
            {
                "src": rx.frame.src,
                "dst": rx.frame.dst,
                "pan_id": rx.frame.dst_pan,
                "type": type(incoming.message).__name__.lower(),
                "rssi_dbm": rx.rssi_dbm,
                "lqi": rx.lqi,
                "end_us": rx.end_us,
            }
        )

    async def close(self) -> None:
        """End the handlers still at work, record the last event (the run's record keeps the driving totals),
        leave the air, close the record. Handlers go first: one that failed after ``stop`` (an answer the hub
        never took, as the run ends) would put an error after the record's last event."""
        pending = list(self._tasks)
        for task in pending:
            task.cancel()
        await asyncio.gather(*pending, return_exceptions=True)
        self.log.record("stop", driving=dict(self.driver.counters))
        await self.rf.radio.close()
        if self.log.sink is not None:
            self.log.sink.close()

    # -- actions ---------------------------------------------------------------------------------

    async def ping(self, dst: int, wait: float = 1.0) -> dict[str, Any]:
        """Send a ping and collect pongs for ``wait`` seconds."""
        self._nonce = (self._nonce + 1) & 0xFFFFFFFF
        nonce = self._nonce
        replies: asyncio.Queue[tuple[int, float]] = asyncio.Queue()
        self._waiting[nonce] = replies
        start = clock.now()
        try:
            result = await self.rf.send(dst, Ping(nonce))
            self.pings_sent += 1
            await asyncio.sleep(wait)
        finally:
            self._waiting.pop(nonce, None)
        answers = []
        while not replies.empty():
            src, at = replies.get_nowait()
            answers.append({"from": src, "rtt_ms": round((at - start) * 1000, 3)})
        return {"tx": _result_dict(result), "replies": answers}

    async def handle(self, cmd: dict[str, Any]) -> dict[str, Any]:
        """Carry out one control command; errors come back as ``{"error": ...}``."""
        name = cmd.get("cmd")
        try:
            if name == "status":
                return self.status()
            if name == "ping":
                return await self.ping(int(cmd.get("dst", BROADCAST)), float(cmd.get("wait", 1.0)))
            if name == "send":
                return await self._send_blob(cmd)
            if name == "configure":
                radio = await self.rf.radio.configure(
                    **{k: int(cmd[k]) for k in ("pan_id", "short_addr", "channel") if k in cmd}
                )
                return {"radio": _identity_dict(radio)}
            if name == "received":
                return {"frames": list(self.recent)}
            if name == "stop":
                self.stopping.set()
                return {"stopping": True}
            if name == "organize":
                return await self.formation.organize(int(cmd.get("count", 0)), cmd.get("protocol"))
            if name == "disperse":
                return await self.formation.disperse(cmd.get("protocol"))
            if name == "connect":
                return self._connect_user(int(cmd.get("user", 1)), str(cmd.get("mode", "following")))
            if name == "events":
                return events_answer(list(self.log.events))
        except (FrameError, RadioError, HubUnavailable, FormationError, TransitionError, ValueError, TypeError) as err:
            return {"error": f"{type(err).__name__}: {err}"}
        return {"error": f"unknown command {name!r}; known: {', '.join(COMMANDS)}"}

    def _connect_user(self, user: int, mode: str) -> dict[str, Any]:
        """Stand-in for the LF/BLE pairing the wearables issue brings: this robot now serves ``user``."""
        states = {
            "following": RobotState.FOLLOWING,
            "leading": RobotState.LEADING,
            "remote-control": RobotState.REMOTE_CONTROL,
        }
        if mode not in states or user < 1:
            raise ValueError(f"need user >= 1 and mode one of {sorted(states)}")
        if self.sequence.state in (RobotState.ORGANIZING, RobotState.MASTER_DRIVING, RobotState.SLAVE_DRIVING):
            raise ValueError(f"robot is {self.sequence.state.label}: the swarm must disperse before its user changes")

        self.formation.user = user
        self.sequence.transition(states[mode], user=user)
        return {"state": self.sequence.state.label, "user": user}

    async def _send_blob(self, cmd: dict[str, Any]) -> dict[str, Any]:
        only = cmd.get("only")
        if only is not None and self.config.robot_id not in only:
            return {"skipped": True}
        size = int(cmd.get("payload_len", 20))
        filler = bytes(max(size - 4, 0))
        msg: SwarmMessage = Blob(int(cmd.get("tag", 0)), filler)
        result = await self.rf.send(
            int(cmd.get("dst", BROADCAST)), msg, dst_pan=cmd.get("dst_pan"), ack=bool(cmd.get("ack", True))
        )
        return {"tx": _result_dict(result)}

    def status(self) -> dict[str, Any]:
        """Counters and radio state, for ``petswarm run`` summaries and tests."""
        radio = self.rf.radio
        return {
            "robot_id": self.config.robot_id,
            "pid": os.getpid(),
            "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
            "radio": _identity_dict(radio.identity),
            "uptime_s": round(clock.now() - self.started, 3),
            "pings_sent": self.pings_sent,
            "pings_answered": self.pings_answered,
            "heard_from": dict(self.heard_from),
            "messages_received": self.rf.received,
            "malformed_payloads": self.rf.malformed,
            "tx_results": dict(self.rf.tx_results),
            "radio_malformed": radio.malformed,
            "link_security": None if radio.security is None else radio.security.counters.to_dict(),
            "transport_gaps": radio.transport_gaps,
            "radio_dropped": {**radio.dropped, "link": radio.link_dropped},
            "faults": radio.faults.to_dict(),
            "state": self.sequence.state.label,
            "user": self.formation.user if self.sequence.user_connected else 0,
            "swarm": None if self.formation.swarm is None else self.formation.swarm.to_dict(),
            "organizations": self.formation.organizations,
            "retries": self.mpm.retries,
            "duplicates": self.mpm.duplicates,
            "late_responses": self.mpm.late,
            "ir": self.schedule.status(),
            "driving": {
                "owner": self.driver.owner,
                "mode": str(self.driver.mode),
                "command": [
                    round(v, 3) for v in (self.driver.command.vx, self.driver.command.vy, self.driver.command.omega)
                ],
                **self.driver.counters,
                "unpaired": self.driver.core.unpaired,
            },
            "relative_location": self.locations.snapshot(clock.now()),
            "surround": None if self.surround is None else self.surround.status(),
        }


def _result_dict(result: Any) -> dict[str, Any]:
    d = asdict(result)
    d["status"] = result.status.value
    return d


def _identity_dict(radio: RadioIdentity) -> dict[str, Any]:
    d = asdict(radio)
    d["position"] = list(radio.position)
    return d


CONTROL_PENDING = 64
"""Control commands a robot has in hand at once (a flood on its control keys is dropped and counted)."""
CONTROL_MAX_BYTES = 64 << 10
"""The longest control command a robot reads."""


class ControlServer:
    """Serves a robot's control queryable and the all-robots topic on the robot's event loop."""

    def __init__(self, session: zenoh.Session, robot: Robot) -> None:
        self.robot = robot
        self.malformed = 0
        self.dropped = 0
        """Commands refused unread: too long, or ``CONTROL_PENDING`` already in hand."""
        self._pending = 0
        self._lock = threading.Lock()
        self._loop = asyncio.get_running_loop()
        keys = Keys(robot.rf.radio.world)
        self._decls = [
            session.declare_queryable(robot_key(keys, robot.config.robot_id), self._on_query),
            session.declare_subscriber(all_robots_key(keys), self._on_broadcast),
        ]

    def _on_query(self, query: zenoh.Query) -> None:
        size = 0 if query.payload is None else len(query.payload)
        if not self._admit(size):
            query.drop()  # unanswered: the asker times out
            return
        payload = query.payload.to_bytes() if query.payload is not None else b""
        self._hand_over(query, payload)

    def _on_broadcast(self, sample: zenoh.Sample) -> None:
        if self._admit(len(sample.payload)):
            self._hand_over(None, sample.payload.to_bytes())

    def _hand_over(self, query: zenoh.Query | None, payload: bytes) -> None:
        coro = self._answer(query, payload)
        try:
            self._loop.call_soon_threadsafe(self.robot._spawn, coro)
        except RuntimeError:  # the robot's loop has closed: the process is ending
            coro.close()
            with self._lock:
                self._pending -= 1

    def _admit(self, size: int) -> bool:
        """Zenoh's thread: at most ``CONTROL_PENDING`` commands of at most ``CONTROL_MAX_BYTES`` in hand."""
        with self._lock:
            if size > CONTROL_MAX_BYTES or self._pending >= CONTROL_PENDING:
                self.dropped += 1
                return False
            self._pending += 1
            return True

    async def _answer(self, query: zenoh.Query | None, payload: bytes) -> None:
        try:
            await self._answer_one(query, payload)
        finally:
            with self._lock:
                self._pending -= 1

    async def _answer_one(self, query: zenoh.Query | None, payload: bytes) -> None:
        try:
            cmd = msgpack.unpackb(payload, raw=False)
            if not isinstance(cmd, dict):
                raise ValueError("command is not a map")
        except Exception as err:  # garbage on the control key must not hurt the robot
            self.malformed += 1
            answer: dict[str, Any] = {"error": f"malformed command: {type(err).__name__}"}
        else:
            answer = await guarded_handle(self.robot.handle, cmd, self.robot.rf.radio.faults)
        if query is not None:
            try:
                query.reply(query.key_expr, msgpack.packb(answer, use_bin_type=True))
            finally:
                query.drop()

    def close(self) -> None:
        """Undeclare the control keys."""
        for decl in self._decls:
            decl.undeclare()


async def attach(config: RobotConfig) -> tuple[RobotConfig, RadioClient]:
    """Put the robot on the air, waiting up to ``attach_timeout`` for a hub that is still starting."""
    deadline = clock.now() + config.attach_timeout
    told = False
    while True:
        try:
            return await _attach_once(config)
        except HubUnavailable:
            if clock.now() >= deadline:
                raise
            if not told:
                print(
                    f"robot {config.robot_id or 'auto'}: waiting for a hub of world {config.world!r} at "
                    f"{config.endpoint} (up to {config.attach_timeout:g} s)",
                    file=sys.stderr,
                    flush=True,
                )
                told = True
            await asyncio.sleep(0.5)


async def _attach_once(config: RobotConfig) -> tuple[RobotConfig, RadioClient]:
    """One attempt; with ``AUTO_ID`` claim ids 1, 2, ... until one is free."""
    if config.robot_id != AUTO_ID:
        return config, await RadioClient.connect(config.identity(), config.endpoint, config.world, timeout=1.0)
    session = await asyncio.to_thread(open_session, "client", config.endpoint)
    for candidate in range(1, 0xFFFE):
        claimed = replace(config, robot_id=candidate)
        try:
            radio = await RadioClient.connect(
                claimed.identity(), config.endpoint, config.world, session=session, exclusive=True, timeout=1.0
            )
        except RadioError as err:
            if "is taken" in str(err):
                continue
            session.close()
            raise
        except HubUnavailable:
            session.close()
            raise
        radio.link.owns_session = True  # type: ignore[attr-defined]  # the claim's session is the radio's
        return claimed, radio
    raise RadioError("every robot id is taken")


def load_numpy() -> None:
    """Import numpy now, before the robot attaches (the middleware's modules take it lazily, ``radio_hub.lazy``).

    Left to its first use, numpy came with a slave's first IR sweep, inside the join handshake: its import
    (about 0.1 CPU-s, a second of wall time on a loaded machine) held the loop while the master waited for
    the answer to its joining notice, and the master gave the robot up as missing. Every robot that joins a
    swarm needs numpy; a robot process pays its memory (7 MB more peak RSS in ``petswarm bench scale``, shared by
    robots forked from the fork server, which loads it too) rather than a stall when its timing matters most."""
    importlib.import_module("numpy")


async def run_robot(config: RobotConfig, link: HubLink | None = None) -> int:
    """The robot process's main coroutine; returns the exit code. ``link``: the port to the hub (default:
    zenoh to ``config.endpoint``, waiting for a hub that is still starting; a lockstep link is already open)."""
    load_numpy()
    try:
        if link is None:
            config, radio = await attach(config)
        else:
            radio = await RadioClient.connect(config.identity(), world=config.world, link=link, timeout=5.0)
    except (HubUnavailable, RadioError) as err:
        print(f"robot {config.robot_id or 'auto'}: {err}", file=sys.stderr)
        return 2
    robot = Robot(config, radio)
    control = ControlServer(radio.session, robot)
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, robot.stopping.set)
    print(
        f"robot {config.robot_id}: attached as {radio.identity.node_id} "
        f"(short 0x{radio.identity.short_addr:04x}, PAN 0x{radio.identity.pan_id:04x}, "
        f"channel {radio.identity.channel})",
        file=sys.stderr,
        flush=True,
    )
    try:
        await robot.run()
    except HubUnavailable as err:
        print(f"robot {config.robot_id}: {err}", file=sys.stderr)
        return 3
    finally:
        control.close()
        await robot.close()
        clock.work_done(loop)  # the next SIGTERM must not kill a robot that has stopped
    return 0
