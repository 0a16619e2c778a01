"""The radio hub process: a zenoh router whose one job thread owns the ``Medium``.

Zenoh callbacks only hand samples to an inbox queue. The job thread takes them in arrival order,
stamps each with the model clock (microseconds since the hub started), feeds the medium, and sleeps
until the next model event with a timed wait. A plain thread is used rather than asyncio because
epoll's millisecond timeouts would add up to a millisecond of lag to every delivery; a timed queue
wait overshoots by tens of microseconds.

With ``pcap_path`` the hub also writes every transmission that leaves the air, data frames and ACKs,
to a pcap file (``radio_hub.pcap``), stamped with the wall-clock time at which it started on the air.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import math
import os
import queue
import sys
import threading
import time
import tomllib
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
import zenoh

from radio_hub import wire
from radio_hub.config import MediumConfig
from radio_hub.ir_air import IrAir
from radio_hub.keys import Keys, check_name, reliable_publisher, session_config
from radio_hub.light import IrConfig
from radio_hub.medium import Medium, Output, RadioNode, Reception, Transmission, TxReport, TxStatus
from radio_hub.pcap import PcapWriter

_IDLE_WAKE_US = 200_000
_SPIN_US = 100
"""Sleep until this close to the next model event, then spin: deliveries land within a few us of model time."""

_PR_SET_TIMERSLACK = 29


@dataclass
class HubCounters:
    """Anything that is not a radio outcome: bad input and transport anomalies."""

    malformed: int = 0
    unattached: int = 0
    transport_gaps: int = 0
    config_errors: int = 0
    attaches: int = 0
    detaches: int = 0
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
            "lag_p50_us": float(np.percentile(lags, 50)),
            "lag_p99_us": float(np.percentile(lags, 99)),
            "lag_samples": len(self.lag_us),
        }


class RadioHub:
    """The emulated air of one world, served over zenoh."""

    def __init__(
        self,
        endpoint: str,
        world: str,
        config: MediumConfig | None = None,
        seed: int = 0,
        ir_config: IrConfig | None = None,
        pcap_path: str | Path | None = None,
    ) -> None:
        """Raises OSError when ``pcap_path`` is given and cannot be opened for writing."""
        self.endpoint = endpoint
        self.keys = Keys(world)
        self.seed = seed
        self.pcap_path = None if pcap_path is None else Path(pcap_path)
        self._pcap = None if self.pcap_path is None else PcapWriter(self.pcap_path)
        self._pcap_records = 0
        self._pcap_error = ""
        self.medium = Medium(
            config or MediumConfig(),
            np.random.default_rng(seed),
            on_air_end=None if self._pcap is None else self._write_pcap,
        )
        self.counters = HubCounters()
        self._inbox: queue.SimpleQueue[tuple[Any, ...]] = queue.SimpleQueue()
        self._stop = threading.Event()
        self._pubs: dict[str, zenoh.Publisher] = {}
        self._up_seq: dict[str, int] = {}
        self._instances: dict[str, str] = {}
        self._headings: dict[str, float] = {}
        self.ir = IrAir(ir_config or IrConfig(), np.random.default_rng([seed, 1]))
        self._down_seq: dict[str, int] = {}
        self._t0_ns = time.perf_counter_ns()
        self._t0_wall_us = time.time_ns() // 1000
        self._session: zenoh.Session | None = None
        self._decls: list[Any] = []

    def now_us(self) -> int:
        """The model clock."""
        return (time.perf_counter_ns() - self._t0_ns) // 1000

    def open(self) -> None:
        """Open the router session and declare the hub's keys. Raises zenoh.ZError if it cannot listen."""
        session = zenoh.open(session_config("router", self.endpoint))
        self._session = session
        put = self._inbox.put
        keys = self.keys
        self._decls = [
            session.declare_subscriber(keys.up_all, lambda s: put(("up", str(s.key_expr), s.payload.to_bytes()))),
            session.liveliness().declare_subscriber(
                keys.alive_all, lambda s: put(("alive", str(s.key_expr), s.kind)), history=True
            ),
            session.declare_queryable(keys.stats, lambda q: put(("stats", q))),
            session.declare_queryable(keys.air, lambda q: put(("air", q))),
            session.declare_queryable(keys.chaos, lambda q: put(("chaos", q))),
            session.liveliness().declare_token(keys.hub_alive),
        ]
        self._t0_ns = time.perf_counter_ns()
        self._t0_wall_us = time.time_ns() // 1000

    def stop(self) -> None:
        """Ask the job loop to end (safe from any thread or a signal handler)."""
        self._stop.set()
        self._inbox.put(("wake",))

    def close(self) -> None:
        """Undeclare everything, close the session and the pcap file."""
        pcap, self._pcap = self._pcap, None
        if pcap is not None:
            pcap.close()
        for decl in self._decls:
            decl.undeclare()
        self._decls = []
        if self._session is not None:
            self._session.close()
            self._session = None

    def serve(self) -> None:
        """Run the job loop until ``stop``."""
        _tight_timer_slack()
        inbox, medium = self._inbox, self.medium
        while not self._stop.is_set():
            due = min((t for t in (medium.next_event_us(), self.ir.next_event_us()) if t is not None), default=None)
            until_due = _IDLE_WAKE_US if due is None else due - self.now_us()
            try:
                if until_due > _SPIN_US:
                    self._handle(inbox.get(timeout=(until_due - _SPIN_US) / 1e6))
                else:
                    self._handle(inbox.get_nowait())
                while True:  # take everything that arrived meanwhile before advancing time
                    self._handle(inbox.get_nowait())
            except queue.Empty:
                if 0 < until_due <= _SPIN_US:
                    # a timed wait wakes tens of microseconds late; yield-spin the last stretch instead
                    os.sched_yield()
            self._dispatch(medium.advance(self.now_us()))
            self._sweep_ir()

    def _sweep_ir(self) -> None:
        now = self.now_us()
        nodes = self.medium.nodes
        poses = {n: (*node.position, self._headings.get(n, 0.0)) for n, node in nodes.items()}
        for node_id, readings in self.ir.sweep(now, poses, self.medium.chaos).items():
            self._send_down(node_id, wire.IrSample(readings=readings.astype("<f4").tobytes(), t_us=now))

    # -- inputs ----------------------------------------------------------------------------------

    def _handle(self, item: tuple[Any, ...]) -> None:
        kind = item[0]
        if kind == "up":
            self._on_up(self.keys.node_of(item[1]), item[2])
        elif kind == "alive":
            self._on_alive(*self.keys.alive_of(item[1]), item[2])
        elif kind == "stats":
            self._reply(item[1], self.stats())
        elif kind == "air":
            self._reply(item[1], {"transmissions": [tx.to_dict() for tx in self.medium.air_log]})
        elif kind == "chaos":
            self._reply(item[1], self._on_chaos(item[1]))

    def _on_up(self, node_id: str, data: bytes) -> None:
        try:
            check_name("node", node_id)
            msg = wire.decode(data)
        except ValueError as err:
            self.counters.malformed += 1
            self._send_down(node_id, wire.Error(reason=f"malformed message: {err}"))
            return
        if isinstance(msg, wire.Attach) and msg.exclusive and node_id in self.medium.nodes:
            # a refused claim must not touch the live node's sequence numbering
            self._send_down(node_id, wire.Error(reason=f"node id {node_id} is taken"))
            return
        self._check_sequence(node_id, msg)
        if isinstance(msg, wire.Attach):
            self._on_attach(node_id, msg)
        elif node_id not in self.medium.nodes:
            self.counters.unattached += 1
            self._send_down(node_id, wire.Error(token=getattr(msg, "token", 0), reason=wire.NOT_ATTACHED))
        elif isinstance(msg, wire.Transmit):
            self._dispatch(self.medium.submit(node_id, msg.psdu, msg.token, self.now_us()))
        elif isinstance(msg, wire.Configure):
            self._on_configure(node_id, msg)
        elif isinstance(msg, wire.SetIrMode):
            self._on_ir_mode(node_id, msg)
        elif isinstance(msg, wire.Detach):
            self._detach(node_id)
        else:
            self.counters.malformed += 1
            self._send_down(node_id, wire.Error(reason=f"{msg.TYPE} is not a node-to-hub message"))

    def _check_sequence(self, node_id: str, msg: wire.Message) -> None:
        # an attach starts a node's numbering (a node re-attaching after a hub restart goes on counting)
        last = msg.n - 1 if isinstance(msg, wire.Attach) else self._up_seq.get(node_id, msg.n - 1)
        if msg.n > last + 1:
            self.counters.transport_gaps += msg.n - last - 1
        self._up_seq[node_id] = msg.n

    def _on_attach(self, node_id: str, msg: wire.Attach) -> None:
        self.medium.detach(node_id)
        self.ir.remove(node_id, self.now_us())  # a restarted node's module starts dark, as the node believes
        # a node that restarts under the same id starts afresh
        node = RadioNode(node_id, msg.ext_addr, msg.short_addr, msg.pan_id, msg.channel, _pos(msg.position))
        try:
            self.medium.attach(node)
        except ValueError as err:
            self.counters.config_errors += 1
            self._send_down(node_id, wire.Error(reason=f"cannot attach: {err}"))
            return
        self._headings[node_id] = math.radians(msg.heading_deg)
        self.counters.attaches += 1
        self._instances[node_id] = msg.instance
        if node_id not in self._pubs:
            self._pubs[node_id] = reliable_publisher(self._require_session(), self.keys.down(node_id))

        self._down_seq[node_id] = 0
        self._send_down(node_id, self._attached(node, 0))

    def _on_configure(self, node_id: str, msg: wire.Configure) -> None:
        changes: dict[str, Any] = {
            name: getattr(msg, name) for name in ("pan_id", "short_addr", "channel") if getattr(msg, name) is not None
        }
        if msg.position is not None:
            changes["position"] = _pos(msg.position)
        if msg.heading_deg is not None:
            self._headings[node_id] = math.radians(msg.heading_deg)
        try:
            node = self.medium.update(node_id, **changes)
        except (ValueError, TypeError) as err:
            self.counters.config_errors += 1
            self._send_down(node_id, wire.Error(token=msg.token, reason=f"cannot configure: {err}"))
            return
        self._send_down(node_id, self._attached(node, msg.token))

    def _on_ir_mode(self, node_id: str, msg: wire.SetIrMode) -> None:
        try:
            self.ir.set_mode(node_id, msg.mode, self.now_us())
        except ValueError:
            self.counters.config_errors += 1
            self._send_down(node_id, wire.Error(token=msg.token, reason=f"unknown IR mode {msg.mode!r}"))
            return
        self._send_down(node_id, self._attached(self.medium.nodes[node_id], msg.token))

    def _on_chaos(self, query: zenoh.Query) -> dict[str, Any]:
        """Add, clear or list faults; every change is logged with model and wall time."""
        chaos = self.medium.chaos
        try:
            request = msgpack.unpackb(query.payload.to_bytes(), raw=False) if query.payload else {}
            if not isinstance(request, dict):
                raise ValueError("a chaos request is a map")
            op = request.get("op", "list")
            if op == "add":
                fault = chaos.add(request["fault"], self.now_us(), time.time())
                print(f"hub: chaos {fault.to_dict()} at model {self.now_us()} us", file=sys.stderr, flush=True)
            elif op == "clear":
                ended = chaos.clear(request.get("id"), self.now_us(), time.time())
                print(f"hub: chaos cleared {ended} at model {self.now_us()} us", file=sys.stderr, flush=True)
            elif op != "list":
                raise ValueError(f"op must be add, clear or list, not {op!r}")
        except Exception as err:  # a bad request must not hurt the hub
            return {"error": f"{type(err).__name__}: {err}"}
        return {"faults": [f.to_dict() for f in chaos.faults.values()], "log": chaos.log}

    def _attached(self, node: RadioNode, token: int) -> wire.Attached:
        return wire.Attached(
            token=token,
            ext_addr=node.ext_addr,
            short_addr=node.short_addr,
            pan_id=node.pan_id,
            channel=node.channel,
            position=list(node.position),
            heading_deg=math.degrees(self._headings.get(node.node_id, 0.0)),
            now_us=self.now_us(),
        )

    def _on_alive(self, node_id: str, instance: str, kind: zenoh.SampleKind) -> None:
        gone = kind == zenoh.SampleKind.DELETE
        if gone and node_id in self.medium.nodes and self._instances.get(node_id) == instance:
            self._detach(node_id)

    def _detach(self, node_id: str) -> None:
        self.medium.detach(node_id)
        self.ir.remove(node_id, self.now_us())
        self.counters.detaches += 1
        pub = self._pubs.pop(node_id, None)
        if pub is not None:
            pub.undeclare()

    # -- outputs ---------------------------------------------------------------------------------

    def _dispatch(self, outputs: list[Output]) -> None:
        if not outputs:
            return
        now = self.now_us()
        lag = self.counters.lag_us
        for out in outputs:
            if isinstance(out, Reception):
                lag.append(now - out.handed_up_us)  # a chaos delay is model time, not hub lag
                msg: wire.Message = wire.Received(
                    psdu=out.psdu,
                    rssi_dbm=out.rssi_dbm,
                    lqi=out.lqi,
                    start_us=out.start_us,
                    end_us=out.end_us,
                    submitted_us=out.submitted_us,
                )
            else:
                if out.status != TxStatus.REFUSED:  # refusals are immediate, not scheduled deliveries
                    lag.append(now - out.done_us)
                msg = _tx_done(out)

            self._send_down(out.node_id, msg)

    def _send_down(self, node_id: str, msg: wire.Message) -> None:
        seq = self._down_seq.get(node_id, 0) + 1
        self._down_seq[node_id] = seq
        msg.n = seq
        pub = self._pubs.get(node_id)
        try:
            if pub is not None:
                pub.put(msg.encode())
            else:  # a node that never attached (or a raw client): best effort
                self._require_session().put(self.keys.down(node_id), msg.encode())
        except zenoh.ZError as err:
            print(f"hub: cannot reach {node_id}: {err}", file=sys.stderr)

    def _reply(self, query: zenoh.Query, body: dict[str, Any]) -> None:
        try:
            query.reply(query.key_expr, msgpack.packb(body, use_bin_type=True))
        finally:
            query.drop()

    def _require_session(self) -> zenoh.Session:
        if self._session is None:
            raise RuntimeError("hub session is not open")
        return self._session

    def _write_pcap(self, tx: Transmission) -> None:
        pcap = self._pcap
        if pcap is None:
            return
        try:
            pcap.write(tx.psdu, self._t0_wall_us + tx.start_us)
            self._pcap_records += 1
        except (OSError, ValueError) as err:  # a full disk must not take the air down: stop recording
            self._pcap_error = str(err)
            self._pcap = None
            print(f"hub: pcap {self.pcap_path}: {err}; no longer recording", file=sys.stderr)
            with contextlib.suppress(OSError):
                pcap.close()

    # -- introspection ---------------------------------------------------------------------------

    def stats(self) -> dict[str, Any]:
        """Counters per node and per channel, hub anomalies, and the attached nodes' radios."""
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
            "world": self.keys.world,
            "seed": self.seed,
            "now_us": self.now_us(),
            "config": medium.config.to_dict(),
            "nodes": nodes,
            "channels": channels,
            "hub": self.counters.to_dict(),
            "chaos": [f.to_dict() for f in medium.chaos.faults.values()],
            "ir": {
                **self.ir.counter.as_dict(self.now_us()),
                "sweeps": self.ir.sweeps,
                "config": self.ir.config.to_dict(),
            },
        }
        if self.pcap_path is not None:
            stats["pcap"] = {"path": str(self.pcap_path), "records": self._pcap_records, "error": self._pcap_error}
        return stats


def _tight_timer_slack() -> None:
    # Linux lets a sleeping thread wake up to 50 us late by default (timer slack); deliveries are
    # timed to the microsecond, so ask for 1 us. Best effort: other kernels keep their default.
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_TIMERSLACK, 1000)


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


def _pos(values: list[float]) -> tuple[float, float]:
    return (float(values[0]), float(values[1]))


def load_config(path: str | Path) -> tuple[MediumConfig, IrConfig]:
    """A hub config file (TOML or JSON): the radio's tables plus an optional ``[ir]`` table."""
    path = Path(path)
    text = path.read_text()
    data = tomllib.loads(text) if path.suffix == ".toml" else json.loads(text)
    if not isinstance(data, dict):
        raise ValueError("a hub config file holds tables")
    ir = IrConfig.from_dict(data.pop("ir", {}))
    try:
        return MediumConfig.from_dict(data.get("medium", data)), ir
    except ValueError as err:
        raise ValueError(f"{err} (and [ir] for the IR module)" if "the top level" in str(err) else str(err)) from None


def ready_line(hub: RadioHub) -> str:
    """The one JSON line a hub prints on stdout once it serves, for supervisors to wait on."""
    return json.dumps({"event": "hub_ready", "endpoint": hub.endpoint, "world": hub.keys.world, "seed": hub.seed})
