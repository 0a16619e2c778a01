"""The radio hub process: a zenoh router whose one job thread drives the ``Environment`` on the wall clock.

Zenoh callbacks only hand samples to an inbox queue. The job thread takes them in arrival order,
stamps each with the model clock (microseconds since the hub started), feeds the environment, and sleeps
until the environment's next event with a timed wait. A plain thread is used rather than asyncio because
epoll's millisecond timeouts would add up to a millisecond of lag to every delivery; a timed queue
wait overshoots by tens of microseconds.

With ``pcap_path`` the hub also writes every transmission that leaves the air, data frames and ACKs,
to a pcap file (``radio_hub.pcap``), stamped with the wall-clock time at which it started on the air.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import os
import queue
import threading
import time
from pathlib import Path
from typing import Any

import msgpack
import zenoh

from radio_hub.config import MediumConfig
from radio_hub.environment import (
    Environment,
    EnvironmentConfig,
    environment_from_dict,
    load_config,
    process_usage,
)
from radio_hub.keys import Keys
from radio_hub.light import IrConfig
from radio_hub.zenoh_link import HubDownlink, declare_hub_keys, reply, session_config

__all__ = ["Environment", "EnvironmentConfig", "RadioHub", "environment_from_dict", "load_config", "ready_line"]

_IDLE_WAKE_US = 200_000
_SPIN_US = 100
"""Sleep until this close to the next model event, then spin: deliveries land within a few us of model time."""

_PR_SET_TIMERSLACK = 29


class RadioHub:
    """The emulated environment of one world, served over zenoh on the wall clock."""

    def __init__(
        self,
        endpoint: str,
        world: str,
        config: MediumConfig | None = None,
        seed: int = 0,
        ir_config: IrConfig | None = None,
        pcap_path: str | Path | None = None,
        environment: EnvironmentConfig | None = None,
        world_log: str | Path | None = None,
    ) -> None:
        """Raises OSError when ``pcap_path`` or ``world_log`` is given and cannot be opened for writing.

        ``environment`` gives every table at once (``config`` and ``ir_config`` override its medium and IR);
        ``world_log`` receives one JSON line per world tick (the ground truth a run's metrics come from).
        """
        env = environment or EnvironmentConfig()
        tables = EnvironmentConfig(config or env.medium, ir_config or env.ir, env.world, env.ble, env.lf, env.obstacles)
        self.endpoint = endpoint
        self.keys = Keys(world)
        self.seed = seed
        self._downlink = HubDownlink(self.keys)
        self._t0_ns = time.perf_counter_ns()
        self.env = Environment(
            tables,
            seed,
            self._downlink,
            wall_epoch_us=time.time_ns() // 1000,
            pcap_path=pcap_path,
            world_log=world_log,
        )
        self._inbox: queue.SimpleQueue[tuple[Any, ...]] = queue.SimpleQueue()
        self._stop = threading.Event()
        self._session: zenoh.Session | None = None
        self._decls: list[Any] = []

    @property
    def medium(self) -> Any:
        """The environment's 802.15.4 medium."""
        return self.env.medium

    @property
    def environment(self) -> EnvironmentConfig:
        """The environment's tables."""
        return self.env.config

    def now_us(self) -> int:
        """The model clock: microseconds of wall time since the hub opened."""
        return (time.perf_counter_ns() - self._t0_ns) // 1000

    def open(self) -> None:
        """Open the router session and declare the hub's keys. Raises zenoh.ZError if it cannot listen."""
        session = zenoh.open(session_config("router", self.endpoint))
        self._session = session
        self._decls = declare_hub_keys(session, self.keys, self._inbox.put)
        self._downlink.world_pub = session.declare_publisher(self.keys.world_state)
        self._decls.append(self._downlink.world_pub)
        self._downlink.session = session
        self._t0_ns = time.perf_counter_ns()
        self.env.wall_epoch_us = time.time_ns() // 1000

    def stop(self) -> None:
        """Ask the job loop to end (safe from any thread or a signal handler)."""
        self._stop.set()
        self._inbox.put(("wake",))

    def close(self) -> None:
        """Undeclare everything, close the session, the pcap file and the world log."""
        self.env.close()
        self._downlink.session = None
        for decl in self._decls:
            decl.undeclare()
        self._decls = []
        if self._session is not None:
            self._session.close()
            self._session = None

    def serve(self) -> None:
        """Run the job loop until ``stop``."""
        _tight_timer_slack()
        inbox, env = self._inbox, self.env
        while not self._stop.is_set():
            until_due = env.next_event_us() - self.now_us()
            until_due = min(until_due, _IDLE_WAKE_US)
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
            env.advance(self.now_us())

    def _handle(self, item: tuple[Any, ...]) -> None:
        kind = item[0]
        if kind == "up":
            self.env.receive(self.keys.node_of(item[1]), item[2], self.now_us())
        elif kind == "alive":
            node_id, instance = self.keys.alive_of(item[1])
            if item[2] == zenoh.SampleKind.DELETE:
                self.env.node_gone(node_id, instance, self.now_us())
        elif kind == "stats":
            reply(item[1], self.stats())
        elif kind == "air":
            reply(item[1], self.env.air())
        elif kind == "chaos":
            query = item[1]
            try:
                request = msgpack.unpackb(query.payload.to_bytes(), raw=False) if query.payload else {}
            except Exception as err:  # a bad request must not hurt the hub
                reply(query, {"error": f"{type(err).__name__}: {err}"})
                return
            reply(query, self.env.chaos_request(request, self.now_us(), time.time()))
        elif kind == "world":
            reply(item[1], self.env.world_state(self.now_us()))

    def stats(self) -> dict[str, Any]:
        """The environment's counters, with this hub's world name and model clock."""
        return {"world": self.keys.world, **self.env.stats(self.now_us()), "process": process_usage()}


def _tight_timer_slack() -> None:
    # Linux lets a sleeping thread wake up to 50 us late by default (timer slack); deliveries are
    # timed to the microsecond, so ask for 1 us. Best effort: other kernels keep their default.
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_TIMERSLACK, 1000)


def ready_line(hub: RadioHub) -> str:
    """The one JSON line a hub prints on stdout once it serves, for supervisors to wait on."""
    return json.dumps({"event": "hub_ready", "endpoint": hub.endpoint, "world": hub.keys.world, "seed": hub.seed})
