"""Process-level fixtures: a real hub process and real robot processes on loopback."""

from __future__ import annotations

import json
import time
import uuid
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import pytest
import zenoh

from petswarm import control
from petswarm.lab.processes import Supervisor, free_tcp_port
from radio_hub.interface import Keys, open_session, query_hub
from radio_hub.values import HubUnavailable

LOSSLESS = {"range": {"success_ratio_rx": 1.0}, "path_loss": {"shadowing_sigma_db": 0.0}}
PING_UNTIL_S = 15.0
"""How long ``Air.heard`` pings for the replies it expects: the 20 s a robot has to attach is the same kind of
wait, for a process the machine's load may starve."""


class Air:
    """A hub process with robots attached to it, and a client session to drive them."""

    def __init__(self, tmp: Path, config: dict[str, Any], seed: int = 1, hub_args: Sequence[str] = ()) -> None:
        self.world = f"t{uuid.uuid4().hex[:10]}"
        self.keys = Keys(self.world)
        self.endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
        self.sup = Supervisor(tmp / "logs")
        config_file = tmp / "hub.json"
        config_file.write_text(json.dumps(config))
        where = ["--listen", self.endpoint, "--world", self.world, "--seed", str(seed)]
        self.hub_argv = ["hub", *where, "--config", str(config_file), *hub_args]
        self.sup.spawn("hub", self.hub_argv)
        self.session = self._connect()

    def restart_hub(self, down_s: float = 1.0) -> None:
        """Kill the hub outright and start a new one on the same endpoint after ``down_s``."""
        self.sup.children["hub"].kill()
        self.sup.stop(["hub"])
        self.session.close()
        time.sleep(down_s)
        self.sup.spawn("hub", self.hub_argv)
        self.session = self._connect()

    def _connect(self) -> zenoh.Session:
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            assert not self.sup.dead(), self.sup.log_tail("hub")
            try:
                session = open_session("client", self.endpoint)
            except HubUnavailable:
                time.sleep(0.1)
                continue
            try:
                query_hub(session, self.keys.stats, timeout=1.0)
                return session
            except HubUnavailable:
                session.close()
        raise AssertionError("hub did not come up:\n" + self.sup.log_tail("hub"))

    def robot(
        self, rid: int, pos: tuple[float, float] = (0.0, 0.0), pan: int = 0x1000, channel: int = 11, *extra: str
    ) -> None:
        """Start robot ``rid`` (``extra``: more ``petswarm robot`` arguments) and wait until it serves."""
        where = [f"--pos={pos[0]},{pos[1]}", "--pan", str(pan), "--channel", str(channel)]
        args = ["robot", "--id", str(rid), "--hub", self.endpoint, "--world", self.world, *where, *extra]
        self.sup.spawn(f"robot-{rid}", args)
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            assert not self.sup.dead(), {n: self.sup.log_tail(n) for n in self.sup.dead()}
            if self._attached(rid) and self._answers(rid):
                return
            time.sleep(0.1)
        raise AssertionError(f"robot {rid} did not attach:\n{self.sup.log_tail(f'robot-{rid}')}")

    def _attached(self, rid: int) -> bool:
        """The hub has robot ``rid`` attached; False when the hub is too busy to answer within its timeout (robots
        starting on a loaded machine starve it too: the caller asks again until its own deadline)."""
        try:
            node = self.stats()["nodes"].get(f"robot-{rid}")
        except HubUnavailable:
            return False
        return bool(node and node["attached"])

    def _answers(self, rid: int) -> bool:
        try:
            return self.cmd(rid, "status", timeout=1.0)["robot_id"] == rid
        except HubUnavailable:
            return False

    def cmd(self, rid: int, name: str, timeout: float = 5.0, **args: Any) -> dict[str, Any]:
        """A control command to one robot."""
        return control.command(self.session, self.keys, rid, name, timeout, **args)

    def heard(self, rid: int, expected: set[int], timeout: float = PING_UNTIL_S, **ping: Any) -> set[int]:
        """Who answered robot ``rid``'s pings (``ping``: the command's ``dst``, ``wait``), pinging again until all
        of ``expected`` have: a reply reaches the pinger within the ping's wait only when both processes get
        the CPU in time, so a missing reply on a loaded machine says nothing; every sender that ever answered is
        returned, so one that should not have still shows."""
        senders: set[int] = set()
        deadline = time.monotonic() + timeout
        while True:
            senders |= {r["from"] for r in self.cmd(rid, "ping", **ping)["replies"]}
            if expected <= senders or time.monotonic() > deadline:
                return senders

    def stats(self) -> dict[str, Any]:
        """The hub's counters."""
        return query_hub(self.session, self.keys.stats)

    def node(self, rid: int) -> dict[str, Any]:
        """The hub's counters of one robot."""
        return self.stats()["nodes"][f"robot-{rid}"]

    def air_log(self) -> list[dict[str, Any]]:
        """The hub's recent transmissions."""
        return query_hub(self.session, self.keys.air)["transmissions"]

    def close(self) -> dict[str, int]:
        """Stop everything; returns exit codes."""
        self.session.close()
        return self.sup.stop_all()


@pytest.fixture
def make_air(tmp_path: Path) -> Iterator[Any]:
    """``make_air(config=None, seed=1, hub_args=())`` starts a hub process (``hub_args``: more ``petswarm hub``
    arguments); everything is stopped after the test."""
    started: list[Air] = []

    def factory(config: dict[str, Any] | None = None, seed: int = 1, hub_args: Sequence[str] = ()) -> Air:
        air = Air(tmp_path / f"air{len(started)}", LOSSLESS if config is None else config, seed, hub_args)
        started.append(air)
        return air

    yield factory
    for air in started:
        if air.sup.children and any(p.poll() is None for p in air.sup.children.values()):
            air.close()
