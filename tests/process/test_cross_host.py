"""A swarm across hosts: the hub, the robots and the user's CLI each in their own Linux network namespace.

Every namespace is a host with one address on 10.200.0.0/24, joined by veth pairs to a bridge that lives
in a namespace of its own, so no packet of the test touches the machine's own network: the hosts have no
default route and the addresses exist only inside them.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from petswarm.lab.processes import Supervisor

from ..waiting import once_settled

pytestmark = pytest.mark.process

SUBNET = "10.200.0"
HUB_PORT = 7447
# host name -> last octet of its address; the hub gets .1 so the README's addresses read naturally
HOSTS = {"hub": 1, "robots-a": 2, "robots-b": 3, "user": 4}


class NamespaceHosts:
    """Network namespaces on one bridge; ``run`` and ``wrap`` put commands on one of them."""

    def __init__(self) -> None:
        self.tag = f"ps{uuid.uuid4().hex[:6]}"
        self.switch = f"{self.tag}-sw"
        self.created: list[str] = []

    def namespace(self, host: str) -> str:
        """The namespace of ``host``."""
        return f"{self.tag}-{host}"

    def address(self, host: str) -> str:
        """The one address ``host`` has."""
        return f"{SUBNET}.{HOSTS[host]}"

    def wrap(self, host: str) -> list[str]:
        """The command prefix that runs a program on ``host`` (``ip netns exec`` execs it, so signals reach it)."""
        return ["ip", "netns", "exec", self.namespace(host)]

    def build(self) -> None:
        """The switch, then every host with a veth pair to it."""
        self._add_namespace(self.switch)
        self._ip(self.switch, "link", "add", "br0", "type", "bridge")
        self._ip(self.switch, "link", "set", "br0", "up")
        for n, host in enumerate(HOSTS):
            ns = self.namespace(host)
            self._add_namespace(ns)
            port = f"p{n}"
            self._ip(self.switch, "link", "add", port, "type", "veth", "peer", "name", "eth0", "netns", ns)
            self._ip(self.switch, "link", "set", port, "master", "br0", "up")
            self._ip(ns, "addr", "add", f"{self.address(host)}/24", "dev", "eth0")
            self._ip(ns, "link", "set", "eth0", "up")
            self._ip(ns, "link", "set", "lo", "up")

    def destroy(self) -> None:
        """Delete every namespace made (their veths go with them)."""
        for ns in reversed(self.created):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=10)
        self.created.clear()

    def run(self, host: str, *args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
        """``petswarm <args>`` on ``host``, to completion."""
        argv = [*self.wrap(host), sys.executable, "-m", "cli", *args]
        return subprocess.run(argv, capture_output=True, text=True, timeout=timeout, env=_env())

    def _add_namespace(self, ns: str) -> None:
        _check(["ip", "netns", "add", ns])
        self.created.append(ns)

    def _ip(self, ns: str, *args: str) -> None:
        _check(["ip", "-n", ns, *args])


def _check(argv: list[str]) -> None:
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=10)
    if proc.returncode:
        raise OSError(f"{' '.join(argv)}: {proc.stderr.strip()}")


def _env() -> dict[str, str]:
    # the children import this checkout's packages whatever the namespace's working directory
    root = str(Path(__file__).resolve().parents[2])
    return {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))}


def _why_namespaces_are_impossible() -> str | None:
    if not sys.platform.startswith("linux"):
        return "network namespaces exist only on Linux"
    if shutil.which("ip") is None:
        return "the `ip` command (iproute2) is not installed"
    if os.geteuid() != 0:
        return "creating network namespaces needs root (CAP_NET_ADMIN and CAP_SYS_ADMIN)"
    return None


@pytest.fixture
def hosts() -> Iterator[NamespaceHosts]:
    """Four test hosts on one bridge, removed after the test whatever happened."""
    reason = _why_namespaces_are_impossible()
    if reason:
        pytest.skip(f"cannot build test hosts: {reason}")
    made = NamespaceHosts()
    try:
        made.build()
    except OSError as err:
        made.destroy()
        pytest.skip(f"cannot build test hosts (no CAP_NET_ADMIN here?): {err}")
    try:
        yield made
    finally:
        made.destroy()


def _wait_attached(hosts: NamespaceHosts, hub: str, world: str, robots: set[str], sup: Supervisor) -> dict[str, Any]:
    deadline = time.monotonic() + 30
    stats: dict[str, Any] = {}
    while time.monotonic() < deadline:
        assert not sup.dead(), {n: sup.log_tail(n) for n in sup.dead()}
        proc = hosts.run("user", "stats", "--hub", hub, "--world", world, "--json", timeout=20)
        if proc.returncode == 0:
            stats = json.loads(proc.stdout)
            if {n for n, node in stats["nodes"].items() if node["attached"]} >= robots:
                return stats
        time.sleep(0.3)
    raise AssertionError(f"robots did not attach across hosts: {stats}\n" + sup.log_tail("hub"))


def _peers_of_hub(hosts: NamespaceHosts) -> set[str]:
    """Addresses with an established TCP connection to the hub's port, as the hub's host sees them."""
    argv = [*hosts.wrap("hub"), "ss", "-Htn", "state", "established", f"( sport = :{HUB_PORT} )"]
    out = subprocess.run(argv, capture_output=True, text=True, timeout=10).stdout
    return {line.split()[-1].rsplit(":", 1)[0] for line in out.splitlines() if line.strip()}


STATUS_WAIT_S = 10.0
"""How long a member may take to show what the master's answer already says (its process starved of CPU)."""


def _status_once(hosts: Any, where: list[str], rid: int, settled: Any) -> dict[str, Any]:
    """Robot ``rid``'s status from the user's host once ``settled(status)`` holds, or as it is after
    ``STATUS_WAIT_S`` (for the test to say what is wrong), instead of one read after a fixed sleep."""
    ask = ["swarm", "status", "--robot", str(rid), "--json", *where]
    return once_settled(lambda: json.loads(hosts.run("user", *ask).stdout), settled, STATUS_WAIT_S, every=0.1)


def test_robots_on_two_hosts_form_a_swarm_through_a_hub_on_a_third(hosts, tmp_path):
    world = "cross"
    hub = f"tcp/{hosts.address('hub')}:{HUB_PORT}"
    sup = Supervisor(tmp_path / "logs")
    try:
        sup.spawn("hub", ["hub", "--listen", f"tcp/0.0.0.0:{HUB_PORT}", "--world", world], hosts.wrap("hub"))
        robot = ["robot", "--hub", hub, "--world", world]
        sup.spawn("robot-1", [*robot, "--id", "1", "--user", "1"], hosts.wrap("robots-a"))
        sup.spawn("robot-2", [*robot, "--id", "2"], hosts.wrap("robots-b"))
        sup.spawn("robot-3", [*robot, "--id", "3"], hosts.wrap("robots-b"))
        _wait_attached(hosts, hub, world, {"robot-1", "robot-2", "robot-3"}, sup)
        if shutil.which("ss"):  # every robot host, and the user's, really talks to the hub over the bridge
            assert {hosts.address(h) for h in ("robots-a", "robots-b")} <= _peers_of_hub(hosts)

        where = ["--hub", hub, "--world", world]
        organized = hosts.run("user", "swarm", "organize", "--master", "1", "--count", "2", "--json", *where)
        assert organized.returncode == 0, organized.stderr + sup.log_tail("robot-1")
        answer = json.loads(organized.stdout)
        assert answer["members"] == [2, 3], answer

        for rid in (2, 3):  # a member's state follows messages its radio acknowledged before its process read them
            status = _status_once(hosts, where, rid, lambda s: s["state"] == "slave-driving")
            assert status["state"] == "slave-driving" and status["swarm"]["master"] == 1, status
            assert status["radio"]["pan_id"] == answer["pan_id"]
        dispersed = hosts.run("user", "swarm", "disperse", "--master", "1", "--json", *where)
        assert dispersed.returncode == 0 and json.loads(dispersed.stdout)["unconfirmed"] == []
    finally:
        codes = sup.stop_all()
    assert all(code == 0 for code in codes.values()), {n: sup.log_tail(n) for n in codes}
