"""The environment: the 802.15.4 medium, the world, the IR light, BLE and the LF field on one model timeline.

Pure code: no zenoh, no threads, no clock reads. Whoever drives it passes ``now_us`` (model microseconds)
into every entry point: ``receive`` (a node's message), ``node_gone`` (a node's liveliness ended), the
queries, and ``advance``, which carries out everything due by then (medium outcomes, world ticks, body
sensors, IR sweeps, beacons, BLE deliveries). ``next_event_us`` says when the next one is due. Messages for
a node leave through ``Downlink.send`` already encoded.

Two drivers exist: the hub process (``radio_hub.shell.hub``, zenoh and the wall clock) and the model-time run
(``runner.model``, every node in one process on a ``ModelClockLoop``). There is one schedule, this one.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import json
import math
import operator
import re
import resource
import sys
import threading
import tomllib
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import msgpack
import numpy as np

from radio_hub.air.chaos import describe_change
from radio_hub.air.mac import Frame, FrameError, FrameType
from radio_hub.air.medium import Medium, Output, RadioNode, Reception, Transmission, TxReport, TxStatus
from radio_hub.air.pcap import PcapWriter
from radio_hub.config import MediumConfig, check_keys
from radio_hub.guard import Faults
from radio_hub.link import wire
from radio_hub.link.keys import check_name
from radio_hub.physics.ble import BleAir, BleConfig
from radio_hub.physics.ir_air import IrAir
from radio_hub.physics.lf import LfConfig, antenna_positions, lf_rssi
from radio_hub.physics.light import PERSON_BEACON_POWER, IrConfig
from radio_hub.physics.world import Body, Obstacle, World, WorldConfig, parse_obstacle

SENSORS_EVERY = 2
"""World ticks per robot sensor message (50 Hz ticks: sensors at 25 Hz)."""
PUBLISH_EVERY = 5
"""World ticks per world publication for viewers (10 Hz)."""
BEACONS_EVERY = SENSORS_EVERY
"""World ticks per beacon sweep: beacons are swept with the body sensors (25 Hz), so a robot, which steps on
each sample, steps on the sweep of its own instant. (They were meant to go at 20 Hz, every fifth IR sweep, but
the count divided was of receive sweeps, which stays 0 in the surround formation: they went at every IR
period, 100 Hz, of which a robot used the one at its sample's instant. A true 20 Hz gave the cylinder a
contact on seed 1, its fixes up to 50 ms old and beating against the 25 Hz steps.)"""


HUB = "hub"
"""The name a ``Relay`` gives the environment itself."""
NODE_KINDS = ("robot", "user", "control")
"""``control``: a run's orchestrator in model and lockstep time (no body, no radio; it only relays)."""
GONE_KEPT = 256
"""Departed (or never attached) ids whose bookkeeping is kept: radio counters for the run's record, downlink
numbering; beyond this the oldest are forgotten, so a stream of new ids cannot grow the hub."""
MAX_GAP = 1 << 32
"""The most one message adds to ``transport_gaps`` (a forged sequence number must not overflow the counter)."""


def process_usage() -> dict[str, float]:
    """The calling process's CPU seconds and peak resident memory (MB): what a shell adds to its stats."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return {"cpu_s": round(usage.ru_utime + usage.ru_stime, 3), "peak_rss_mb": round(usage.ru_maxrss / 1024, 1)}


class Downlink(Protocol):
    """Where the environment's messages to nodes go (a zenoh publisher per node, or a node in memory)."""

    def send(self, node_id: str, data: bytes) -> None:
        """Deliver one encoded ``wire`` message to ``node_id`` (best effort for unknown nodes)."""

    def forget(self, node_id: str) -> None:
        """``node_id`` detached: release whatever was kept for it."""

    def publish_world(self, state: dict[str, Any]) -> None:
        """The world's state for viewers (10 Hz). A downlink whose ``publishes_world`` is False (optional,
        default True) drops it, and the environment then does not make it."""


class MessageDownlink(Downlink, Protocol):
    """A downlink in memory, to nodes in this process: it may take the body-sensor and beacon messages (the
    bulk of a run's traffic, 25 Hz per robot) as they are, without their bytes (``RadioClient`` checks a
    message handed over as it would decode it)."""

    def send_message(self, node_id: str, msg: wire.Message) -> None:
        """Deliver one message to ``node_id`` as it is; the environment keeps no reference to it."""


HANDED_OVER = (wire.Sensors, wire.IrBeacons)
"""The messages a ``MessageDownlink`` takes as they are: every field a plain value (numbers, strings, bytes
and lists of them), so the node sees the very values their bytes would decode to."""


@dataclass
class EnvironmentConfig:
    """Everything a hub emulates besides the 802.15.4 medium's own tables: the IR light, the world,
    the obstacles of a scenario, the BLE links and the LF field."""

    medium: MediumConfig = field(default_factory=MediumConfig)
    ir: IrConfig = field(default_factory=IrConfig)
    world: WorldConfig = field(default_factory=WorldConfig)
    ble: BleConfig = field(default_factory=BleConfig)
    lf: LfConfig = field(default_factory=LfConfig)
    obstacles: list[Obstacle] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """Plain values for stats and run records."""
        return {
            "medium": self.medium.to_dict(),
            "ir": self.ir.to_dict(),
            "world": self.world.to_dict(),
            "ble": self.ble.to_dict(),
            "lf": self.lf.to_dict(),
            "obstacles": [o.to_dict() for o in self.obstacles],
        }


@dataclass
class HubCounters:
    """Anything that is not a radio outcome: bad input and transport anomalies."""

    malformed: int = 0
    unattached: int = 0
    transport_gaps: int = 0
    config_errors: int = 0
    attaches: int = 0
    detaches: int = 0
    foreign: int = 0
    """Messages for an attached id with another session key than the one it attached with (refused)."""
    spoofed: int = 0
    """Frames whose source address is not the sender's own (refused)."""
    forgotten: int = 0
    """Departed ids whose bookkeeping was dropped (``GONE_KEPT``)."""
    chaos_refused: int = 0
    """Chaos requests refused (malformed, a selector out of its bounds, too many faults, too long)."""
    relay_refused: int = 0
    """Relays from a node that is not a run's orchestrator, and orchestrator attaches under a robot's or a
    user's id (refused): a relay must not grant what the same request, asked directly, would be denied."""
    lag_us: deque[int] = field(default_factory=lambda: deque(maxlen=20000))

    def to_dict(self) -> dict[str, Any]:
        """Counts plus the delivery lag percentiles (actual minus model delivery time)."""
        lags = np.array(self.lag_us) if self.lag_us else np.zeros(1)
        return {
            "malformed": self.malformed,
            "unattached": self.unattached,
            "transport_gaps": self.transport_gaps,
            "config_errors": self.config_errors,
            "attaches": self.attaches,
            "detaches": self.detaches,
            "foreign": self.foreign,
            "spoofed": self.spoofed,
            "forgotten": self.forgotten,
            "relay_refused": self.relay_refused,
            "chaos_refused": self.chaos_refused,
            "lag_p50_us": float(np.percentile(lags, 50)),
            "lag_p99_us": float(np.percentile(lags, 99)),
            "lag_samples": len(self.lag_us),
        }


class Environment:
    """The emulated environment of one world: every model outcome, decided at the ``now_us`` it is given."""

    def __init__(
        self,
        config: EnvironmentConfig,
        seed: int,
        downlink: Downlink,
        *,
        wall_epoch_us: int = 0,
        pcap_path: str | Path | None = None,
        world_log: str | Path | None = None,
    ) -> None:
        """Raises OSError when ``pcap_path`` or ``world_log`` is given and cannot be opened for writing.

        ``wall_epoch_us`` is the wall-clock time of model time 0 (pcap stamps and the world's ``wall``);
        ``world_log`` receives one JSON line per world tick (the ground truth a run's metrics come from).
        """
        self.config = config
        self.seed = seed
        self.downlink = downlink
        self._hand_over: Callable[[str, wire.Message], None] | None = (
            downlink.send_message if getattr(downlink, "takes_messages", False) else None  # type: ignore[attr-defined]
        )
        self.wall_epoch_us = wall_epoch_us
        self.pcap_path = None if pcap_path is None else Path(pcap_path)
        self._pcap = None if self.pcap_path is None else PcapWriter(self.pcap_path)
        self._pcap_records = 0
        self._pcap_error = ""
        self.medium = Medium(
            config.medium,
            np.random.default_rng(seed),
            on_air_end=None if self._pcap is None else self._write_pcap,
        )
        self.counters = HubCounters()
        self.faults = Faults("hub")
        """Unexpected exceptions in the entry points, per kind (the input is dropped, the hub goes on)."""
        self.holder_alive: Callable[[str, str], bool] | None = None
        """Whether the liveliness token of (node id, instance) is present. A shell that watches tokens sets it:
        an attach with another session key then cannot take an id whose holder is still there. None (model
        time: every node is in this process) lets a new attach replace the old one."""
        self._up_seq: dict[str, int] = {}
        self._instances: dict[str, str] = {}
        self._session_keys: dict[str, int] = {}
        self._gone: dict[str, None] = {}
        """Ids that left (oldest first), whose counters and numbering are still kept."""
        self.ir = IrAir(config.ir, np.random.default_rng([seed, 1]))
        self.world = World(config.world, config.obstacles)
        self.ble = BleAir(config.ble, np.random.default_rng([seed, 2]))
        self._body_rng = np.random.default_rng([seed, 3])
        self._lf_rng = np.random.default_rng([seed, 4])
        self.lf_counters = {"bursts": 0, "heard": 0}
        self._kinds: dict[str, str] = {}
        """Attached nodes and their kind (robot or user)."""
        self._telemetry: dict[str, dict[str, Any]] = {}
        self._ticks = 0
        self._next_tick_us = 0
        self._world_log = None if world_log is None else open(world_log, "w")  # noqa: SIM115 (closed in close())
        self._template_of: tuple[tuple[Any, ...], str, tuple[int, ...]] = ((), "", ())
        """``_bodies_template``'s key, template and referenced bodies."""
        self._obstacles_text_of: tuple[tuple[Obstacle, ...], str] = ((), "[]")
        self._down_seq: dict[str, int] = {}
        self._now = 0
        self.world_lock = threading.RLock()
        """Held by whatever touches the world, the IR light, BLE, LF or the set of nodes (everything but a
        robot's frame and the medium's outcomes). In one thread (model time, lockstep) nobody waits on it; the
        hub runs ``advance_world`` on a thread of its own, and its job thread then only needs it for the rare
        message that is not a frame."""
        self._down_lock = threading.RLock()
        """A message's number and its sending go together, so a node's stream stays in order from two threads."""

    def now_us(self) -> int:
        """The model time of the latest input or advance."""
        return self._now

    def _at(self, now_us: int) -> None:
        # time never runs backwards: a late input is stamped with the latest model time
        self._now = max(self._now, int(now_us))

    def instance_of(self, node_id: str) -> str | None:
        """The liveliness instance of the attached node ``node_id`` (None: not attached)."""
        return self._instances.get(node_id) if node_id in self._kinds else None

    @property
    def kinds(self) -> dict[str, str]:
        """Attached nodes and their kind (``robot`` or ``user``)."""
        return self._kinds

    def close(self) -> None:
        """Close the pcap file and the world log."""
        pcap, self._pcap = self._pcap, None
        if pcap is not None:
            pcap.close()
        log, self._world_log = self._world_log, None
        if log is not None:
            log.close()

    def next_event_us(self) -> int:
        """When the next scheduled thing is due: a medium outcome, an IR sweep, a BLE delivery or a world tick."""
        due = self.next_world_event_us()
        medium = self.medium.next_event_us()
        return due if medium is None or medium >= due else medium

    def next_world_event_us(self) -> int:
        """When the next world tick, IR sweep or BLE delivery is due."""
        due = self._next_tick_us
        for t in (self.ir.next_event_us(), self.ble.next_event_us()):
            if t is not None and t < due:
                due = t
        return due

    def advance(self, now_us: int) -> None:
        """Carry out everything due by ``now_us``, in one fixed order: medium, world tick, IR, BLE."""
        self.advance_medium(now_us)
        self.advance_world(self._now)

    def advance_medium(self, now_us: int) -> None:
        """Carry out the medium's outcomes due by ``now_us`` (and move the model clock to it)."""
        self._at(now_us)
        self._dispatch(self.medium.advance(self._now))

    def advance_world(self, now_us: int) -> None:
        """Carry out the world tick, IR sweeps and BLE deliveries due by ``now_us``, in that order, under
        ``world_lock``. It does not move the model clock, so a shell may call it from another thread than the
        one that feeds the medium (the hub does)."""
        with self.world_lock:
            self._tick_world(now_us)
            self._sweep_ir(now_us)
            self._deliver_ble(now_us)

    def receive(self, node_id: str, data: bytes | wire.Message, now_us: int, *, wait: bool = True) -> bool:
        """A node's message (``wire``-encoded, or in memory handed over as it is, checked as its bytes would
        be) arrived at ``now_us``. Never raises: anything unexpected is counted in ``faults`` and the message
        dropped. With ``wait=False`` a message that needs ``world_lock`` (all but an attached robot's frame)
        while another thread holds it is left untouched and False returned: the caller offers it again."""
        self._at(now_us)
        try:
            return self._on_up(node_id, data, wait)
        except Exception as err:
            what = f"{len(data)} bytes" if isinstance(data, bytes) else f"a {type(data).__name__}"
            self.faults.record("receive", err, f"{what} from {node_id[:64]!r}")
        return True

    def node_gone(self, node_id: str, instance: str, now_us: int) -> None:
        """The node's liveliness ended; ignored when another instance has attached under that id since."""
        self._at(now_us)
        try:
            if node_id in self._kinds and self._instances.get(node_id) == instance:
                self._detach(node_id)
        except Exception as err:
            self.faults.record("node_gone", err, node_id[:64])

    def session_key_of(self, node_id: str) -> int | None:
        """The session key the attached node ``node_id`` attached with (None: not attached)."""
        return self._session_keys.get(node_id) if node_id in self._kinds else None

    def air(self) -> dict[str, Any]:
        """Every transmission the medium keeps in its air log."""
        return {"transmissions": [tx.to_dict() for tx in self.medium.air_log]}

    def _sweep_ir(self, now: int) -> None:
        if not self.ir.take_due(now):
            return
        poses = self.world.poses()
        chaos = self.medium.chaos
        for node_id, readings in self.ir.receive_sweep(poses, chaos).items():
            self._send_down(node_id, wire.IrSample(readings=readings.astype("<f4").tobytes(), t_us=now))

    def _sweep_beacons(self, now: int, poses: dict[str, tuple[float, float, float]]) -> None:
        sweeps = self.ir.beacon_sweep(poses, self.medium.chaos)
        self._send_all(
            (
                node_id,
                wire.IrBeacons(
                    sources=sources, readings=block.astype("<f4", copy=False).tobytes(), t_us=now, gains=gains
                ),
            )
            for node_id, (sources, block, gains) in sweeps.items()
        )

    def _tick_world(self, now: int) -> None:
        if now < self._next_tick_us:
            return
        tick_us = round(self.world.config.tick_s * 1e6)
        self._next_tick_us = max(self._next_tick_us + tick_us, now - tick_us)  # a late hub does not race to catch up
        self._ticks += 1
        world = self.world
        world.step(now / 1e6)
        poses = world.poses()  # as the tick left them: nothing below moves a body
        for node_id, node in self.medium.nodes.items():
            pose = poses.get(node_id)
            if pose is not None:
                node.position = pose[:2]
        if self._ticks % SENSORS_EVERY == 0:
            self._send_sensors(now)
        if self._ticks % BEACONS_EVERY == 0:
            self._sweep_beacons(now, poses)
        if self._world_log is not None or self._ticks % PUBLISH_EVERY == 0:
            self._record_world(now)

    def _send_sensors(self, now: int) -> None:
        robots = [n for n, kind in self._kinds.items() if kind == "robot" and n in self.world.bodies]
        if not robots:
            return
        # every robot's sample converted at once: the same float32 bytes and floats as robot by robot
        ranges, yaws, odometry = self.world.sense_arrays(robots, self._body_rng)
        wire_ranges = ranges.astype("<f4")
        self._send_all(
            (node_id, wire.Sensors(t_us=now, ranges=wire_ranges[k].tobytes(), yaw=yaw, odometry=own_odometry))
            for k, (node_id, yaw, own_odometry) in enumerate(zip(robots, yaws, odometry.tolist(), strict=True))
        )

    def _record_world(self, now: int) -> None:
        if self._world_log is not None:
            try:
                self._world_log.write(self.world_line(now) + "\n")
                self._world_log.flush()
            except (OSError, ValueError) as err:  # a full disk must not take the world down
                print(f"hub: world log: {err}; no longer recording", file=sys.stderr)
                self._world_log = None
        # a downlink may say nobody watches (a model run without a viewer): no state is made for nobody
        if self._ticks % PUBLISH_EVERY == 0 and getattr(self.downlink, "publishes_world", True):
            self.downlink.publish_world(self.world_state(now))

    def world_line(self, now: int | None = None) -> str:
        """``world_state`` as compact JSON (``json.dumps`` with separators "," and ":"), the very same text,
        without building its dicts: the world log takes a line every tick (50 Hz), where the dicts and their
        encoding were a fifth of the world tick. The bodies' text is one %-template, made again only when a
        body's unchanging fields do, filled with every pose and velocity in one formatting; a value that is not
        finite (which JSON writes as NaN or Infinity) takes the encoder's own path."""
        now = self._now if now is None else now
        world = self.world
        bodies = list(world.bodies.values())
        rows = world.truth_rows()
        values = list(itertools.chain.from_iterable(rows))
        if not math.isfinite(sum(values)):  # a sum of finite values may overflow too: that path is only slower
            return json.dumps(self.world_state(now), separators=(",", ":"))
        template, referenced = self._bodies_template(bodies)
        if referenced:
            values = self._with_references(bodies, rows, referenced)
        # a snapshot, as world_state takes: the medium's thread may add or drop a node's counters meanwhile
        counters = list(self.medium.node_counters.values())
        radio = [sum(map(count, counters)) for count in _RADIO_TOTALS]
        wall = round((self.wall_epoch_us + now) / 1e6, 4)
        return (
            f'{{"v":1,"t_us":{_json_number(now)},"wall":{_json_number(wall)},"bodies":[{template % tuple(values)}],'
            f'"obstacles":{self._obstacles_text()},"collisions":{_json_number(world.collisions)},{_contacts_text(world)}'
            f'"radio":{{"delivered":{radio[0]},"collided":{radio[1]},"lost":{radio[2]}}}}}'
        )

    def _bodies_template(self, bodies: list[Body]) -> tuple[str, tuple[int, ...]]:
        """The bodies' JSON as a %-template of their six truth values each (``%r``: the ``repr`` that
        ``json.dumps`` writes a finite float with), and the indices of the bodies whose reference is not
        null (a slave with a slot): theirs is a ``%s`` after the six. Made again only when an id, kind,
        radius, PAN, IR mode or telemetry changes (one comparison of a tuple per line)."""
        ids = tuple(self.world.bodies)
        nodes = self.medium.nodes
        key = (
            ids,
            tuple(map(_KIND, bodies)),
            tuple(map(_RADIUS, bodies)),
            tuple(nodes),  # the bodies with a radio, and their PANs (changed in place: kept as values)
            tuple(map(_PAN_ID, nodes.values())),
            tuple(map(self.ir.counter.modes.get, ids)),
            tuple(map(self._telemetry.get, ids)),  # a new dict per telemetry message: compared by content
        )
        if key != self._template_of[0]:
            self._template_of = (key, *self._make_template(bodies))
        return self._template_of[1], self._template_of[2]

    def _make_template(self, bodies: list[Body]) -> tuple[str, tuple[int, ...]]:
        """``_bodies_template``'s template and referenced bodies, made from scratch."""
        modes, nodes, telemetry = self.ir.counter.modes, self.medium.nodes, self._telemetry
        names = {b.body_id for b in bodies}
        parts, referenced = [], []
        for k, body in enumerate(bodies):
            tele = telemetry.get(body.body_id, {})
            node = nodes.get(body.body_id)
            state, role = tele.get("state") or None, tele.get("role") or None
            ir = str(modes.get(body.body_id, "idle"))
            head, tail = _body_text(
                body.body_id, body.kind, body.radius, None if node is None else node.pan_id, ir, state, role
            )
            head, tail = head.replace("%", "%%"), tail.replace("%", "%%")  # ids and telemetry come from nodes
            if tele.get("slot") is not None and tele.get("master", "") in names:
                tail = tail[: -len("null}")] + "%s}"
                referenced.append(k)
            parts.append(f'{head}%r,"y":%r,"yaw":%r,"vx":%r,"vy":%r,"omega":%r{tail}')
        return ",".join(parts), tuple(referenced)

    def _with_references(self, bodies: list[Body], rows: list[list[float]], referenced: tuple[int, ...]) -> list[Any]:
        """The template's values: each body's six, and after those of a referenced body its reference's JSON
        (its slot placed by its master's true pose, rounded as ``world_state`` does)."""
        index = {b.body_id: k for k, b in enumerate(bodies)}
        values: list[Any] = []
        at = set(referenced)
        for k, row in enumerate(rows):
            values += row
            if k in at:
                tele = self._telemetry[bodies[k].body_id]
                x, y, yaw = rows[index[tele["master"]]][:3]
                reference = _reference({"x": x, "y": y, "yaw": yaw}, tele["slot"])
                values.append(json.dumps(reference, separators=(",", ":")))
        return values

    def _obstacles_text(self) -> str:
        """The obstacles' JSON, made again only when they change."""
        obstacles = tuple(self.world.obstacles)
        if obstacles != self._obstacles_text_of[0]:
            text = json.dumps([o.to_dict() for o in obstacles], separators=(",", ":"))
            self._obstacles_text_of = (obstacles, text)
        return self._obstacles_text_of[1]

    def world_state(self, now: int | None = None) -> dict[str, Any]:
        """The ground truth as viewers and run records see it (one line of ``world.jsonl``), at ``now``
        (default: the latest model time)."""
        now = self._now if now is None else now
        bodies = self.world.snapshot()
        poses = {b["id"]: b for b in bodies}
        modes = self.ir.counter.modes
        for body in bodies:
            node = self.medium.nodes.get(body["id"])
            body["pan_id"] = None if node is None else node.pan_id
            body["ir"] = str(modes.get(body["id"], "idle"))
            tele = self._telemetry.get(body["id"], {})
            # an empty role or state (a robot outside any swarm) is published as none
            body["state"], body["role"] = tele.get("state") or None, tele.get("role") or None
            body["reference"] = _reference(poses.get(tele.get("master", "")), tele.get("slot"))
        totals = {"delivered": 0, "collided": 0, "lost": 0}
        for counters in list(self.medium.node_counters.values()):  # a snapshot: the medium's thread may add one
            for name in totals:
                totals[name] += getattr(counters, name, 0)
        return {
            "v": 1,
            "t_us": now,
            "wall": round((self.wall_epoch_us + now) / 1e6, 4),
            "bodies": bodies,
            "obstacles": [o.to_dict() for o in self.world.obstacles],
            "collisions": self.world.collisions,
            **({"contacts": [list(pair) for pair in contacts]} if (contacts := self.world.contacts) else {}),
            "radio": totals,
        }

    def _deliver_ble(self, now: int) -> None:
        for delivery in self.ble.due(now):
            if delivery.dst in self._kinds:
                msg = wire.BleReceived(src=delivery.src, payload=delivery.payload, t_us=delivery.due_us)
                self._send_down(delivery.dst, msg)

    # -- inputs ----------------------------------------------------------------------------------
    def _on_up(self, node_id: str, data: bytes | wire.Message, wait: bool) -> bool:
        try:
            if node_id not in self._kinds:  # an attached id's name was checked when it attached
                check_name("node", node_id)
            msg = wire.check(data) if isinstance(data, wire.Message) else wire.decode(data, wire.MAX_UP_BYTES)
        except ValueError as err:
            self.counters.malformed += 1
            if node_id in self._kinds or not _is_name(node_id):
                # an attached id hears nothing it did not send (it may be someone else speaking for it)
                return True
            self._send_down(node_id, wire.Error(reason=f"malformed message: {err}"))
            return True
        if type(msg) is wire.Transmit and self._kinds.get(node_id) == "robot":
            self._take_up(node_id, msg)  # the medium's alone: no world lock
            return True
        if not self.world_lock.acquire(blocking=wait):
            return False
        try:
            self._take_up(node_id, msg)
        finally:
            self.world_lock.release()
        return True

    def _take_up(self, node_id: str, msg: wire.Message) -> None:
        if type(msg) is wire.Drive and self._kinds.get(node_id) == "robot" and msg.s == self._session_keys[node_id]:
            # the bulk of the uplink (every robot's motor command, 25 Hz): the steps the branches below take for it
            self._check_sequence(node_id, msg)
            self._on_body(node_id, msg)
            return
        if isinstance(msg, wire.Attach) and msg.exclusive and node_id in self._kinds:
            # a refused claim must not touch the live node's sequence numbering (its holder ignores the answer)
            self._send_down(node_id, wire.Error(reason=f"node id {node_id} is taken", instance=msg.instance))
            return
        if node_id in self._kinds and msg.s != self._session_keys.get(node_id) and not self._may_take(node_id, msg):
            self.counters.foreign += 1  # refused without an answer: an answer would reach the id's holder
            return
        if node_id in self._kinds and not isinstance(msg, wire.Attach):
            self._check_sequence(node_id, msg)
        if isinstance(msg, wire.Attach):
            self._on_attach(node_id, msg)
        elif node_id not in self._kinds:
            self.counters.unattached += 1
            self._send_down(node_id, wire.Error(token=getattr(msg, "token", 0), reason=wire.NOT_ATTACHED))
        elif isinstance(msg, wire.Relay):
            self._on_relay(node_id, msg)
        elif isinstance(msg, wire.Detach):
            self._detach(node_id)
        elif self._kinds[node_id] == "control":
            self.counters.malformed += 1
            self._send_down(node_id, wire.Error(reason=f"{msg.TYPE}: a control node has no body and no radio"))
        elif isinstance(msg, (wire.Drive, wire.Place, wire.LfBurst, wire.BleSend, wire.Telemetry)):
            self._on_body(node_id, msg)
        elif isinstance(msg, wire.Transmit):
            self._on_transmit(node_id, msg)
        elif isinstance(msg, wire.Configure):
            self._on_configure(node_id, msg)
        elif isinstance(msg, wire.SetIrMode):
            self._on_ir_mode(node_id, msg)
        else:
            self.counters.malformed += 1
            self._send_down(node_id, wire.Error(reason=f"{msg.TYPE} is not a node-to-hub message"))

    def _may_take(self, node_id: str, msg: wire.Message) -> bool:
        """A message with another session key than the attached node's: only an attach, and only once the
        holder's liveliness token is gone (a restarted process), may take the id."""
        if not isinstance(msg, wire.Attach):
            return False
        alive = self.holder_alive
        return alive is None or not alive(node_id, self._instances.get(node_id, ""))

    def _on_transmit(self, node_id: str, msg: wire.Transmit) -> None:
        if self._kinds[node_id] != "robot":
            self._send_down(node_id, wire.Error(token=msg.token, reason="a user has no 802.15.4 radio"))
            return
        node = self.medium.nodes.get(node_id)
        frame = _frame_of(msg.psdu)
        src = None if frame is None or frame.frame_type is FrameType.ACK else frame.src
        if node is not None and src is not None and src != node.short_addr:
            self.counters.spoofed += 1
            reason = f"source address 0x{src:04x} is not this node's (0x{node.short_addr:04x})"
            report = TxReport(node_id, msg.token, TxStatus.REFUSED, 0, 0, self.now_us(), self.now_us(), reason)
            self._send_down(node_id, _tx_done(report))
            return
        self._dispatch(self.medium.submit(node_id, msg.psdu, msg.token, self.now_us(), frame))

    def _on_relay(self, node_id: str, msg: wire.Relay) -> None:
        """The control channel: to another node as it is, or a question to the hub answered at once. Only a run's
        orchestrator (kind ``control``) asks; a robot or a user only answers it (relays to a control node): asking
        through the hub, it would get what access control refuses it when it asks directly (the hub's stats and
        chaos, another robot's control)."""
        if self._kinds[node_id] != "control" and self._kinds.get(msg.to) != "control":
            self.counters.relay_refused += 1
            self._send_down(node_id, wire.Error(reason="only a run's orchestrator relays"))
            return
        if msg.to == HUB:
            self._send_down(node_id, wire.Relayed(frm=HUB, body=self._hub_answer(msg.body)))
        elif msg.to in self._kinds:
            self._send_down(msg.to, wire.Relayed(frm=node_id, body=msg.body))
        else:
            self._send_down(node_id, wire.Relayed(frm=msg.to, body=msg.body, bounced=True))

    def _hub_answer(self, body: bytes) -> bytes:
        try:
            request = msgpack.unpackb(body, raw=False)
            if not isinstance(request, dict):
                raise ValueError("a hub request is a map")
            op = request.get("op")
            if op == "stats":
                answer: dict[str, Any] = self.stats()
            elif op == "chaos":
                answer = self.chaos_request(request.get("request"), self._now, (self.wall_epoch_us + self._now) / 1e6)
            elif op == "world":
                answer = self.world_state()
            else:
                raise ValueError(f"op must be stats, chaos or world, not {op!r}")
        except Exception as err:  # a bad request must not hurt the environment
            answer = {"error": f"{type(err).__name__}: {err}"}
            request = {}
        return msgpack.packb({"id": request.get("id"), "answer": answer}, use_bin_type=True)

    def _check_sequence(self, node_id: str, msg: wire.Message) -> None:
        # an attach starts a node's numbering (a node re-attaching after a hub restart goes on counting)
        last = msg.n - 1 if isinstance(msg, wire.Attach) else self._up_seq.get(node_id, msg.n - 1)
        if msg.n > last + 1:
            self.counters.transport_gaps += min(msg.n - last - 1, MAX_GAP)
        self._up_seq[node_id] = msg.n

    def _on_attach(self, node_id: str, msg: wire.Attach) -> None:
        self.medium.detach(node_id)
        self.ir.remove(node_id, self.now_us())  # a restarted node's module starts dark, as the node believes
        self._kinds.pop(node_id, None)
        # a node that restarts under the same id starts afresh; a robot that re-attaches to a restarted
        # hub says where it last was (its position as the old hub reported it)
        node = RadioNode(node_id, msg.ext_addr, msg.short_addr, msg.pan_id, msg.channel, _pos(msg.position))
        try:
            if msg.kind not in NODE_KINDS:
                raise ValueError(f"kind must be one of {NODE_KINDS}, not {msg.kind!r}")
            if msg.kind == "control" and is_node_identity(node_id):
                # under access control a certificate publishes only on its own node's key: an orchestrator under
                # that id would let it relay what it may not ask directly
                self.counters.relay_refused += 1
                raise ValueError(f"{node_id} is a robot's or a user's id, not a run's orchestrator")
            if msg.kind == "robot":
                self.medium.attach(node)
            if msg.kind != "control":
                x, y = node.position
                self.world.add(node_id, msg.kind, x, y, math.radians(msg.heading_deg))
        except ValueError as err:
            self.medium.detach(node_id)
            self.counters.config_errors += 1
            self._send_down(node_id, wire.Error(reason=f"cannot attach: {err}"))
            return
        self._kinds[node_id] = msg.kind
        if msg.kind == "user":
            self.ir.power[node_id] = PERSON_BEACON_POWER
        self.counters.attaches += 1
        self._instances[node_id] = msg.instance
        self._session_keys[node_id] = msg.s
        self._gone.pop(node_id, None)
        self._check_sequence(node_id, msg)

        self._down_seq[node_id] = 0
        self._send_down(node_id, self._attached(node_id, 0))

    def _on_configure(self, node_id: str, msg: wire.Configure) -> None:
        changes: dict[str, Any] = {
            name: getattr(msg, name) for name in ("pan_id", "short_addr", "channel") if getattr(msg, name) is not None
        }
        body = self.world.bodies[node_id]
        try:
            if changes and self._kinds[node_id] != "robot":
                raise ValueError("a user has no 802.15.4 radio")
            if changes:
                self.medium.update(node_id, **changes)
            if msg.position is not None or msg.heading_deg is not None:
                x, y = _pos(msg.position) if msg.position is not None else body.pose[:2]
                yaw = math.radians(msg.heading_deg) if msg.heading_deg is not None else body.pose[2]
                self.world.place(node_id, float(x), float(y), float(yaw))
                if node_id in self.medium.nodes:
                    self.medium.nodes[node_id].position = (float(x), float(y))
        except (ValueError, TypeError) as err:
            self.counters.config_errors += 1
            self._send_down(node_id, wire.Error(token=msg.token, reason=f"cannot configure: {err}"))
            return
        self._send_down(node_id, self._attached(node_id, msg.token))

    def _on_body(self, node_id: str, msg: wire.Message) -> None:
        """Motor commands, a user's pose, LF bursts, BLE messages and telemetry; none is answered, so a
        bad one is counted and reported with an error message."""
        try:
            if isinstance(msg, wire.Drive):
                self.world.command(node_id, msg.vx, msg.vy, msg.omega, self.now_us() / 1e6)
            elif isinstance(msg, wire.Place):
                if self._kinds[node_id] != "user":
                    raise ValueError("only a user places itself; robots drive")
                self.world.place(node_id, msg.x, msg.y, msg.yaw, msg.vx, msg.vy, msg.omega)
            elif isinstance(msg, wire.LfBurst):
                self._on_lf_burst(node_id, msg)
            elif isinstance(msg, wire.BleSend):
                self._on_ble_send(node_id, msg)
            elif isinstance(msg, wire.Telemetry):
                self._telemetry[node_id] = {
                    "state": msg.state,
                    "role": msg.role,
                    "master": msg.master,
                    "slot": msg.slot,
                }
        except ValueError as err:
            self.counters.config_errors += 1
            self._send_down(node_id, wire.Error(reason=f"{msg.TYPE}: {err}"))

    def _on_lf_burst(self, node_id: str, msg: wire.LfBurst) -> None:
        if self._kinds[node_id] != "robot":
            raise ValueError("only robots have LF antennas")
        if msg.antenna not in ("left", "right") or len(msg.data) > 4:
            raise ValueError("antenna is left or right and data at most 4 bytes")
        self.lf_counters["bursts"] += 1
        left, right = antenna_positions(self.world.bodies[node_id].pose)
        at = left if msg.antenna == "left" else right
        now = self.now_us()
        for user_id, kind in self._kinds.items():
            if kind != "user":
                continue
            rssi = lf_rssi(at, self.world.bodies[user_id].pose[:2], self.config.lf, self._lf_rng)
            if rssi is None:
                continue
            self.lf_counters["heard"] += 1
            heard = wire.LfHeard(antenna=msg.antenna, pattern=msg.pattern, data=msg.data, rssi_dbm=rssi, t_us=now)
            self._send_down(user_id, heard)

    def _on_ble_send(self, node_id: str, msg: wire.BleSend) -> None:
        if msg.to not in self.world.bodies:
            self.ble.counters.sent += 1
            self.ble.counters.out_of_range += 1  # nobody of that name: like a peer out of reach
            return
        a, b = self.world.bodies[node_id].pose, self.world.bodies[msg.to].pose
        self.ble.send(node_id, msg.to, msg.payload, self.now_us(), float(math.hypot(a[0] - b[0], a[1] - b[1])))

    def _on_ir_mode(self, node_id: str, msg: wire.SetIrMode) -> None:
        try:
            self.ir.set_mode(node_id, msg.mode, self.now_us())
        except ValueError:
            self.counters.config_errors += 1
            self._send_down(node_id, wire.Error(token=msg.token, reason=f"unknown IR mode {msg.mode!r}"))
            return
        self._send_down(node_id, self._attached(node_id, msg.token))

    def chaos_request(self, request: Any, now_us: int, wall_s: float) -> dict[str, Any]:
        """Add, clear or list faults (``{"op": "add", "fault": {...}}``...); every change is logged with model
        and wall time. A bad request is answered with ``{"error": ...}``."""
        self._at(now_us)
        chaos = self.medium.chaos
        try:
            if not isinstance(request, dict):
                raise ValueError("a chaos request is a map")
            op = request.get("op", "list")
            if op == "add":
                chaos.add(request["fault"], self.now_us(), wall_s)
                print(f"hub: chaos {describe_change(chaos.log[-1])}", file=sys.stderr, flush=True)
            elif op == "clear":
                chaos.clear(request.get("id"), self.now_us(), wall_s)
                print(f"hub: chaos {describe_change(chaos.log[-1])}", file=sys.stderr, flush=True)
            elif op != "list":
                raise ValueError(f"op must be add, clear or list, not {op!r}")
        except Exception as err:  # a bad request must not hurt the hub
            self.counters.chaos_refused += 1
            return {"error": f"{type(err).__name__}: {str(err)[:300]}"}
        return {"faults": [f.to_dict() for f in chaos.faults.values()], "log": chaos.log}

    def _attached(self, node_id: str, token: int) -> wire.Attached:
        node = self.medium.nodes.get(node_id)
        body = self.world.bodies.get(node_id)
        pose = (0.0, 0.0, 0.0) if body is None else body.pose
        return wire.Attached(
            token=token,
            ext_addr=0 if node is None else node.ext_addr,
            short_addr=0 if node is None else node.short_addr,
            pan_id=0 if node is None else node.pan_id,
            channel=11 if node is None else node.channel,
            position=[float(pose[0]), float(pose[1])],
            heading_deg=math.degrees(float(pose[2])),
            now_us=self.now_us(),
            ultrasonic_deg=list(self.world.config.ultrasonic_angles_deg),
            instance=self._instances.get(node_id, ""),
        )

    def _detach(self, node_id: str) -> None:
        self.medium.detach(node_id)
        self.ir.remove(node_id, self.now_us())
        self.world.remove(node_id)
        self.ir.power.pop(node_id, None)
        self._kinds.pop(node_id, None)
        self._telemetry.pop(node_id, None)
        self._up_seq.pop(node_id, None)
        self._session_keys.pop(node_id, None)
        self._instances.pop(node_id, None)
        self.counters.detaches += 1
        self.downlink.forget(node_id)
        self._forget_gone(node_id)

    def _forget_gone(self, node_id: str) -> None:
        """``node_id`` is not (or no longer) attached: keep its bookkeeping while it is among the last
        ``GONE_KEPT`` such ids, then drop it."""
        self._gone.pop(node_id, None)
        self._gone[node_id] = None
        while len(self._gone) > GONE_KEPT:
            old = next(iter(self._gone))
            del self._gone[old]
            self._down_seq.pop(old, None)
            self.medium.node_counters.pop(old, None)
            self.counters.forgotten += 1

    # -- outputs ---------------------------------------------------------------------------------

    def _dispatch(self, outputs: list[Output]) -> None:
        if not outputs:
            return
        # every frame passes here twice (its delivery and its sender's result): encoded straight from the
        # medium's output, without a wire message in between
        now = self.now_us()
        lag = self.counters.lag_us
        send = self.downlink.send
        with self._down_lock:
            self._send_outputs(outputs, now, lag, send)

    def _send_outputs(
        self, outputs: list[Output], now: int, lag: deque[int], send: Callable[[str, bytes], None]
    ) -> None:
        for out in outputs:
            node_id = out.node_id
            if type(out) is Reception:
                lag.append(now - out.handed_up_us)  # a chaos delay is model time, not hub lag
                data = wire.encode_received(
                    self._next_down_seq(node_id),
                    out.psdu,
                    out.rssi_dbm,
                    out.lqi,
                    out.start_us,
                    out.end_us,
                    out.submitted_us,
                )
            else:
                if out.status is not TxStatus.REFUSED:  # refusals are immediate, not scheduled deliveries
                    lag.append(now - out.done_us)
                data = wire.encode_tx_done(
                    self._next_down_seq(node_id),
                    out.token,
                    out.status.value,
                    out.retries,
                    out.backoffs,
                    out.submitted_us,
                    out.done_us,
                    out.reason,
                )
            send(node_id, data)

    def send_to(self, node_id: str, msg: wire.Message) -> None:
        """A message to a node, numbered in its stream like every other (a lockstep ``Grant``)."""
        self._send_down(node_id, msg)

    def _send_down(self, node_id: str, msg: wire.Message) -> None:
        with self._down_lock:
            msg.n = self._next_down_seq(node_id)
            if self._hand_over is not None and isinstance(msg, HANDED_OVER):
                self._hand_over(node_id, msg)
            else:
                self.downlink.send(node_id, msg.encode())

    def _send_all(self, messages: Iterable[tuple[str, wire.Message]]) -> None:
        """``_send_down`` of a tick's ``HANDED_OVER`` messages (one per robot), in order, under one hold of the
        lock and without asking each whether it may be handed over."""
        hand_over = self._hand_over
        with self._down_lock:
            for node_id, msg in messages:
                msg.n = self._next_down_seq(node_id)
                if hand_over is not None:
                    hand_over(node_id, msg)
                else:
                    self.downlink.send(node_id, msg.encode())

    def _next_down_seq(self, node_id: str) -> int:
        """The number of the next message to ``node_id`` (its stream starts at 1 on every attach)."""
        seq = self._down_seq.get(node_id)
        if seq is None:
            if node_id not in self._kinds:
                self._forget_gone(node_id)  # an answer to an id that never attached: its numbering is bounded too
            seq = 0
        seq += 1
        self._down_seq[node_id] = seq
        return seq

    def _write_pcap(self, tx: Transmission) -> None:
        pcap = self._pcap
        if pcap is None:
            return
        try:
            pcap.write(tx.psdu, self.wall_epoch_us + tx.start_us)
            self._pcap_records += 1
        except (OSError, ValueError) as err:  # a full disk must not take the air down: stop recording
            self._pcap_error = str(err)
            self._pcap = None
            print(f"hub: pcap {self.pcap_path}: {err}; no longer recording", file=sys.stderr)
            with contextlib.suppress(OSError):
                pcap.close()

    # -- introspection ---------------------------------------------------------------------------

    def stats(self, now_us: int | None = None) -> dict[str, Any]:
        """Counters per node and per channel, hub anomalies, and the attached nodes' radios (the caller adds
        the world's name)."""
        if now_us is not None:
            self._at(now_us)
        medium = self.medium
        nodes = {}
        for node_id, counters in medium.node_counters.items():
            entry: dict[str, Any] = counters.to_dict()
            node = medium.nodes.get(node_id)
            entry["attached"] = node is not None
            if node is not None:
                entry.update(
                    pan_id=node.pan_id, short_addr=node.short_addr, channel=node.channel, position=list(node.position)
                )
            nodes[node_id] = entry
        channels = {str(ch): c.to_dict() for ch, c in medium.channel_counters.items() if c.sent or c.heard}
        stats: dict[str, Any] = {
            "seed": self.seed,
            "now_us": self.now_us(),
            "config": medium.config.to_dict(),
            "nodes": nodes,
            "channels": channels,
            "hub": {**self.counters.to_dict(), "faults": self.faults.to_dict()},
            "chaos": [f.to_dict() for f in medium.chaos.faults.values()],
            "chaos_log_dropped": medium.chaos.log_dropped,
            "ir": {
                **self.ir.counter.as_dict(self.now_us()),
                "sweeps": self.ir.sweeps,
                "beacon_sweeps": self.ir.beacon_sweeps,
                "config": self.ir.config.to_dict(),
            },
            "world_model": {
                "bodies": len(self.world.bodies),
                "collisions": self.world.collisions,
                "collision_log": self.world.collision_log[-100:],
                "config": self.world.config.to_dict(),
                "obstacles": [o.to_dict() for o in self.world.obstacles],
            },
            "ble": self.ble.counters.to_dict(),
            "lf": dict(self.lf_counters),
        }
        if self.pcap_path is not None:
            stats["pcap"] = {"path": str(self.pcap_path), "records": self._pcap_records, "error": self._pcap_error}
        return stats


def _tx_done(report: TxReport) -> wire.TxDone:
    return wire.TxDone(
        token=report.token,
        status=report.status.value,
        retries=report.retries,
        backoffs=report.backoffs,
        submitted_us=report.submitted_us,
        done_us=report.done_us,
        reason=report.reason,
    )


def _contacts_text(world: World) -> str:
    """The world line's ``"contacts":[[a,b],...],`` (the pairs touching now, so a judge can tell who touched what:
    the collision counter alone cannot), or nothing at all while nothing touches."""
    contacts = world.contacts
    if not contacts:
        return ""
    return f'"contacts":{json.dumps([list(pair) for pair in contacts], separators=(",", ":"))},'


_KIND, _RADIUS, _PAN_ID = (operator.attrgetter(name) for name in ("kind", "radius", "pan_id"))
_RADIO_TOTALS = tuple(map(operator.attrgetter, ("delivered", "collided", "lost")))
"""The medium's counts a world line sums over nodes, in its order."""


def _body_text(
    body_id: str, kind: str, radius: float, pan_id: int | None, ir: str, state: str | None, role: str | None
) -> tuple[str, str]:
    """The JSON of a body's fields but its pose and velocity, before and after them (its reference null)."""
    compact = functools.partial(json.dumps, separators=(",", ":"))
    head = f'{{"id":{compact(body_id)},"kind":{compact(kind)},"x":'
    tail = (
        f',"radius":{compact(radius)},"pan_id":{compact(pan_id)},"ir":{compact(ir)},'
        f'"state":{compact(state)},"role":{compact(role)},"reference":null}}'
    )
    return head, tail


def _json_number(value: Any) -> str:
    """``json.dumps`` of a number: an int's or a finite float's ``repr`` as it writes them, without the cost of
    its call (microseconds, three times a line)."""
    if type(value) is int or (type(value) is float and math.isfinite(value)):
        return repr(value)
    return json.dumps(value)


def _reference(master: dict[str, Any] | None, slot: list[float] | None) -> list[float] | None:
    """A slave's formation reference in the world: its slot (master frame) placed by the master's true pose."""
    if master is None or slot is None:
        return None
    c, s = math.cos(master["yaw"]), math.sin(master["yaw"])
    return [round(master["x"] + c * slot[0] - s * slot[1], 4), round(master["y"] + s * slot[0] + c * slot[1], 4)]


def _frame_of(psdu: bytes) -> Frame | None:
    """The frame a transmit request carries, decoded once for the source check and the medium (None: not a
    valid frame, which the medium refuses with the reason)."""
    try:
        return Frame.decode(psdu)
    except FrameError:
        return None


_NODE_IDENTITY = re.compile(r"(robot|user)-[0-9]+")


def is_node_identity(node_id: str) -> bool:
    """Whether ``node_id`` is a robot's or a user's id (``robot-<n>``, ``user-<n>``): the ids access control
    gives a certificate of that name, and the only ids a robot or a user process attaches under."""
    return _NODE_IDENTITY.fullmatch(node_id) is not None


def _is_name(node_id: str) -> bool:
    try:
        check_name("node", node_id)
    except ValueError:
        return False
    return True


def _pos(values: list[float]) -> tuple[float, float]:
    return (float(values[0]), float(values[1]))


def load_config(path: str | Path) -> EnvironmentConfig:
    """A hub config file (TOML or JSON): the radio's tables plus optional ``[ir]``, ``[world]``, ``[ble]``,
    ``[lf]`` tables and ``[[obstacles]]``."""
    path = Path(path)
    text = path.read_text()
    data = tomllib.loads(text) if path.suffix == ".toml" else json.loads(text)
    try:
        return environment_from_dict(data)
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from None


def config_problem(path: str | Path) -> str | None:
    """Why the hub config file at ``path`` cannot be used (it names the file), or None: for a run or an
    experiment to refuse it before anything starts."""
    try:
        load_config(path)
    except (OSError, UnicodeDecodeError) as err:
        return f"cannot read {path}: {err}"
    except ValueError as err:  # a bad key, value or syntax; the message names the file and the table
        return str(err)
    return None


def environment_from_dict(data: dict[str, Any]) -> EnvironmentConfig:
    """The tables of a hub config (or a scenario's ``[hub]`` table plus its obstacles)."""
    # the radio's tables sit at the top level or under [medium], not both
    radio = ("medium",) if "medium" in data else tuple(MediumConfig().to_dict())
    check_keys(data, ("ir", "world", "ble", "lf", "obstacles", *radio), "the top level")
    data = dict(data)
    ir = IrConfig.from_dict(data.pop("ir", {}))
    world = WorldConfig.from_dict(data.pop("world", {}))
    ble = BleConfig.from_dict(data.pop("ble", {}))
    lf = LfConfig.from_dict(data.pop("lf", {}))
    obstacles = data.pop("obstacles", [])
    if not isinstance(obstacles, list):
        raise ValueError("obstacles is a list of [[obstacles]] tables")
    parsed = [parse_obstacle(o, f"[[obstacles]][{i}]") for i, o in enumerate(obstacles)]
    medium = MediumConfig.from_dict(data.get("medium", data))
    return EnvironmentConfig(medium, ir, world, ble, lf, parsed)
