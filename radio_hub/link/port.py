"""The radio port: what a node (a robot, a wearable, a test) uses to get on the air, whatever carries it.

``RadioClient`` gives an asyncio node the RF calls of a real 802.15.4 radio driver:
``await send(frame) -> TxResult``, ``await receive() -> RxFrame`` (or ``async for``), and
``await configure(pan_id=..., short_addr=..., channel=...)`` at run time, plus the body's links (motors,
own sensors, IR, BLE, LF). It speaks ``wire`` messages to the hub's environment through a ``HubLink``:
``radio_hub.link.zenoh_link.ZenohLink`` between processes, or a link in memory bound to the environment in a
model-time run (``runner.model``). This module imports no zenoh.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import math
import os
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING, Any, Protocol

from radio_hub.air.mac import BROADCAST, Frame, FrameError, FrameType, TxStatus
from radio_hub.air.security import LinkSecurity, SecurityError
from radio_hub.guard import Faults
from radio_hub.lazy import lazy_numpy
from radio_hub.link import wire
from radio_hub.link.keys import DEFAULT_ENDPOINT, DEFAULT_WORLD, check_name
from radio_hub.link.values import (
    MODEL_EPOCH_S,
    BeaconSweep,
    BleMessage,
    HubUnavailable,
    IrSweep,
    LfBurstHeard,
    OwnSensors,
    RadioError,
    RadioIdentity,
    RxFrame,
    TxResult,
)
from radio_hub.physics.ble import MAX_PAYLOAD as BLE_MAX_PAYLOAD
from radio_hub.physics.light import RECEIVERS as IR_RECEIVERS

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

# The radio's values live in ``values`` (pure): named here too, as the port hands them out.
__all__ = [
    "MODEL_EPOCH_S",
    "BeaconSweep",
    "BleMessage",
    "HubLink",
    "HubUnavailable",
    "IrSweep",
    "LfBurstHeard",
    "OwnSensors",
    "RadioClient",
    "RadioError",
    "RadioIdentity",
    "RxFrame",
    "TxResult",
]


class HubLink(Protocol):
    """How a node's messages reach the hub's environment and its answers come back.

    ``open`` starts the link: from then on ``on_down(data)`` is called on the node's event loop with every
    message for the node (its bytes; a link in memory may hand the message itself over, which the node checks
    as it would decode it), and ``on_hub(present)`` whenever the hub appears or goes away. A link with
    ``takes_messages`` true (in memory) also has ``put_message(msg)``, which takes the ``HANDED_UP``
    messages as they are. ``put`` sends one
    encoded message up (in order, never dropped by the transport); ``close`` ends the node's presence.
    """

    def open(
        self,
        node_id: str,
        instance: str,
        on_down: Callable[[bytes | wire.Message], None],
        on_hub: Callable[[bool], None],
    ) -> None:
        """Start delivering to the node."""

    def put(self, data: bytes) -> None:
        """One encoded message to the hub."""

    async def close(self) -> None:
        """Leave: the hub sees the node go."""


HANDED_UP = (wire.Drive, wire.Place)
"""The node-to-hub messages a link in memory takes as they are: the bulk of the uplink (motor commands and a
user's pose), every field a number the sender made a Python float, so the hub sees what the bytes would
decode to (it checks them as it would decode them)."""


REQUEST_TIMEOUT_S = 5.0

"""How long a node waits for the hub's answer to a request once attached."""


RESEND_S = 0.5
"""An idempotent request (re-attach, configure, IR mode) unanswered this long is sent again."""

QUEUE_LIMIT = 1000
"""Received frames, IR sweeps, BLE messages and LF bursts each waiting for the node at most; past it the
oldest is dropped and counted (``RadioClient.dropped``): a flood costs the node messages, not memory."""
LF_MAX_DATA = 4
"""User data bytes an LF burst carries."""
MAX_GAP = 1 << 32
"""Missing messages one message's number may account for (as the hub counts its own uplink gaps)."""
MAX_COUNT = (1 << 63) - 1
"""Where a node's counters stop: every count stays packable (msgpack takes integers below 2^64)."""
ERRORS_KEPT = 100
"""The hub's latest error reasons a radio keeps (``RadioClient.errors``)."""


class RadioClient:
    """One node's 802.15.4 radio, attached to the hub's air."""

    def __init__(self, link: HubLink, world: str, identity: RadioIdentity) -> None:
        self.identity = identity
        self.world = world
        self.request_timeout = 5.0
        self.malformed = 0
        self.transport_gaps = 0
        self.errors: deque[str] = deque(maxlen=ERRORS_KEPT)
        self.dropped: Counter[str] = Counter()
        """Messages from the hub dropped because their queue was full, per queue (``rx``, ``ir``, ``ble``,
        ``lf``)."""
        self.faults = Faults(f"radio {identity.node_id}")
        """Unexpected exceptions while handling the hub's messages (each message is dropped, the node goes on)."""
        self.link = link
        self._hands_over = bool(getattr(link, "takes_messages", False))
        self._loop = asyncio.get_running_loop()
        self._rx: asyncio.Queue[RxFrame] = asyncio.Queue(QUEUE_LIMIT)
        self._ir: asyncio.Queue[IrSweep] = asyncio.Queue(QUEUE_LIMIT)
        self._ble: asyncio.Queue[BleMessage] = asyncio.Queue(QUEUE_LIMIT)
        self._lf: asyncio.Queue[LfBurstHeard] = asyncio.Queue(QUEUE_LIMIT)
        self.sensors: OwnSensors | None = None
        """The latest own-body sensors (robots; the hub sends them at 25 Hz)."""
        self.beacons = BeaconSweep(0, {}, {})
        """The latest beacon sweep, in beacon mode."""
        self.on_sensors: list[Callable[[OwnSensors], None]] = []
        self.on_relayed: Callable[[wire.Relayed], None] | None = None
        """Where control messages relayed by the hub go (model and lockstep runs); None: counted as malformed."""
        self.security: LinkSecurity | None = None
        """802.15.4 link security (``radio_hub.air.security``): None, the default, sends and takes plain frames;
        set, every data frame leaves secured and only authentic, fresh secured frames are handed up."""
        self._ultrasonic_deg: tuple[float, ...] = ()
        """The ultrasonic ring's axes (degrees from the heading), as the hub gave them on attaching."""
        self._ultrasonic_rad: np.ndarray | None = None
        self._pending: dict[int, asyncio.Future[Any]] = {}
        self._pending_types: dict[int, str] = {}
        self._on_tx_done: dict[int, Callable[[TxResult], None]] = {}
        """Frames handed over with ``transmit``: the callback of each, by token."""
        self.on_frame: Callable[[RxFrame], None] | None = None
        """Where received frames go instead of the queue ``receive`` reads (a high-rate node's lean path)."""

        self._tokens = itertools.count(1)
        self._up_seq = itertools.count(1)
        self._down_seq = 0
        self._dsn = itertools.count()
        node_id = identity.node_id
        # os.urandom as secrets does, without secrets: it brings hmac, random and base64 (with them OpenSSL's
        # _hashlib) into every node process, about 0.5 MB of RSS
        self.instance = os.urandom(8).hex()
        self.session_key = (int.from_bytes(os.urandom(8), "big") >> 1) or 1  # 63 random bits, never 0
        """Sent with every message: the hub refuses this id's messages with any other key while we are
        attached (someone else's session speaking for us)."""
        self.reattaches = 0
        self.hub_present = True
        """False while the hub's liveliness token is gone (the hub died or restarts): silence means nothing."""

        self.on_reattach: list[Callable[[], None]] = []
        """Called after the radio attached again to a restarted hub (the hub forgot IR modes and the like)."""
        self.pan_on_air: tuple[int, int] | None = None
        """(PAN, model us): the PAN the hub's MAC filters this radio's frames by, and when the hub applied it (its
        answer's time). ``identity.pan_id`` is what we asked for, which the hub applies a round trip later; a
        frame's ``RxFrame.end_us`` against this tells which PAN it was received on, however late it is handed up."""
        self.on_pan_change: list[Callable[[int, int], None]] = []
        """Called with (PAN, model us the hub applied it) when the hub's PAN for this radio changes."""
        self._attached_once = False
        self._ir_wanted = "idle"
        """The IR mode last asked for: a switch retried after a re-attach must not undo a later one."""
        self._reattaching: asyncio.Task[None] | None = None
        if hasattr(link, "session_key"):  # a link that speaks for the node itself (a lockstep idle)
            link.session_key = self.session_key
        if hasattr(link, "on_built"):  # a link in memory: the environment's own messages come to on_built
            link.on_built = self.on_built
        link.open(node_id, self.instance, self._on_down, self._hub_seen)

    @classmethod
    async def connect(
        cls,
        identity: RadioIdentity,
        endpoint: str = DEFAULT_ENDPOINT,
        world: str = DEFAULT_WORLD,
        *,
        session: Any = None,
        link: HubLink | None = None,
        timeout: float = 5.0,
        exclusive: bool = False,
    ) -> RadioClient:
        """Attach ``identity`` to the hub; raises HubUnavailable if none answers.

        ``link`` is the port to the hub (default: zenoh to ``endpoint``, on ``session`` if given, which the
        radio then leaves open). With ``exclusive`` the hub refuses (RadioError) when a live node already
        uses the id.
        """
        check_name("node", identity.node_id)
        if link is None:
            from radio_hub.link.zenoh_link import ZenohLink  # here: a node in memory never loads zenoh

            link = await ZenohLink.connect(endpoint, world, session)
        client = cls(link, world, identity)
        client.request_timeout = timeout
        # a zenoh link that gave up waiting for the hub to open its up key has put nothing anywhere yet: its
        # key may open a moment later (a hub busy with a rogue's tokens), so the attach goes again until answered,
        # as a re-attach does; not an exclusive one, whose second copy the hub would refuse as ours taking our id
        resend = RESEND_S if getattr(link, "unheard", False) and not exclusive else None
        try:
            attached = await client._request(0, client._attach_message(exclusive), resend_s=resend)
        except (HubUnavailable, RadioError):
            await client.close(detach=False)
            raise
        client._adopt(attached)
        client._attached_once = True
        client.request_timeout = max(timeout, REQUEST_TIMEOUT_S)
        return client

    @property
    def session(self) -> Any:
        """The zenoh session this radio uses (a node may serve its own keys on it); None off zenoh."""
        return getattr(self.link, "session", None)

    # -- the radio ---------------------------------------------------------------------------------

    def next_dsn(self) -> int:
        """The MAC data sequence number for the next frame (wraps at 256)."""
        return next(self._dsn) & 0xFF

    def data_frame(self, dst: int, payload: bytes, *, dst_pan: int | None = None, ack: bool = True) -> Frame:
        """A data frame from this node; ``ack`` asks for an acknowledgement (ignored for broadcast)."""
        me = self.identity
        return Frame(
            FrameType.DATA,
            self.next_dsn(),
            me.pan_id if dst_pan is None else dst_pan,
            dst,
            me.pan_id,
            me.short_addr,
            payload,
            ack_request=ack and dst != BROADCAST,
        )

    async def send(self, frame: Frame) -> TxResult:
        """Hand a frame to the MAC and wait for its result. FrameError if it cannot be encoded."""
        if self.security is not None:
            try:
                frame = self.security.protect_auto(frame)
            except SecurityError as err:
                raise FrameError(f"cannot secure the frame: {err}") from None
        psdu = frame.encode()
        for attempt in range(2):
            token = next(self._tokens)
            try:
                done: wire.TxDone = await self._request(token, wire.Transmit(token=token, psdu=psdu))
                break
            except RadioError as err:
                if str(err) != wire.NOT_ATTACHED or attempt:
                    raise
                await self._reattached()  # a restarted hub: attach again, then send once more
        return _tx_result(done)

    def transmit(self, frame: Frame, on_done: Callable[[TxResult], None]) -> int:
        """Hand a frame to the MAC without waiting; returns its token. ``on_done`` gets the result on the loop,
        as ``send`` returns it (a refusal by the hub comes as REFUSED with its reason). The lean path of a
        high-rate node: no future, task or timer per frame. Nor a timeout: a frame the hub never answers (it
        died) never calls back, and one sent before a hub restart is settled as REFUSED on the re-attach.
        FrameError if the frame cannot be encoded."""
        token = next(self._tokens)
        self._put(wire.Transmit(token=token, psdu=frame.encode()))
        self._on_tx_done[token] = on_done
        return token

    async def receive(self) -> RxFrame:
        """The next received frame."""
        return await self._rx.get()

    async def set_ir_mode(self, mode: str) -> None:
        """Switch the IR module: ``idle``, ``receive`` or ``transmit``; returns once the hub has it."""
        self._ir_wanted = mode
        token = next(self._tokens)
        try:
            await self._request(token, wire.SetIrMode(token=token, mode=mode), resend_s=RESEND_S)
        except RadioError as err:
            if str(err) != wire.NOT_ATTACHED:
                raise
            # a restarted hub that has not had our attach yet: attach, then switch (a mode is idempotent),
            # unless a later switch has taken its place meanwhile (the hub applies switches in order)
            await self._reattached()
            if mode != self._ir_wanted:
                return
            token = next(self._tokens)
            await self._request(token, wire.SetIrMode(token=token, mode=mode), resend_s=RESEND_S)

    async def ir_sample(self) -> IrSweep:
        """The next sweep of the 12 phototransistors (arrives only while receiving and something shines)."""
        return await self._ir.get()

    # -- the body and the wearables' links --------------------------------------------------------

    def drive(self, vx: float, vy: float, omega: float) -> None:
        """Command the motors (robot frame, m/s and rad/s); the motor controller's watchdog stops the
        robot if no command comes for half a second."""
        self._put(wire.Drive(vx=float(vx), vy=float(vy), omega=float(omega)))

    def place(self, x: float, y: float, yaw: float, vx: float = 0.0, vy: float = 0.0, omega: float = 0.0) -> None:
        """A user's pose and motion in the world frame (users walk; the world does not move them)."""
        self._put(wire.Place(x=float(x), y=float(y), yaw=float(yaw), vx=float(vx), vy=float(vy), omega=float(omega)))

    def lf_burst(self, antenna: str, pattern: int, data: bytes) -> None:
        """Fire one LF burst from the ``left`` or ``right`` antenna (one-way, not answered)."""
        self._put(wire.LfBurst(antenna=antenna, pattern=int(pattern), data=bytes(data)))

    def relay(self, to: str, body: bytes) -> None:
        """A control message to node ``to`` (or ``hub``), carried by the hub outside the emulated air."""
        self._put(wire.Relay(to=to, body=bytes(body)))

    def ble_send(self, to: str, payload: bytes) -> None:
        """A BLE message to another node (not answered; the link may drop it)."""
        self._put(wire.BleSend(to=to, payload=bytes(payload)))

    def telemetry(
        self, state: str, role: str = "", master: str = "", slot: tuple[float, float] | None = None, mode: str = ""
    ) -> None:
        """Tell the hub what this robot believes (for viewers and metrics only)."""
        self._put(
            wire.Telemetry(
                state=state,
                role=role,
                master=master,
                slot=None if slot is None else [float(slot[0]), float(slot[1])],
                mode=mode,
            )
        )

    async def ble_receive(self) -> BleMessage:
        """The next BLE message."""
        return await self._ble.get()

    async def lf_heard(self) -> LfBurstHeard:
        """The next LF burst the belt's front end heard (users)."""
        return await self._lf.get()

    def __aiter__(self) -> RadioClient:
        return self

    async def __anext__(self) -> RxFrame:
        return await self._rx.get()

    async def configure(
        self,
        *,
        pan_id: int | None = None,
        short_addr: int | None = None,
        channel: int | None = None,
        position: tuple[float, float] | None = None,
    ) -> RadioIdentity:
        """Change the radio at run time; returns the radio as the hub now has it. RadioError if refused."""
        token = next(self._tokens)
        msg = wire.Configure(
            token=token,
            pan_id=pan_id,
            short_addr=short_addr,
            channel=channel,
            position=None if position is None else list(position),
        )
        wanted = {
            k: v
            for k, v in (("pan_id", pan_id), ("short_addr", short_addr), ("channel", channel), ("position", position))
            if v is not None
        }
        before = self.identity
        # what we want is our identity from now on: an attach to a restarted hub in the meantime applies it
        self.identity = replace(before, **wanted)
        try:
            self._adopt(await self._request(token, msg, resend_s=RESEND_S))
        except RadioError as err:
            if str(err) != wire.NOT_ATTACHED:
                self.identity = before  # refused: the radio stays as it was
                raise
            try:
                await self._reattached()
            except RadioError:
                self.identity = before  # the new hub refused what we wanted: keep what worked
                raise
        return self.identity

    async def close(self, detach: bool = True) -> None:
        """Leave the air and close the link."""
        if detach:
            with contextlib.suppress(HubUnavailable):
                self._put(wire.Detach())
        for fut in self._pending.values():
            if not fut.done():
                fut.set_exception(HubUnavailable("radio closed"))
        await self.link.close()

    # -- plumbing ----------------------------------------------------------------------------------

    def _adopt(self, attached: wire.Attached) -> None:
        if self.pan_on_air is None or self.pan_on_air[0] != attached.pan_id:
            self.pan_on_air = (attached.pan_id, attached.now_us)
            for callback in self.on_pan_change:
                callback(attached.pan_id, attached.now_us)
        self.identity = replace(
            self.identity,
            ext_addr=attached.ext_addr,
            short_addr=attached.short_addr,
            pan_id=attached.pan_id,
            channel=attached.channel,
            position=(attached.position[0], attached.position[1]),
            heading_deg=attached.heading_deg,
        )
        self._ultrasonic_deg = tuple(attached.ultrasonic_deg)
        self._ultrasonic_rad = None

    def _put(self, msg: wire.Message) -> None:
        msg.n, msg.s = next(self._up_seq), self.session_key
        if self._hands_over and isinstance(msg, HANDED_UP):
            self.link.put_message(msg)  # type: ignore[attr-defined]
        else:
            self.link.put(msg.encode())

    @property
    def link_dropped(self) -> int:
        """Messages the link dropped before they reached the node's loop (too long, or too many waiting)."""
        return int(getattr(self.link, "dropped", 0))

    def _enqueue(self, name: str, queue: asyncio.Queue[Any], item: Any) -> None:
        """Into a bounded queue; when full, the oldest goes (the freshest reading is the useful one)."""
        if queue.full():
            queue.get_nowait()
            self.dropped[name] += 1
        queue.put_nowait(item)

    async def _request(self, token: int, msg: wire.Message, resend_s: float | None = None) -> Any:
        """Send ``msg`` and wait up to ``request_timeout`` for the hub's answer to ``token``. With ``resend_s``
        (idempotent requests only) the message goes again every ``resend_s`` until answered: one sent just
        as the hub restarted, or answered before the router had our subscription back, is lost without a
        trace, and waiting out the whole timeout left a robot deaf for 5 s after a hub restart."""
        fut: asyncio.Future[Any] = self._loop.create_future()
        self._pending[token] = fut
        self._pending_types[token] = msg.TYPE
        deadline = self._loop.time() + self.request_timeout
        try:
            while True:
                self._put(msg)
                left = deadline - self._loop.time()
                # asyncio.wait leaves the future alone on a timeout, so a resend can still be answered
                done, _ = await asyncio.wait({fut}, timeout=left if resend_s is None else min(resend_s, left))
                if done:
                    return fut.result()
                if self._loop.time() >= deadline:
                    raise HubUnavailable(
                        f"no answer from the hub of world {self.world!r} within {self.request_timeout} s"
                    )
        finally:
            self._pending.pop(token, None)
            self._pending_types.pop(token, None)
            if fut.done() and not fut.cancelled():
                fut.exception()  # a caller cancelled as the radio closed: its error is seen, never warned about

    def _on_down(self, data: bytes | wire.Message) -> None:
        """One message from the hub, or a batch of them (``wire.encode_batch``), encoded or handed over in
        memory; never raises (anything unexpected is counted in ``faults``, a malformed batch in ``malformed``
        and dropped whole)."""
        if isinstance(data, bytes) and wire.is_batch(data):
            try:
                parts = wire.split_batch(data)
            except wire.WireError:
                self.malformed += 1
                return
            for part in parts:
                self._on_one(part)  # a part is one message: a batch inside a batch is malformed
        else:
            self._on_one(data)

    def on_built(self, msg: wire.Message) -> None:
        """One of the messages the environment built in this very process and handed over as it is (a model
        run's body sensors and beacon sweeps, ``environment.HANDED_OVER``), taken without ``wire.check``: no
        peer can put anything on a link in memory (a node process's messages come as bytes to ``_on_down``,
        decoded and checked), and the environment makes every field of these a value the check passes (its
        own names and numbering, float32 bytes). Its floats are not sure: a robot's finite but huge command
        makes its velocity nan (the rotation into the world frame overflows), so its yaw, odometry and gains
        are tested here, one sum each (nan and inf carry through a sum), and a message whose sum is not finite
        takes the checked way (``_on_one``), counted as malformed and dropped as before where the check refuses
        it. A message handed to ``_on_down`` is still checked, whoever hands it. Never raises."""
        if type(msg) is wire.Sensors:
            odometry = msg.odometry
            sure = len(odometry) == 3 and math.isfinite(msg.yaw + odometry[0] + odometry[1] + odometry[2])
        else:
            gains = msg.gains  # type: ignore[attr-defined]
            sure = len(gains) <= 1024 and math.isfinite(sum(gains))  # (wire: a gain per beacon, 1024 at most)
        if not sure:
            self._on_one(msg)
            return
        try:
            self._on_message(msg)
        except Exception as err:
            self.faults.record("downlink", err, msg.TYPE)

    def _on_one(self, data: bytes | wire.Message) -> None:
        try:
            msg = wire.check(data) if isinstance(data, wire.Message) else wire.decode(data)
        except wire.WireError:
            self.malformed += 1
            return
        try:
            self._on_message(msg)
        except Exception as err:
            self.faults.record("downlink", err, msg.TYPE)

    def _count_gap(self, n: int) -> None:
        """Messages missing before number ``n``: at most ``MAX_GAP`` per message, and the sum saturates below
        2^63, so forged numbers can never make the counter unpackable (a status answer that cannot be encoded
        is never sent: the robot's status query went unanswered for good)."""
        self.transport_gaps = min(self.transport_gaps + min(n - self._down_seq - 1, MAX_GAP), MAX_COUNT)

    def _on_message(self, msg: wire.Message) -> None:
        kind = type(msg)
        if kind is wire.Sensors or kind is wire.IrBeacons:  # most of the traffic, by its exact type
            if msg.n > self._down_seq + 1:
                self._count_gap(msg.n)
            if msg.n > self._down_seq:
                self._down_seq = msg.n
            if kind is wire.Sensors:
                self._on_sensors(msg)  # type: ignore[arg-type]
            else:
                self._on_beacons(msg)  # type: ignore[arg-type]
            return
        if isinstance(msg, (wire.Attached, wire.Error)) and msg.instance not in ("", self.instance):
            return  # another process claiming our id at the same moment: its answer, not ours
        if isinstance(msg, wire.Attached) and msg.token == 0:
            self._down_seq = msg.n - 1  # the hub numbers afresh on every attach
        if msg.n > self._down_seq + 1:
            self._count_gap(msg.n)
        self._down_seq = max(self._down_seq, msg.n)
        if isinstance(msg, wire.Received):
            self._on_received(msg)
        elif isinstance(msg, wire.IrSample):
            self._on_ir(msg)
        elif isinstance(msg, wire.Sensors):
            self._on_sensors(msg)
        elif isinstance(msg, wire.BleReceived):
            if len(msg.payload) > BLE_MAX_PAYLOAD:
                self.malformed += 1
                return
            self._enqueue("ble", self._ble, BleMessage(msg.src, msg.payload, msg.t_us))
        elif isinstance(msg, wire.LfHeard):
            if len(msg.data) > LF_MAX_DATA:
                self.malformed += 1
                return
            heard = LfBurstHeard(msg.antenna, msg.pattern, msg.data, msg.rssi_dbm, msg.t_us)
            self._enqueue("lf", self._lf, heard)
        elif isinstance(msg, wire.Grant):
            pass  # lockstep: the link has already moved the clock; the grant only keeps the numbering whole
        elif isinstance(msg, wire.Relayed) and self.on_relayed is not None:
            self.on_relayed(msg)
        elif isinstance(msg, wire.IrBeacons):
            self._on_beacons(msg)
        elif isinstance(msg, wire.TxDone) and msg.token in self._on_tx_done:
            self._on_tx_done.pop(msg.token)(_tx_result(msg))
        elif isinstance(msg, (wire.TxDone, wire.Attached)):
            self._resolve(msg.token, msg)
        elif isinstance(msg, wire.Error):
            self.errors.append(msg.reason)
            on_done = self._on_tx_done.pop(msg.token, None)
            if on_done is not None:
                on_done(TxResult(TxStatus.REFUSED, 0, 0, 0, 0, msg.reason))
            fut = self._pending.get(msg.token)
            if fut is not None and not fut.done() and not self._answers_a_tokenless_message(msg):
                fut.set_exception(RadioError(msg.reason))
            if msg.reason == wire.NOT_ATTACHED:
                self._start_reattach()  # the hub restarted and forgot us
        else:
            self.malformed += 1

    def _answers_a_tokenless_message(self, error: wire.Error) -> bool:
        """A hub that does not know us answers a message without a token (a drive, say) "not attached" with
        token 0, the token of our attach: never an answer to the attach itself, which it takes. Failing the
        attach on it had a robot give up a re-attach the hub then took, and keep the radio it had before."""
        return error.reason == wire.NOT_ATTACHED and self._pending_types.get(error.token) == wire.Attach.TYPE

    def _on_received(self, msg: wire.Received) -> None:
        try:
            frame = Frame.decode(msg.psdu)
        except FrameError:
            self.malformed += 1
            return
        if self.security is not None:
            try:
                frame = self.security.unprotect(frame)
            except SecurityError:
                return  # counted by kind in the security's counters
        rx = RxFrame(frame, msg.rssi_dbm, msg.lqi, msg.start_us, msg.end_us, msg.submitted_us)
        if self.on_frame is not None:
            self.on_frame(rx)
        else:
            self._enqueue("rx", self._rx, rx)

    def _on_ir(self, msg: wire.IrSample) -> None:
        if len(msg.readings) != 4 * IR_RECEIVERS:
            self.malformed += 1
            return
        self._enqueue("ir", self._ir, IrSweep(np.frombuffer(msg.readings, dtype="<f4").astype(float), msg.t_us))

    def _ultrasonic_angles(self) -> np.ndarray:
        """The ring's axes in radians, one array shared by every sample until the next attach."""
        if self._ultrasonic_rad is None:
            self._ultrasonic_rad = np.radians(np.asarray(self._ultrasonic_deg, dtype=float))
        return self._ultrasonic_rad

    def _on_sensors(self, msg: wire.Sensors) -> None:
        if len(msg.ranges) != 4 * len(self._ultrasonic_deg):  # 4 bytes a float32: a range per sensor
            self.malformed += 1
            return
        odometry = (float(msg.odometry[0]), float(msg.odometry[1]), float(msg.odometry[2]))
        self.sensors = OwnSensors.of_wire(
            msg.t_us, bytes(msg.ranges), self._ultrasonic_angles, float(msg.yaw), odometry
        )
        for callback in self.on_sensors:
            callback(self.sensors)

    def _on_beacons(self, msg: wire.IrBeacons) -> None:
        if len(msg.readings) != 4 * IR_RECEIVERS * len(msg.sources):
            self.malformed += 1
            return
        block = np.frombuffer(msg.readings, dtype="<f4").astype(float)
        gains = msg.gains or [1.0] * len(msg.sources)
        if block.size != len(msg.sources) * IR_RECEIVERS or len(gains) != len(msg.sources):
            self.malformed += 1
            return
        # (min and max: the wire checks made every gain a finite int or float)
        if gains and not (min(gains) > 0 and max(gains) <= 1):
            self.malformed += 1
            return
        block = block.reshape(-1, IR_RECEIVERS)
        gains = list(map(float, gains))
        if len(set(msg.sources)) == len(msg.sources):
            self.beacons = BeaconSweep.of_block(msg.t_us, msg.sources, block, gains)
        else:  # a source named twice: its last sweep counts, as in a map
            readings = dict(zip(msg.sources, block, strict=True))
            self.beacons = BeaconSweep(msg.t_us, readings, dict(zip(msg.sources, gains, strict=True)))

    def _hub_seen(self, present: bool) -> None:
        self.hub_present = present
        if present and self._attached_once:
            self._start_reattach()

    def _start_reattach(self) -> None:
        if self._reattaching is None or self._reattaching.done():
            self._reattaching = self._loop.create_task(self._reattach())
            self._reattaching.add_done_callback(self._reattach_done)

    def _reattach_done(self, task: asyncio.Task[None]) -> None:
        # nobody may await a re-attach started by the hub's reappearance or its "not attached": its failure
        # (no hub, or a refusal, perhaps forged) is counted here, and the next hint starts another
        if not task.cancelled() and task.exception() is not None:
            self.faults.record("reattach", task.exception())  # type: ignore[arg-type]

    async def _reattached(self) -> None:
        self._start_reattach()
        assert self._reattaching is not None
        await asyncio.shield(self._reattaching)

    def _attach_message(self, exclusive: bool = False) -> wire.Attach:
        """Attach with the radio as this node wants it now."""
        me = self.identity
        return wire.Attach(
            ext_addr=me.ext_addr,
            short_addr=me.short_addr,
            pan_id=me.pan_id,
            channel=me.channel,
            position=list(me.position),
            heading_deg=float(me.heading_deg),
            instance=self.instance,
            exclusive=exclusive,
            kind=me.kind,
        )

    async def _reattach(self) -> None:
        orphans = [token for token in self._pending if token]  # sent before this attach: to the dead hub
        orphaned_frames, self._on_tx_done = self._on_tx_done, {}
        sent = self._attach_message()
        attached = await self._request(0, sent, resend_s=RESEND_S)
        # a configure while we attached (a robot going home as its swarm timed out) may have reached the new
        # hub before our attach and been refused: the hub has the radio as the attach said, so configure it
        # (another attach would start the node afresh on the hub, dropping frames sent meanwhile)
        changes = _still_wanted(sent, self._attach_message(), attached)
        if changes:
            token = next(self._tokens)
            attached = await self._request(token, wire.Configure(token=token, **changes), resend_s=RESEND_S)
        self._adopt(attached)
        self.reattaches += 1
        self._settle_orphans(orphans, attached)
        for on_done in orphaned_frames.values():
            on_done(TxResult(TxStatus.REFUSED, 0, 0, 0, 0, "the hub restarted before it answered"))
        for callback in self.on_reattach:
            callback()

    def _settle_orphans(self, orphans: list[int], attached: wire.Attached) -> None:
        """Requests the dead hub took with it: the attach carried our configuration (and the IR mode is
        sent again), so those are done; a frame is lost, as in any crash. Requests sent after the attach
        went to the new hub, which answers them itself."""
        for token in orphans:
            fut = self._pending.get(token)
            if fut is None or fut.done():
                continue
            if self._pending_types.get(token) in (wire.Configure.TYPE, wire.SetIrMode.TYPE):
                fut.set_result(attached)
            else:
                fut.set_exception(HubUnavailable("the hub restarted before it answered"))

    def _resolve(self, token: int, msg: wire.Message) -> None:

        fut = self._pending.get(token)
        if fut is not None and not fut.done():
            fut.set_result(msg)


def _still_wanted(sent: wire.Attach, wanted: wire.Attach, attached: wire.Attached) -> dict[str, Any]:
    """What a configure must still change after an attach answered ``attached``: the radio's fields where
    ``wanted`` differs from the answer (an answer to an earlier copy of the attach may arrive late, so the
    answer is what counts), and the position if it was moved since the attach was ``sent`` (the hub answers
    with its own world's position, which a radio that took another answer meanwhile has as its own)."""
    changes: dict[str, Any] = {
        name: getattr(wanted, name)
        for name in ("short_addr", "pan_id", "channel")
        if getattr(wanted, name) != getattr(attached, name)
    }
    if wanted.position not in (sent.position, list(attached.position)):
        changes["position"] = wanted.position
    return changes


def _tx_result(done: wire.TxDone) -> TxResult:
    return TxResult(TxStatus(done.status), done.retries, done.backoffs, done.submitted_us, done.done_us, done.reason)
