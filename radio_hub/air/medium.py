"""The 802.15.4 air as a discrete-event model (sans I/O).

A ``Medium`` takes MAC data requests and the current model time in microseconds, and returns what
happened: frames received by nodes (with RSSI/LQI) and MAC results for senders. It runs unslotted
CSMA-CA, puts frames on the air for their exact airtime, decides at every receiver whether a frame
collided, was lost or was filtered, and runs acknowledged unicast with retries. All randomness comes
from the ``numpy.random.Generator`` it is given, so a seed and an arrival order fix every outcome.

The caller owns the clock: it calls ``submit`` when a request arrives and ``advance`` when the time of
``next_event_us`` has come. Events are processed strictly in model-time order, so an outcome does not
depend on how late the caller's timer fires. A caller that records the traffic (a pcap file) sets
``on_air_end``: it is handed every transmission, data and ACK, once it has left the air.
"""

from __future__ import annotations

import enum
import heapq
import itertools
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from radio_hub.air.chaos import Chaos
from radio_hub.air.error_model import BITS_PER_US, clean_sinr, dbm_to_mw, noise_floor_dbm, piece_success
from radio_hub.air.mac import ACK_PSDU_LEN, BROADCAST, MAX_PSDU, Frame, FrameError, FrameType, TxStatus
from radio_hub.air.propagation import (
    GilbertElliott,
    Position,
    distance,
    lqi_from_rssi,
    mean_rssi_dbm,
    reception_probability,
)
from radio_hub.config import CHANNELS, MediumConfig, airtime_us

# Receptions are judged against every transmission that could still overlap them.
_AIR_HORIZON_US = airtime_us(MAX_PSDU) * 2
_ACK_AIRTIME_US = airtime_us(len(Frame(FrameType.ACK, 0).encode()))


class RxOutcome(enum.StrEnum):
    """What became of one frame at one receiver in its range."""

    DELIVERED = "delivered"
    COLLIDED = "collided"
    LOST = "lost"
    FILTERED = "filtered"


@dataclass
class RadioNode:
    """A radio attached to the air: its addresses, PAN, channel and position."""

    node_id: str
    ext_addr: int
    short_addr: int
    pan_id: int
    channel: int
    position: Position = (0.0, 0.0)

    def validate(self) -> None:
        """Raise ValueError on a channel or address outside 802.15.4's ranges."""
        if self.channel not in CHANNELS:
            raise ValueError(f"channel {self.channel} is not a 2.4 GHz channel (11-26)")
        for name, value, bits in (
            ("short_addr", self.short_addr, 16),
            ("pan_id", self.pan_id, 16),
            ("ext_addr", self.ext_addr, 64),
        ):
            if not 0 <= value < 1 << bits:
                raise ValueError(f"{name} {value} does not fit in {bits} bits")


@dataclass
class Counters:
    """Per-node or per-channel counts. At every receiver heard = delivered + collided + lost + filtered."""

    sent: int = 0
    """Data frames put on the air, every attempt counted."""
    acks_sent: int = 0
    mac_retries: int = 0
    channel_access_failures: int = 0
    no_ack: int = 0
    refused: int = 0
    heard: int = 0
    """Frames that arrived in range on this node's channel (the receiver side)."""
    delivered: int = 0
    collided: int = 0
    lost: int = 0
    filtered: int = 0
    acks_lost: int = 0
    chaos_lost: int = 0
    """Of ``lost``: receptions an injected loss fault took."""
    corrupted: int = 0
    """Of ``lost``: receptions an injected corruption spoiled (bad FCS, dropped by the MAC)."""
    duplicated: int = 0
    """Deliveries handed up twice by an injected duplication (not counted again in ``delivered``)."""

    def count(self, outcome: RxOutcome) -> None:
        """Count one arrival and its outcome."""
        self.heard += 1
        name = _OUTCOME_FIELDS[outcome]
        setattr(self, name, getattr(self, name) + 1)

    def to_dict(self) -> dict[str, int]:
        """Plain dict for the wire and summaries."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


_OUTCOME_FIELDS = {outcome: str(outcome.value) for outcome in RxOutcome}
"""Each outcome's counter (a plain str: reading an enum's ``value`` costs a descriptor call per frame)."""


@dataclass(frozen=True, slots=True)
class Reception:
    """A frame handed up by a receiver's MAC at ``handed_up_us``: when it left the air (``end_us``), or later
    under a chaos delay fault."""

    node_id: str
    sender: str
    psdu: bytes
    frame: Frame
    rssi_dbm: float
    lqi: int
    start_us: int
    end_us: int
    submitted_us: int
    """When the sender's MAC got the request: end_us - submitted_us is the modelled latency on the air."""
    handed_up_us: int
    """When the receiver's stack hands the frame up: ``end_us`` plus any injected delay."""


@dataclass(frozen=True, slots=True)
class TxReport:
    """The MAC result for one data request, delivered to the sender at ``done_us``."""

    node_id: str
    token: int
    status: TxStatus
    retries: int
    backoffs: int
    submitted_us: int
    done_us: int
    reason: str = ""


Output = Reception | TxReport


@dataclass
class _Job:
    node_id: str
    token: int
    frame: Frame
    psdu: bytes
    submitted_us: int
    nb: int = 0
    be: int = 0
    retries: int = 0
    backoffs: int = 0
    done: bool = False
    wants_ack: bool = field(init=False)

    def __post_init__(self) -> None:
        self.wants_ack = self.frame.ack_request and not self.frame.is_broadcast


@dataclass
class Transmission:
    """One PPDU on the air, with what each receiver made of it once it ended."""

    tx_id: int
    sender: str
    channel: int
    start_us: int
    end_us: int
    frame: Frame
    psdu_len: int
    position: Position
    submitted_us: int
    psdu: bytes = b""
    """The bytes on the air (MAC header, payload, FCS): a data request's PSDU as sent, or the MAC's ACK."""
    left_sender: bool = True
    job: _Job | None = None
    attempt: int = 0
    outcomes: dict[str, RxOutcome] = field(default_factory=dict)
    powers: dict[str, tuple[Position, float]] = field(default_factory=dict)
    """Its mean received power at each node judged so far, with where that node was."""

    def overlaps(self, start_us: int, end_us: int) -> bool:
        """True when this transmission is on the air at some instant of [start_us, end_us)."""
        return self.start_us < end_us and self.end_us > start_us

    def to_dict(self) -> dict[str, Any]:
        """A frame-log record."""
        return {
            "tx_id": self.tx_id,
            "sender": self.sender,
            "channel": self.channel,
            "start_us": self.start_us,
            "end_us": self.end_us,
            "type": self.frame.frame_type.name.lower(),
            "seq": self.frame.seq,
            "dst_pan": self.frame.dst_pan,
            "dst": self.frame.dst,
            "src": self.frame.src,
            "psdu_len": self.psdu_len,
            "outcomes": {k: v.value for k, v in self.outcomes.items()},
        }


class Medium:
    """The air of every 2.4 GHz channel, shared by the attached nodes."""

    def __init__(
        self,
        config: MediumConfig,
        rng: np.random.Generator,
        log_size: int = 4096,
        on_air_end: Callable[[Transmission], None] | None = None,
    ) -> None:
        self.config = config.validate()
        self.rng = rng
        self.nodes: dict[str, RadioNode] = {}
        self.node_counters: dict[str, Counters] = {}
        self.channel_counters: dict[int, Counters] = {ch: Counters() for ch in CHANNELS}
        self.air_log: deque[Transmission] = deque(maxlen=log_size)
        self.on_air_end = on_air_end
        """Called with every transmission that has left the air, its outcomes decided, in the order they end.
        It must not call back into the medium."""
        self.now_us = 0
        self._burst = GilbertElliott(config.loss.gilbert_elliott)
        self.chaos = Chaos()
        self._queues: dict[str, deque[_Job]] = {}
        self._air: dict[int, list[Transmission]] = {ch: [] for ch in CHANNELS}
        """Per channel, the transmissions that may still overlap one being judged (a channel's frames meet only
        frames of their own channel, so each is judged against a handful, not the whole air)."""
        self._on_channel: dict[int, list[RadioNode]] | None = None
        """Per channel, the attached nodes tuned to it in attach order (worked out again after an attach,
        update or detach; the order of receivers is the order of their random draws)."""
        self._acking_until: dict[str, int] = {}
        """Per node, when the last ACK its MAC committed to send has left the air and its SIFS is over: the radio
        neither senses nor sends its own frames until then."""
        self._ifs_until: dict[str, int] = {}
        """Per node, when the interframe spacing after its last data frame (or that frame's ACK) ends: its next
        frame's CSMA-CA starts no earlier (IEEE 802.15.4-2011 5.1.1.3)."""
        self._sinr = config.reception.model == "sinr"
        self._noise_mw = dbm_to_mw(noise_floor_dbm(config.path_loss.sensitivity_dbm))
        self._ed_threshold_mw = dbm_to_mw(
            config.path_loss.sensitivity_dbm + config.reception.ed_threshold_above_sensitivity_db
        )
        self._clean_sinr = clean_sinr()
        self._events: list[tuple[int, int, Callable[..., None], tuple[Any, ...]]] = []
        self._seq = itertools.count()
        self._tx_ids = itertools.count(1)
        self._out: list[Output] = []

    # -- nodes -------------------------------------------------------------------------------

    def attach(self, node: RadioNode) -> None:
        """Put a node on the air; raises ValueError on a bad node or a duplicate id."""
        node.validate()
        if node.node_id in self.nodes:
            raise ValueError(f"node {node.node_id!r} is already attached")
        self.nodes[node.node_id] = node
        self.node_counters.setdefault(node.node_id, Counters())
        self._queues[node.node_id] = deque()
        self._on_channel = None

    def update(self, node_id: str, **changes: Any) -> RadioNode:
        """Change a node's PAN, short address, channel or position at run time."""
        node = self.nodes[node_id]
        candidate = RadioNode(**{**node.__dict__, **changes})
        candidate.validate()
        node.__dict__.update(candidate.__dict__)
        self._on_channel = None
        return node

    def detach(self, node_id: str) -> None:
        """Take a node off the air; its queued requests are dropped without a report."""
        self.nodes.pop(node_id, None)
        self._on_channel = None
        self._acking_until.pop(node_id, None)
        self._ifs_until.pop(node_id, None)
        for job in self._queues.pop(node_id, ()):
            job.done = True
        self._burst.forget(node_id)

    def _nodes_on(self, channel: int) -> list[RadioNode]:
        """The attached nodes tuned to ``channel``, in attach order."""
        on_channel = self._on_channel
        if on_channel is None:
            on_channel = {ch: [] for ch in CHANNELS}
            for node in self.nodes.values():
                on_channel[node.channel].append(node)
            self._on_channel = on_channel
        return on_channel[channel]

    # -- time ------------------------------------------------------------------------------------

    def next_event_us(self) -> int | None:
        """Model time of the earliest pending event, or None when the air is idle."""
        return self._events[0][0] if self._events else None

    def advance(self, now_us: int) -> list[Output]:
        """Process every event due at or before ``now_us``; return what they produced."""
        while self._events and self._events[0][0] <= now_us:
            t, _, handler, args = heapq.heappop(self._events)
            self.now_us = t
            handler(*args)
        self.now_us = max(self.now_us, now_us)
        out, self._out = self._out, []
        return out

    def submit(self, node_id: str, psdu: bytes, token: int, now_us: int, frame: Frame | None = None) -> list[Output]:
        """A MAC data request from ``node_id`` at ``now_us``; returns every output due by then. ``frame`` is
        ``psdu`` decoded, when the caller has done so already (it is not decoded twice)."""
        out = self.advance(now_us)
        node = self.nodes.get(node_id)
        if node is None:
            return [*out, self._refusal(node_id, token, "node is not attached")]
        if frame is None:
            try:
                frame = Frame.decode(psdu)
            except FrameError as err:
                return [*out, self._refusal(node_id, token, str(err))]
        if frame.frame_type == FrameType.ACK:
            return [*out, self._refusal(node_id, token, "ACK frames are sent by the MAC itself")]
        queue = self._queues[node_id]
        if len(queue) >= self.config.mac.queue_limit:
            return [*out, self._refusal(node_id, token, "MAC queue full")]
        if not self.config.mac.ack_enabled and frame.ack_request:
            frame = Frame(**{**_frame_fields(frame), "ack_request": False})
        queue.append(_Job(node_id, token, frame, bytes(psdu), self.now_us))
        if len(queue) == 1:
            self._start_csma(queue[0])
        return out + self._drain()

    def _refusal(self, node_id: str, token: int, reason: str) -> TxReport:
        self._count(node_id, "refused")

        return TxReport(node_id, token, TxStatus.REFUSED, 0, 0, self.now_us, self.now_us, reason)

    def _drain(self) -> list[Output]:
        out, self._out = self._out, []
        return out

    def _at(self, t_us: int, handler: Callable[..., None], *args: Any) -> None:
        heapq.heappush(self._events, (t_us, next(self._seq), handler, args))

    # -- CSMA-CA ---------------------------------------------------------------------------------

    def _start_csma(self, job: _Job) -> None:
        ifs_end = self._ifs_until.get(job.node_id, 0)
        if ifs_end > self.now_us:
            # the MAC is still in the interframe spacing after its last frame: channel access waits for its end
            self._at(ifs_end, self._start_csma, job)
            return
        if job.done:
            return
        job.nb, job.be = 0, self.config.mac.min_be
        self._backoff(job)

    def _backoff(self, job: _Job) -> None:
        mac = self.config.mac
        if not mac.csma_enabled:
            self._at(self.now_us + mac.turnaround_us, self._on_tx_start, job)
            return
        slots = int(self.rng.integers(0, 1 << job.be))
        cca_start = self.now_us + slots * mac.unit_backoff_us
        self._at(cca_start + mac.cca_us, self._on_cca_end, job, cca_start)

    def _on_cca_end(self, job: _Job, cca_start: int) -> None:
        if job.done or self._defer_while_acking(job, cca_start):
            return
        mac = self.config.mac
        node = self.nodes[job.node_id]
        if not self._energy_detected(node, cca_start, self.now_us):
            self._at(self.now_us + mac.turnaround_us, self._on_tx_start, job)
            return
        job.nb += 1
        job.backoffs += 1
        job.be = min(job.be + 1, mac.max_be)
        if job.nb > mac.max_csma_backoffs:
            self._count(job.node_id, "channel_access_failures")
            self._finish(job, TxStatus.CHANNEL_ACCESS_FAILURE)
        else:
            self._backoff(job)

    def _defer_while_acking(self, job: _Job, from_us: int) -> bool:
        """Put the job's channel access off when its radio is busy with an ACK at some instant from ``from_us``.

        A half-duplex radio that is turning around to send an ACK, or sending it, can neither assess the channel
        nor start a data frame: it does the CCA (or, without CSMA, the transmission) once the ACK has left the
        air. This is the radio's own state, not a busy channel, so no backoff is counted. Returns True when put
        off.
        """
        free_us = self._acking_until.get(job.node_id, 0)
        if free_us <= from_us:
            return False
        mac = self.config.mac
        start = max(free_us, self.now_us)
        if mac.csma_enabled:
            self._at(start + mac.cca_us, self._on_cca_end, job, start)
        else:
            self._at(start + mac.turnaround_us, self._on_tx_start, job)
        return True

    def _energy_detected(self, node: RadioNode, start_us: int, end_us: int) -> bool:
        """CCA over [start_us, end_us). ``sinr``: mode 1, energy above the ED threshold at its peak (2006 6.9.9,
        2011 8.2.7). ``overlap``: any transmission inside the interference disk."""
        if self._sinr:
            heard = [
                (max(tx.start_us, start_us), min(tx.end_us, end_us), self._power_at(tx, node))
                for tx in self._on_air_for(node, start_us, end_us)
            ]
            return any(power > self._ed_threshold_mw for _, _, power in _pieces(heard, start_us, end_us))
        reach = self.config.range.interference_range_m
        chaos = self.chaos if self.chaos.faults else None
        node_id, (x, y) = node.node_id, node.position
        for tx in self._air[node.channel]:
            if (
                tx.start_us < end_us
                and tx.end_us > start_us
                and tx.sender != node_id
                and math.hypot(tx.position[0] - x, tx.position[1] - y) <= reach
                and (chaos is None or not chaos.separated(tx.sender, node_id))
            ):
                return True
        return False

    # -- transmissions ---------------------------------------------------------------------------

    def _put_on_air(self, sender: RadioNode, frame: Frame, psdu: bytes, submitted_us: int) -> Transmission:
        tx = Transmission(
            tx_id=next(self._tx_ids),
            sender=sender.node_id,
            channel=sender.channel,
            start_us=self.now_us,
            end_us=self.now_us + airtime_us(len(psdu)),
            frame=frame,
            psdu_len=len(psdu),
            position=sender.position,
            submitted_us=submitted_us,
            psdu=psdu,
        )
        ratio = self.config.range.success_ratio_tx
        tx.left_sender = ratio >= 1.0 or self.rng.random() < ratio
        self._air[tx.channel].append(tx)
        return tx

    def _on_tx_start(self, job: _Job) -> None:
        # an ACK can fall due after a clear CCA (a node moved into range, a partition was lifted, no CSMA at all)
        if job.done or self._defer_while_acking(job, self.now_us):
            return
        tx = self._put_on_air(self.nodes[job.node_id], job.frame, job.psdu, job.submitted_us)
        tx.job, tx.attempt = job, job.retries
        self._count(job.node_id, "sent")
        self._at(tx.end_us, self._on_tx_end, tx)

    def _on_tx_end(self, tx: Transmission) -> None:
        self._prune_air(tx.channel)
        job = tx.job
        assert job is not None
        channel_counters = self.channel_counters[tx.channel]
        overlapping = self._overlapping(tx) if self._sinr else []
        for node in self._receivers(tx):
            outcome = self._judge(tx, node, not addressed_to(tx.frame, node), overlapping)
            tx.outcomes[node.node_id] = outcome
            self.node_counters[node.node_id].count(outcome)
            channel_counters.count(outcome)
            if outcome is RxOutcome.DELIVERED:
                self._deliver(tx, node, job.psdu)
                if job.wants_ack and node.short_addr == tx.frame.dst:
                    mac = self.config.mac
                    ack_start = self.now_us + mac.turnaround_us
                    self._at(ack_start, self._on_ack_start, tx, node)
                    # from now the responder's radio is turning around to send the ACK, then sending it, then
                    # keeping the interframe spacing after it (an ACK is a frame of at most aMaxSIFSFrameSize)
                    ack_done = ack_start + _ACK_AIRTIME_US + mac.ifs_us(ACK_PSDU_LEN)
                    until = max(self._acking_until.get(node.node_id, 0), ack_done)
                    self._acking_until[node.node_id] = until
        self._left_air(tx)
        if job.done:
            return
        if job.wants_ack:
            self._at(self.now_us + self.config.mac.ack_wait_us, self._on_ack_timeout, job, tx.attempt)
        else:
            self._ifs_until[job.node_id] = self.now_us + self.config.mac.ifs_us(len(job.psdu))
            self._finish(job, TxStatus.SUCCESS)

    def _receivers(self, tx: Transmission) -> list[RadioNode]:
        reach = self.config.range.tx_range_m
        chaos = self.chaos if self.chaos.faults else None
        sender, (x, y) = tx.sender, tx.position
        return [
            n
            for n in self._nodes_on(tx.channel)
            if n.node_id != sender
            and math.hypot(x - n.position[0], y - n.position[1]) <= reach
            and (chaos is None or not chaos.separated(sender, n.node_id))
        ]

    def _overlapping(self, tx: Transmission) -> list[Transmission]:
        """The other transmissions on ``tx``'s channel at some instant of its airtime, in the air's order
        (worked out once per frame, not once per receiver)."""
        start, end = tx.start_us, tx.end_us
        return [o for o in self._air[tx.channel] if o is not tx and o.start_us < end and o.end_us > start]

    def _judge(
        self, tx: Transmission, node: RadioNode, filtered: bool, overlapping: list[Transmission] | None = None
    ) -> RxOutcome:
        """Interference first (the bits are garbled), then random loss, then the address filter.
        ``overlapping``: ``self._overlapping(tx)``, when the caller judges the frame at several receivers."""
        if not tx.left_sender:
            return RxOutcome.LOST
        if self._sinr:
            spoiled = self._spoiled(tx, node, self._overlapping(tx) if overlapping is None else overlapping)
            if spoiled is not None:
                return spoiled
        elif self._collided(tx, node):
            return RxOutcome.COLLIDED
        if self._lost(tx, node):
            return RxOutcome.LOST
        return RxOutcome.FILTERED if filtered else RxOutcome.DELIVERED

    def _power_mw(self, sender: Position, receiver: Position) -> float:
        return dbm_to_mw(mean_rssi_dbm(self.config.path_loss, distance(sender, receiver)))

    def _power_at(self, tx: Transmission, node: RadioNode) -> float:
        """Mean received power (mW) of ``tx`` at ``node``, remembered on the transmission while the node stays
        where it was: a frame's power at a receiver is asked for when the frame is judged there and again for
        every frame it overlaps there."""
        position = node.position
        known = tx.powers.get(node.node_id)
        if known is not None and known[0] == position:
            return known[1]
        power = self._power_mw(tx.position, position)
        tx.powers[node.node_id] = (position, power)
        return power

    def _on_air_for(self, node: RadioNode, start_us: int, end_us: int) -> list[Transmission]:
        """Other nodes' transmissions on the node's channel at some instant of [start_us, end_us) that a
        partition does not keep from it."""
        chaos = self.chaos if self.chaos.faults else None
        node_id = node.node_id
        return [
            tx
            for tx in self._air[node.channel]
            if tx.start_us < end_us
            and tx.end_us > start_us
            and tx.sender != node_id
            and (chaos is None or not chaos.separated(tx.sender, node_id))
        ]

    def _spoiled(self, tx: Transmission, node: RadioNode, overlapping: list[Transmission]) -> RxOutcome | None:
        """The ``sinr`` model's verdict on ``tx`` at ``node``: COLLIDED, LOST (noise alone) or None (intact).

        - Half duplex: a node that transmits at any instant of the frame receives none of it.
        - Synchronisation: the receiver locks on the first preamble it hears and keeps it unless a stronger
          frame starts, so a frame that starts after (or with, and after in air order) an at least as strong
          frame it can decode is not received (it only interferes).
        - Otherwise each stretch of the airtime with one set of overlapping transmissions has its SINR (their
          summed power and the noise floor), and the frame survives with the product of the stretches'
          (1 - BER)^bits (Annex E). One draw decides, and none where the product is exactly 0 or 1.
        """
        start, end = tx.start_us, tx.end_us
        signal = self._power_at(tx, node)
        reach = self.config.range.tx_range_m
        heard = []
        for other in overlapping:
            if other.sender == node.node_id:
                return RxOutcome.COLLIDED
            if other.sender == tx.sender or (self.chaos.faults and self.chaos.separated(other.sender, node.node_id)):
                continue
            power = self._power_at(other, node)
            first = other.start_us < start or (other.start_us == start and other.tx_id < tx.tx_id)
            if first and power >= signal and distance(other.position, node.position) <= reach:
                return RxOutcome.COLLIDED
            heard.append((max(other.start_us, start), min(other.end_us, end), power))
        success = 1.0
        # every stretch's interference is at most the sum of all (exactly rounded sums of positive powers are
        # monotone), so when even that leaves the frame clean no stretch needs working out
        if heard and signal / (self._noise_mw + math.fsum([p for _, _, p in heard])) < self._clean_sinr:
            for a, b, interference in _pieces(heard, start, end):
                sinr = signal / (self._noise_mw + interference)
                if sinr < self._clean_sinr:
                    success *= piece_success(sinr, (b - a) * BITS_PER_US)
                    if success == 0.0:
                        break
        elif not heard and signal / self._noise_mw < self._clean_sinr:
            success = piece_success(signal / self._noise_mw, (end - start) * BITS_PER_US)
        if success >= 1.0 or (success > 0.0 and self.rng.random() >= 1.0 - success):
            return None
        return RxOutcome.COLLIDED if heard else RxOutcome.LOST

    def _collided(self, tx: Transmission, node: RadioNode) -> bool:
        """The ``overlap`` model: any overlap inside the interference disk collides, unless capture saves it."""
        reach = self.config.range.interference_range_m
        chaos = self.chaos if self.chaos.faults else None
        start, end, node_id, (x, y) = tx.start_us, tx.end_us, node.node_id, node.position
        interferers = []
        for other in self._air[tx.channel]:
            if other is tx or not (other.start_us < end and other.end_us > start):
                continue
            if other.sender == node_id:
                return True  # half duplex: a node that is transmitting receives nothing
            if (
                other.sender != tx.sender
                and math.hypot(other.position[0] - x, other.position[1] - y) <= reach
                and (chaos is None or not chaos.separated(other.sender, node_id))
            ):
                interferers.append(other)
        if not interferers:
            return False
        capture = self.config.capture
        if not capture.enabled:
            return True
        wanted = mean_rssi_dbm(self.config.path_loss, distance(tx.position, node.position))
        strongest = max(mean_rssi_dbm(self.config.path_loss, distance(o.position, node.position)) for o in interferers)
        return wanted - strongest < capture.margin_db

    def _lost(self, tx: Transmission, node: RadioNode) -> bool:
        rng = self.rng
        p = reception_probability(self.config.range, distance(tx.position, node.position))
        if p < 1.0 and rng.random() >= p:
            return True
        base = self.config.loss.base
        if base > 0.0 and rng.random() < base:
            return True
        if self._burst.cfg.enabled and self._burst.lost((tx.sender, node.node_id), rng):
            return True
        if not self.chaos.faults:
            return False
        # injected faults: a burst, a fade (loss) or a bad FCS the receiving MAC drops (corrupt)
        if self.chaos.burst_lost(tx.sender, node.node_id, node.pan_id, tx.channel, rng):
            self._count(node.node_id, "chaos_lost")
            return True
        for kind in ("loss", "corrupt"):
            for p in self.chaos.probabilities(kind, tx.sender, node.node_id, node.pan_id, tx.channel):
                if rng.random() < p:
                    self._count(node.node_id, "corrupted" if kind == "corrupt" else "chaos_lost")
                    return True
        return False

    def _deliver(self, tx: Transmission, node: RadioNode, psdu: bytes) -> None:
        pl = self.config.path_loss
        rssi = mean_rssi_dbm(pl, distance(tx.position, node.position))
        if pl.shadowing_sigma_db > 0:
            rssi += float(self.rng.normal(0.0, pl.shadowing_sigma_db))
        copies, delay_us = 1, 0
        if self.chaos.faults:
            # every selecting fault draws (so the seeded sequence does not depend on which one hit first), but
            # the frame is duplicated, and counted, once however many of them hit
            probabilities = self.chaos.probabilities("duplicate", tx.sender, node.node_id, node.pan_id, tx.channel)
            if any([self.rng.random() < p for p in probabilities]):
                copies = 2
                self._count(node.node_id, "duplicated")
            delay_us = self.chaos.delay_us(tx.sender, node.node_id, node.pan_id, tx.channel, self.rng)
        reception = Reception(
            node.node_id,
            tx.sender,
            psdu,
            tx.frame,
            round(rssi, 1),
            lqi_from_rssi(pl, rssi),
            tx.start_us,
            tx.end_us,
            tx.submitted_us,
            tx.end_us + delay_us,
        )
        if delay_us:
            # the outcome and the ACK stay the air's; only the receiver's stack hands the frame up later
            self._at(reception.handed_up_us, self._hand_up, node, reception, copies)
        else:
            self._out.extend([reception] * copies)

    def _hand_up(self, node: RadioNode, reception: Reception, copies: int) -> None:
        # a node that left (or re-attached as a new radio) meanwhile does not get its old frames
        if self.nodes.get(node.node_id) is node:
            self._out.extend([reception] * copies)

    # -- acknowledgements ------------------------------------------------------------------------

    def _on_ack_start(self, data: Transmission, responder: RadioNode) -> None:
        if responder.node_id not in self.nodes:
            return
        frame = Frame(FrameType.ACK, data.frame.seq)
        ack = self._put_on_air(responder, frame, frame.encode(), self.now_us)
        ack.job, ack.attempt = data.job, data.attempt
        self._count(responder.node_id, "acks_sent")
        self._at(ack.end_us, self._on_ack_end, ack)

    def _on_ack_end(self, ack: Transmission) -> None:
        job = ack.job
        assert job is not None
        self._judge_ack(ack, job)
        self._left_air(ack)

    def _judge_ack(self, ack: Transmission, job: _Job) -> None:
        sender = self.nodes.get(job.node_id)
        if job.done or sender is None or job.retries != ack.attempt:
            return
        # a sender that changed channel since it sent (its radio is tuned elsewhere) hears nothing of the ACK
        in_range = sender.channel == ack.channel
        in_range = in_range and distance(ack.position, sender.position) <= self.config.range.tx_range_m
        in_range = in_range and not self.chaos.separated(ack.sender, sender.node_id)

        outcome = self._judge(ack, sender, filtered=False) if in_range else RxOutcome.LOST
        ack.outcomes[sender.node_id] = outcome
        if outcome == RxOutcome.DELIVERED:
            self._ifs_until[job.node_id] = self.now_us + self.config.mac.ifs_us(len(job.psdu))
            self._finish(job, TxStatus.SUCCESS)
        else:
            self._count(job.node_id, "acks_lost")

    def _on_ack_timeout(self, job: _Job, attempt: int) -> None:
        if job.done or job.retries != attempt:
            return
        if job.retries < self.config.mac.max_frame_retries:
            job.retries += 1
            self._count(job.node_id, "mac_retries")
            self._start_csma(job)
        else:
            self._count(job.node_id, "no_ack")
            self._finish(job, TxStatus.NO_ACK)

    def _finish(self, job: _Job, status: TxStatus) -> None:
        job.done = True
        self._out.append(
            TxReport(job.node_id, job.token, status, job.retries, job.backoffs, job.submitted_us, self.now_us)
        )
        queue = self._queues.get(job.node_id)
        if queue and queue[0] is job:
            queue.popleft()
            if queue:
                self._start_csma(queue[0])

    # -- bookkeeping -----------------------------------------------------------------------------

    def _left_air(self, tx: Transmission) -> None:
        self.air_log.append(tx)
        if self.on_air_end is not None:
            self.on_air_end(tx)

    def _count(self, node_id: str, name: str) -> None:
        """Count for the node and for the channel it is on (so per-channel sums match per-node ones)."""
        node = self.nodes.get(node_id)
        if node is None:
            return
        for counters in (self.node_counters[node_id], self.channel_counters[node.channel]):
            setattr(counters, name, getattr(counters, name) + 1)

    def _prune_air(self, channel: int) -> None:
        # what ended before the horizon can overlap nothing still to be judged
        horizon = self.now_us - _AIR_HORIZON_US
        air = self._air[channel]
        if air and air[0].end_us < horizon:
            self._air[channel] = [tx for tx in air if tx.end_us >= horizon]


def _pieces(spans: list[tuple[int, int, float]], start_us: int, end_us: int) -> list[tuple[int, int, float]]:
    """[start_us, end_us) cut where any of ``spans`` (start, end, power) begins or ends: each piece with the
    summed power of the spans that cover it."""
    if not spans:
        return [(start_us, end_us, 0.0)]
    cuts = sorted({start_us, end_us, *(s for s, _, _ in spans), *(e for _, e, _ in spans)})
    return [
        (a, b, math.fsum(p for s, e, p in spans if s <= a and e >= b))
        for a, b in itertools.pairwise(cuts)
        if start_us <= a and b <= end_us
    ]


def addressed_to(frame: Frame, node: RadioNode) -> bool:
    """The MAC's address filter: the frame's destination PAN and short address are the node's, or broadcast."""
    pan_ok = frame.dst_pan in (node.pan_id, BROADCAST)
    return pan_ok and frame.dst in (node.short_addr, BROADCAST)


def _frame_fields(frame: Frame) -> dict[str, Any]:
    return {f: getattr(frame, f) for f in Frame.__slots__}
