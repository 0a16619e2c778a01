"""A run as Foxglove channels: what ``petswarm export --mcap`` writes and ``--foxglove`` serves live.

A run record holds three streams in time order: the world log (``world.jsonl``, the hub's ground truth each world
tick, petswarm/lab/watch_frames.py), each node's events (``events/<node>.jsonl``) and the air's frames
(``air.pcap``). ``RunChannels`` turns each item of them into Foxglove messages on these topics, every message logged
at the run's model time (nanoseconds from model time 0):

    /world/scene       SceneUpdate      bodies (robots coloured by their state, the user), obstacles, swarm links,
                                        the slots masters assign, IR modules that transmit: one per world frame
    /world/tf          FrameTransforms  world -> each body: one per world frame
    /world/counters    JSON             collisions and the air's delivered, collided, lost: one per world frame
    /ir/modes          JSON             the IR modules' modes at a world tick where one transmits or beacons (the
                                        hub sweeps the receivers while one does): one per such world frame
    /ir/fixes          JSON             every IR fix (robot, holder, bearing, distance): one per ``ir_fix`` event
    /ir/fix_scene      SceneUpdate      the same fix as an arrow in the robot's frame, shown for a second
    /radio/<node>      JSON             each frame a node put on the air: decoded MAC header, payload summary
                                        (the swarm message's type and fields) and that node's frames so far
    /radio/unknown     JSON             ACKs that answer no data frame of the capture (their sender is unknown)
    /counters/air      JSON             totals of the air so far (frames, data, ACKs, bytes): one per frame
    /log               Log              every event of every node (``name``: the node)

Everything here is pure but for logging on the channels: the caller reads the record (or follows a run) and says
what model time each item belongs to.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Iterable
from typing import Any

from petswarm.lab.palette import STATE_COLOURS
from petswarm.managers.messages import MessageError
from petswarm.managers.messages import decode as decode_message
from radio_hub.values import BROADCAST, Frame, FrameError, FrameType

EXTRA = "foxglove"
"""The optional dependencies (pyproject.toml) that export and live streaming need."""


class MissingExtra(RuntimeError):
    """The Foxglove SDK is not installed: one line saying which extra brings it."""


def require_sdk() -> Any:
    """The ``foxglove`` module of foxglove-sdk; MissingExtra when it is not installed."""
    try:
        import foxglove
        import foxglove.messages
    except ImportError as err:
        raise MissingExtra(
            f"the Foxglove SDK is not installed ({err.name or err}): pip install 'petswarm[{EXTRA}]'"
        ) from None
    return foxglove


UNKNOWN_STATE_COLOUR = "#808080"
USER_COLOUR = "#f0c808"
OBSTACLE_COLOUR = "#5a5a5a"
LINK_COLOUR = "#c44e52"
IR_COLOURS = {"transmit": "#ff7f0e", "beacon": "#17becf"}
BODY_HEIGHT_M = {"robot": 0.25, "user": 1.7}
WALL_HEIGHT_M = 0.5
FIX_SHOWN_S = 1.0
"""An IR fix's arrow stays in the 3D view this long (the next fix of the same pair replaces it)."""
WORLD_FRAME = "world"
RADIO_UNKNOWN = "unknown"

_NUMBER = {"type": "number"}
_INTEGER = {"type": "integer"}
COUNTERS_SCHEMA = {
    "type": "object",
    "title": "petswarm.WorldCounters",
    "properties": {
        "t_s": _NUMBER,
        "collisions": _INTEGER,
        "delivered": _INTEGER,
        "collided": _INTEGER,
        "lost": _INTEGER,
        "bodies": _INTEGER,
        "ir_transmitting": _INTEGER,
    },
}
IR_MODES_SCHEMA = {
    "type": "object",
    "title": "petswarm.IrModes",
    "properties": {
        "t_s": _NUMBER,
        "transmit": {"type": "array", "items": {"type": "string"}},
        "beacon": {"type": "array", "items": {"type": "string"}},
        "receive": {"type": "array", "items": {"type": "string"}},
    },
}
IR_FIX_SCHEMA = {
    "type": "object",
    "title": "petswarm.IrFix",
    "properties": {
        "t_s": _NUMBER,
        "robot": {"type": "string"},
        "holder": {"type": "string"},
        "round": _INTEGER,
        "sweeps": _INTEGER,
        "bearing_deg": _NUMBER,
        "distance_m": _NUMBER,
    },
}
RADIO_SCHEMA = {
    "type": "object",
    "title": "petswarm.RadioFrame",
    "properties": {
        "t_s": _NUMBER,
        "node": {"type": "string"},
        "length": _INTEGER,
        "valid": {"type": "boolean"},
        "error": {"type": "string"},
        "mac": {
            "type": "object",
            "properties": {
                "type": {"type": "string"},
                "seq": _INTEGER,
                "ack_request": {"type": "boolean"},
                "dst_pan": {"type": "string"},
                "dst": {"type": "string"},
                "src_pan": {"type": "string"},
                "src": {"type": "string"},
                "broadcast": {"type": "boolean"},
            },
        },
        "payload": {
            "type": "object",
            "properties": {"bytes": _INTEGER, "message": {"type": "string"}, "fields": {"type": "object"}},
        },
        "sent_so_far": _INTEGER,
    },
}
AIR_COUNTERS_SCHEMA = {
    "type": "object",
    "title": "petswarm.AirCounters",
    "properties": {
        "t_s": _NUMBER,
        "frames": _INTEGER,
        "data": _INTEGER,
        "acks": _INTEGER,
        "broadcasts": _INTEGER,
        "bytes": _INTEGER,
        "undecodable": _INTEGER,
    },
}

TOPIC_SCENE = "/world/scene"
TOPIC_TF = "/world/tf"
TOPIC_COUNTERS = "/world/counters"
TOPIC_IR_MODES = "/ir/modes"
TOPIC_IR_FIXES = "/ir/fixes"
TOPIC_IR_FIX_SCENE = "/ir/fix_scene"
TOPIC_AIR_COUNTERS = "/counters/air"
TOPIC_LOG = "/log"
RADIO_PREFIX = "/radio/"
FIXED_TOPICS = (
    TOPIC_SCENE,
    TOPIC_TF,
    TOPIC_COUNTERS,
    TOPIC_IR_MODES,
    TOPIC_IR_FIXES,
    TOPIC_IR_FIX_SCENE,
    TOPIC_AIR_COUNTERS,
    TOPIC_LOG,
)
"""Every topic but the radio's, which has one per node (``radio_topic``)."""

_LOG_LEVELS = {
    "warning": ("retry", "sync_missed", "ir_no_fix", "lost_user", "emergency", "no_owner"),
    "error": ("error", "died", "crash"),
}


def radio_topic(node: str) -> str:
    """The topic of one node's frames."""
    return RADIO_PREFIX + node


def node_of_address(short_addr: int) -> str:
    """The node a short address belongs to: a robot's short address is its id (``RobotConfig.identity``)."""
    return f"robot-{short_addr}"


def hex_colour(text: str, alpha: float = 1.0) -> dict[str, float]:
    """``#rrggbb`` as Foxglove's r, g, b, a in 0-1."""
    value = int(text.lstrip("#"), 16)
    return {"r": (value >> 16 & 255) / 255, "g": (value >> 8 & 255) / 255, "b": (value & 255) / 255, "a": alpha}


def state_colour(kind: str, state: str | None) -> str:
    """A body's colour: the user's own, a robot's by its state (grey when unknown)."""
    if kind == "user":
        return USER_COLOUR
    return STATE_COLOURS.get(state or "waiting", UNKNOWN_STATE_COLOUR)


@dataclasses.dataclass
class AirState:
    """What decoding the air's frames in order remembers: who sent each frame, and the totals so far."""

    awaiting_ack: dict[int, int] = dataclasses.field(default_factory=dict)
    """Sequence number -> destination of the latest data frame that asked for an ACK: who sends its ACK."""
    sent: dict[str, int] = dataclasses.field(default_factory=dict)
    frames: int = 0
    data: int = 0
    acks: int = 0
    broadcasts: int = 0
    bytes: int = 0
    undecodable: int = 0


def describe_frame(psdu: bytes, air: AirState) -> tuple[str, dict[str, Any]]:
    """(sending node, the frame's decoded MAC header and payload summary), and ``air`` brought up to date.

    An ACK carries no address: its sender is the destination of the data frame it answers (the latest one of its
    sequence number that asked for an ACK), else ``unknown``. A frame that does not decode (bad FCS, truncated) is
    kept with its error under ``unknown``."""
    air.frames += 1
    air.bytes += len(psdu)
    body: dict[str, Any] = {"length": len(psdu), "valid": True}
    try:
        frame = Frame.decode(psdu)
    except FrameError as err:
        air.undecodable += 1
        air.sent[RADIO_UNKNOWN] = air.sent.get(RADIO_UNKNOWN, 0) + 1
        return RADIO_UNKNOWN, {**body, "valid": False, "error": str(err), "sent_so_far": air.sent[RADIO_UNKNOWN]}
    if frame.frame_type == FrameType.ACK:
        air.acks += 1
        answered = air.awaiting_ack.pop(frame.seq, None)
        node = RADIO_UNKNOWN if answered is None else node_of_address(answered)
        body["mac"] = {"type": "ack", "seq": frame.seq, "ack_request": False}
    else:
        air.data += int(frame.frame_type == FrameType.DATA)
        air.broadcasts += int(frame.is_broadcast)
        if frame.ack_request and not frame.is_broadcast:
            air.awaiting_ack[frame.seq] = frame.dst
        node = node_of_address(frame.src)
        body["mac"] = {
            "type": frame.frame_type.name.lower(),
            "seq": frame.seq,
            "ack_request": frame.ack_request,
            "dst_pan": f"0x{frame.dst_pan:04x}",
            "dst": "broadcast" if frame.dst == BROADCAST else f"0x{frame.dst:04x}",
            "src_pan": f"0x{frame.src_pan:04x}",
            "src": f"0x{frame.src:04x}",
            "broadcast": frame.is_broadcast,
        }
        body["payload"] = summarise_payload(frame.payload)
    air.sent[node] = air.sent.get(node, 0) + 1
    body["sent_so_far"] = air.sent[node]
    return node, body


def summarise_payload(payload: bytes) -> dict[str, Any]:
    """A frame payload in a few fields: its size, and the swarm message it carries with its fields (bytes
    fields by their length), or ``message: undecoded`` for a payload that is not one."""
    summary: dict[str, Any] = {"bytes": len(payload)}
    try:
        message = decode_message(payload)
    except MessageError:
        summary["message"] = "undecoded"
        return summary
    summary["message"] = type(message).__name__
    summary["fields"] = {name: _plain(value) for name, value in dataclasses.asdict(message).items()}
    return summary


def _plain(value: Any) -> Any:
    if isinstance(value, bytes):
        return f"{len(value)} bytes"
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


def event_level(kind: str) -> str:
    """An event's log level by its kind: the failures and retries stand out from the course of the run."""
    for level, kinds in _LOG_LEVELS.items():
        if kind in kinds:
            return level
    return "info"


def event_text(event: dict[str, Any]) -> str:
    """One event as a log line: its kind, then its fields (times left out: the log time says it)."""
    fields = {k: v for k, v in event.items() if k not in ("t", "mono", "kind")}
    return f"{event.get('kind', '?')} {json.dumps(fields, separators=(',', ':'), default=str)}"


class RunChannels:
    """The channels of one run in a Foxglove context: give it the record's items in time order with their model
    time (``world_frame``, ``event``, ``air_frame``) and it logs them; ``counts`` says how many went to each topic.
    """

    def __init__(self, context: Any = None) -> None:
        """``context``: the Foxglove ``Context`` whose sinks (an MCAP writer, a WebSocket server) get the messages
        (None: the SDK's default one). Radio channels are made as their nodes first send."""
        fox = require_sdk()
        from foxglove import channels as ch
        from foxglove import messages as m

        self._fox, self._m, self._context = fox, m, context
        self.counts: dict[str, int] = {}
        self.air = AirState()
        self._scene = ch.SceneUpdateChannel(TOPIC_SCENE, context=context)
        self._tf = ch.FrameTransformsChannel(TOPIC_TF, context=context)
        self._counters = self._json(TOPIC_COUNTERS, COUNTERS_SCHEMA)
        self._ir_modes = self._json(TOPIC_IR_MODES, IR_MODES_SCHEMA)
        self._ir_fixes = self._json(TOPIC_IR_FIXES, IR_FIX_SCHEMA)
        self._fix_scene = ch.SceneUpdateChannel(TOPIC_IR_FIX_SCENE, context=context)
        self._air_counters = self._json(TOPIC_AIR_COUNTERS, AIR_COUNTERS_SCHEMA)
        self._log = ch.LogChannel(TOPIC_LOG, context=context)
        self._radio: dict[str, Any] = {}
        self._levels = {
            "info": m.LogLevel.Info,
            "warning": m.LogLevel.Warning,
            "error": m.LogLevel.Error,
        }
        self._deletion = [m.SceneEntityDeletion(type=m.SceneEntityDeletionType.All)]

    def _json(self, topic: str, schema: dict[str, Any]) -> Any:
        return self._fox.Channel(topic, schema=schema, context=self._context)

    def _emit(self, channel: Any, topic: str, message: Any, t_ns: int) -> None:
        channel.log(message, log_time=t_ns)
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def _stamp(self, t_ns: int) -> Any:
        return self._m.Timestamp(t_ns // 1_000_000_000, t_ns % 1_000_000_000)

    # -- the world -------------------------------------------------------------------------------------

    def world_frame(self, frame: dict[str, Any], t_ns: int) -> None:
        """One checked world frame (``watch_frames.check_frame``): scene, transforms, counters, IR modes."""
        stamp = self._stamp(t_ns)
        bodies = frame["bodies"]
        for body in bodies:  # a robot's radio channel is there from its first frame: a live viewer subscribes to
            if body["kind"] == "robot":  # it before the robot sends, and misses none of its frames
                self._radio_channel(body["id"])
        entities = [self._body_entity(b, stamp) for b in bodies]
        entities.append(self._obstacles_entity(frame["obstacles"], stamp))
        links = self._links_entity(bodies, stamp)
        if links is not None:
            entities.append(links)
        m = self._m
        self._emit(self._scene, TOPIC_SCENE, m.SceneUpdate(deletions=self._deletion, entities=entities), t_ns)
        transforms = [
            m.FrameTransform(
                timestamp=stamp,
                parent_frame_id=WORLD_FRAME,
                child_frame_id=b["id"],
                translation=m.Vector3(x=b["x"], y=b["y"], z=0.0),
                rotation=_yaw_quaternion(m, b["yaw"]),
            )
            for b in bodies
        ]
        self._emit(self._tf, TOPIC_TF, m.FrameTransforms(transforms=transforms), t_ns)
        modes: dict[str, list[str]] = {"transmit": [], "beacon": [], "receive": []}
        for b in bodies:
            if b["ir"] in modes:
                modes[b["ir"]].append(b["id"])
        t_s = t_ns / 1e9
        radio = frame["radio"]
        counters = {"t_s": t_s, "collisions": frame["collisions"], **radio, "bodies": len(bodies)}
        counters["ir_transmitting"] = len(modes["transmit"]) + len(modes["beacon"])
        self._emit(self._counters, TOPIC_COUNTERS, counters, t_ns)
        if modes["transmit"] or modes["beacon"]:
            self._emit(self._ir_modes, TOPIC_IR_MODES, {"t_s": t_s, **modes}, t_ns)

    def declare_robots(self, count: int) -> None:
        """Make the radio channels of robots 1 to ``count`` now. A live server advertises a channel made while a
        viewer is connected before it can take the viewer's subscription (foxglove-sdk 0.30 refuses it as "unknown
        channel" now and then), so a run's own channels are best all there before anyone connects."""
        for robot_id in range(1, count + 1):
            self._radio_channel(node_of_address(robot_id))

    def _radio_channel(self, node: str) -> Any:
        topic = radio_topic(node)
        channel = self._radio.get(topic)
        if channel is None:
            channel = self._radio[topic] = self._json(topic, RADIO_SCHEMA)
        return channel

    def _body_entity(self, body: dict[str, Any], stamp: Any) -> Any:
        m = self._m
        kind, radius = body["kind"], body["radius"]
        height = BODY_HEIGHT_M.get(kind, 0.25)
        colour = m.Color(**hex_colour(state_colour(kind, body["state"])))
        x, y, yaw = body["x"], body["y"], body["yaw"]
        heading, upright = _yaw_quaternion(m, yaw), _yaw_quaternion(m, 0.0)
        cylinder = m.CylinderPrimitive(
            pose=m.Pose(position=m.Vector3(x=x, y=y, z=height / 2), orientation=upright),
            size=m.Vector3(x=2 * radius, y=2 * radius, z=height),
            bottom_scale=1.0,
            top_scale=1.0,
            color=colour,
        )
        arrow = m.ArrowPrimitive(
            pose=m.Pose(position=m.Vector3(x=x, y=y, z=height + 0.02), orientation=heading),
            shaft_length=radius * 1.2,
            shaft_diameter=radius * 0.25,
            head_length=radius * 0.6,
            head_diameter=radius * 0.6,
            color=m.Color(r=0.1, g=0.1, b=0.1, a=1.0),
        )
        label = body["id"] if body["state"] is None else f"{body['id']} {body['state']}"
        text = m.TextPrimitive(
            pose=m.Pose(position=m.Vector3(x=x, y=y, z=height + 0.25), orientation=upright),
            billboard=True,
            font_size=12.0,
            scale_invariant=True,
            color=m.Color(r=0.0, g=0.0, b=0.0, a=1.0),
            text=label,
        )
        cylinders = [cylinder]
        lit = IR_COLOURS.get(body["ir"])
        if lit is not None:  # an IR module that lights the others: a flat translucent disc round the body (a
            # cylinder costs the file a tenth of what a ring of line points does, at every frame of every body)
            cylinders.append(
                m.CylinderPrimitive(
                    pose=m.Pose(position=m.Vector3(x=x, y=y, z=0.01), orientation=upright),
                    size=m.Vector3(x=3.2 * radius, y=3.2 * radius, z=0.02),
                    bottom_scale=1.0,
                    top_scale=1.0,
                    color=m.Color(**hex_colour(lit, 0.45)),
                )
            )
        metadata = [m.KeyValuePair(key=key, value=str(body[key])) for key in ("kind", "state", "role", "ir", "pan_id")]
        return m.SceneEntity(
            timestamp=stamp,
            frame_id=WORLD_FRAME,
            id=body["id"],
            metadata=metadata,
            cylinders=cylinders,
            arrows=[arrow],
            texts=[text],
        )

    def _obstacles_entity(self, obstacles: Iterable[dict[str, Any]], stamp: Any) -> Any:
        m = self._m
        colour = m.Color(**hex_colour(OBSTACLE_COLOUR, 0.9))
        upright = _yaw_quaternion(m, 0.0)
        cylinders, cubes = [], []
        for o in obstacles:
            if o["kind"] == "circle":
                cylinders.append(
                    m.CylinderPrimitive(
                        pose=m.Pose(position=m.Vector3(x=o["x"], y=o["y"], z=WALL_HEIGHT_M / 2), orientation=upright),
                        size=m.Vector3(x=2 * o["r"], y=2 * o["r"], z=WALL_HEIGHT_M),
                        bottom_scale=1.0,
                        top_scale=1.0,
                        color=colour,
                    )
                )
                continue
            x0, y0, x1, y1 = o["x0"], o["y0"], o["x1"], o["y1"]
            if o["kind"] == "rect":
                centre = m.Vector3(x=(x0 + x1) / 2, y=(y0 + y1) / 2, z=WALL_HEIGHT_M / 2)
                size = m.Vector3(x=abs(x1 - x0), y=abs(y1 - y0), z=WALL_HEIGHT_M)
                pose = m.Pose(position=centre, orientation=upright)
                cubes.append(m.CubePrimitive(pose=pose, size=size, color=colour))
                continue
            length = math.hypot(x1 - x0, y1 - y0)  # a wall: a thin box along its segment
            centre = m.Vector3(x=(x0 + x1) / 2, y=(y0 + y1) / 2, z=WALL_HEIGHT_M / 2)
            along = _yaw_quaternion(m, math.atan2(y1 - y0, x1 - x0))
            size = m.Vector3(x=length, y=0.05, z=WALL_HEIGHT_M)
            cubes.append(m.CubePrimitive(pose=m.Pose(position=centre, orientation=along), size=size, color=colour))
        return m.SceneEntity(timestamp=stamp, frame_id=WORLD_FRAME, id="obstacles", cylinders=cylinders, cubes=cubes)

    def _links_entity(self, bodies: list[dict[str, Any]], stamp: Any) -> Any | None:
        """The swarm's links (each slave to the master of its PAN) and the slots the masters give (spheres)."""
        m = self._m
        masters = {b["pan_id"]: b for b in bodies if b["role"] == "master" and b["pan_id"] is not None}
        points = []
        for b in bodies:
            master = masters.get(b["pan_id"]) if b["role"] == "slave" else None
            if master is not None:
                points += [m.Point3(x=master["x"], y=master["y"], z=0.3), m.Point3(x=b["x"], y=b["y"], z=0.3)]
        slots = [
            m.SpherePrimitive(
                pose=m.Pose(
                    position=m.Vector3(x=b["reference"][0], y=b["reference"][1], z=0.02),
                    orientation=_yaw_quaternion(m, 0.0),
                ),
                size=m.Vector3(x=0.08, y=0.08, z=0.08),
                color=m.Color(**hex_colour(STATE_COLOURS["slave-driving"], 0.6)),
            )
            for b in bodies
            if b["reference"] is not None
        ]
        if not points and not slots:
            return None
        lines = []
        if points:
            lines.append(
                m.LinePrimitive(
                    type=m.LinePrimitiveLineType.LineList,
                    thickness=0.02,
                    points=points,
                    color=m.Color(**hex_colour(LINK_COLOUR, 0.8)),
                )
            )
        return m.SceneEntity(timestamp=stamp, frame_id=WORLD_FRAME, id="swarm-links", lines=lines, spheres=slots)

    # -- events ----------------------------------------------------------------------------------------

    def event(self, node: str, event: dict[str, Any], t_ns: int) -> None:
        """One event of ``node``'s record: a log line, and an IR fix also on the IR channels."""
        m = self._m
        kind = str(event.get("kind", "?"))
        log = m.Log(
            timestamp=self._stamp(t_ns),
            level=self._levels[event_level(kind)],
            message=event_text(event),
            name=node,
        )
        self._emit(self._log, TOPIC_LOG, log, t_ns)
        if kind == "ir_fix":
            self._ir_fix(node, event, t_ns)

    def _ir_fix(self, node: str, event: dict[str, Any], t_ns: int) -> None:
        m = self._m
        holder = event.get("holder")
        holder_node = node_of_address(holder) if isinstance(holder, int) else str(holder)
        bearing = _finite(event.get("bearing_deg"))
        distance = _finite(event.get("distance_m"))
        fix = {
            "t_s": t_ns / 1e9,
            "robot": node,
            "holder": holder_node,
            "round": event.get("round", 0),
            "sweeps": event.get("sweeps", 0),
            "bearing_deg": bearing,
            "distance_m": distance,
        }
        self._emit(self._ir_fixes, TOPIC_IR_FIXES, fix, t_ns)
        seconds = int(FIX_SHOWN_S)
        towards = _yaw_quaternion(m, math.radians(bearing))
        arrow = m.ArrowPrimitive(
            pose=m.Pose(position=m.Vector3(x=0.0, y=0.0, z=0.15), orientation=towards),
            shaft_length=max(distance - 0.1, 0.01),
            shaft_diameter=0.02,
            head_length=0.1,
            head_diameter=0.06,
            color=m.Color(**hex_colour(IR_COLOURS["transmit"], 0.8)),
        )
        entity = m.SceneEntity(
            timestamp=self._stamp(t_ns),
            frame_id=node,
            id=f"fix-{node}-{holder_node}",
            lifetime=self._m.Duration(seconds, round((FIX_SHOWN_S - seconds) * 1e9)),
            frame_locked=True,
            arrows=[arrow],
        )
        self._emit(self._fix_scene, TOPIC_IR_FIX_SCENE, m.SceneUpdate(entities=[entity]), t_ns)

    # -- the air ---------------------------------------------------------------------------------------

    def air_frame(self, psdu: bytes, t_ns: int) -> None:
        """One frame of the air (a pcap record's bytes): on its sender's channel, and the air's totals."""
        node, body = describe_frame(psdu, self.air)
        t_s = t_ns / 1e9
        self._emit(self._radio_channel(node), radio_topic(node), {"t_s": t_s, "node": node, **body}, t_ns)
        air = self.air
        totals = {
            "t_s": t_s,
            "frames": air.frames,
            "data": air.data,
            "acks": air.acks,
            "broadcasts": air.broadcasts,
            "bytes": air.bytes,
            "undecodable": air.undecodable,
        }
        self._emit(self._air_counters, TOPIC_AIR_COUNTERS, totals, t_ns)

    def close(self) -> None:
        """Close every channel (a live server drops their advertisements)."""
        fixed = (self._scene, self._tf, self._counters, self._ir_modes, self._ir_fixes, self._fix_scene)
        for channel in (*fixed, self._air_counters, self._log, *self._radio.values()):
            channel.close()


def _yaw_quaternion(m: Any, yaw: float) -> Any:
    return m.Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))


def _finite(value: Any) -> float:
    return float(value) if isinstance(value, int | float) and math.isfinite(value) else 0.0
