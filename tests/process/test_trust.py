"""The trust model with real processes: a hub on mutual TLS with access control (README "Trust model").

Across network-namespace hosts, robots holding certificates form a swarm and a client without one cannot
even open a session; on loopback, a client holding robot-1's certificate cannot speak for robot-2, cannot
publish on any downlink, and cannot read another robot's downlink.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import msgpack
import pytest
import zenoh

from petswarm.lab.certs import make_certificates
from petswarm.lab.processes import Supervisor, free_tcp_port
from radio_hub.interface import Keys, open_session, query_hub
from radio_hub.link import wire, zenoh_link
from radio_hub.link.trust import OPERATOR, TransportSecurity
from radio_hub.link.up_keys import wait_for_up_key
from radio_hub.values import HubUnavailable
from tests.process import test_cross_host as cross
from tests.waiting import once_settled

pytestmark = pytest.mark.process

hosts = cross.hosts
"""Four namespace hosts on one bridge (the cross-host test's fixture, with its skip rule: root and iproute2)."""
HUB_PORT = cross.HUB_PORT

ROGUE = b"rogue"


def _certificates(out: Path, hub_host: str, robots: int) -> Path:
    try:
        make_certificates(out, [hub_host], [*(f"robot-{n}" for n in range(1, robots + 1)), OPERATOR])
    except FileNotFoundError:
        pytest.skip("the openssl command is not installed")
    return out


def _tls(certs: Path, name: str | None) -> list[str]:
    """Client options: the CA, and ``name``'s certificate unless None (a client without one)."""
    own = ["--tls-cert", str(certs / f"{name}.pem"), "--tls-key", str(certs / f"{name}.key")] if name else []
    return ["--tls-ca", str(certs / "ca.pem"), *own]


def _hub_tls(certs: Path) -> list[str]:
    return [
        "--tls-cert",
        str(certs / "hub.pem"),
        "--tls-key",
        str(certs / "hub.key"),
        "--tls-ca",
        str(certs / "ca.pem"),
    ]


def test_robots_on_two_hosts_form_a_swarm_over_mutual_tls_and_a_client_without_a_certificate_is_refused(
    hosts: cross.NamespaceHosts, tmp_path: Path
) -> None:
    world = "tls"
    certs = _certificates(tmp_path / "certs", hosts.address("hub"), 3)
    hub = f"tls/{hosts.address('hub')}:{HUB_PORT}"
    where = ["--hub", hub, "--world", world]
    sup = Supervisor(tmp_path / "logs")
    try:
        listen = ["hub", "--listen", f"tls/0.0.0.0:{HUB_PORT}", "--world", world, *_hub_tls(certs)]
        sup.spawn("hub", listen, hosts.wrap("hub"))
        for rid, host in ((1, "robots-a"), (2, "robots-b"), (3, "robots-b")):
            user = ["--user", "1"] if rid == 1 else []
            argv = ["robot", "--id", str(rid), *where, *_tls(certs, f"robot-{rid}"), *user]
            sup.spawn(f"robot-{rid}", argv, hosts.wrap(host))
        operator = [*where, *_tls(certs, OPERATOR)]
        _wait_attached(hosts, operator, {"robot-1", "robot-2", "robot-3"}, sup)

        organized = hosts.run("user", "swarm", "organize", "--master", "1", "--count", "2", "--json", *operator)
        assert organized.returncode == 0, organized.stderr + sup.log_tail("robot-1")
        assert json.loads(organized.stdout)["members"] == [2, 3]

        refused = hosts.run("user", "stats", "--json", *where, *_tls(certs, None), timeout=30)
        assert refused.returncode == 2 and "cannot reach" in refused.stderr, refused.stderr
        plain = hosts.run(
            "user", "stats", "--json", "--hub", f"tcp/{hosts.address('hub')}:{HUB_PORT}", "--world", world
        )
        assert plain.returncode == 2, plain.stdout
        # a robot's certificate opens a session but grants no question to the hub
        robot_asks = hosts.run("user", "stats", "--json", *where, *_tls(certs, "robot-3"), timeout=30)
        assert robot_asks.returncode == 2 and "no hub answered" in robot_asks.stderr, robot_asks.stderr
    finally:
        codes = sup.stop_all()
    assert all(code == 0 for code in codes.values()), {n: sup.log_tail(n) for n in codes}


def _wait_attached(hosts: cross.NamespaceHosts, operator: list[str], robots: set[str], sup: Supervisor) -> None:
    deadline = time.monotonic() + 30
    stats: dict = {}
    while time.monotonic() < deadline:
        assert not sup.dead(), {n: sup.log_tail(n) for n in sup.dead()}
        proc = hosts.run("user", "stats", "--json", *operator, timeout=20)
        if proc.returncode == 0:
            stats = json.loads(proc.stdout)
            if {n for n, node in stats["nodes"].items() if node["attached"]} >= robots:
                return
        time.sleep(0.3)
    raise AssertionError(f"robots did not attach over TLS: {stats}\n" + sup.log_tail("hub"))


@pytest.fixture
def tls_air(tmp_path: Path) -> Iterator[tuple[str, Keys, Path, Supervisor]]:
    """A hub on mutual TLS on loopback with robots 1 and 2 pinging; (endpoint, keys, certs, supervisor)."""
    certs = _certificates(tmp_path / "certs", "127.0.0.1", 2)
    endpoint, keys = f"tls/127.0.0.1:{free_tcp_port()}", Keys(f"tls{free_tcp_port()}")
    where = ["--hub", endpoint, "--world", keys.world]
    sup = Supervisor(tmp_path / "logs")
    try:
        sup.spawn("hub", ["hub", "--listen", endpoint, "--world", keys.world, *_hub_tls(certs)])
        for rid in (1, 2):
            argv = ["robot", "--id", str(rid), *where, *_tls(certs, f"robot-{rid}"), "--ping-interval", "0.2"]
            sup.spawn(f"robot-{rid}", argv)
        yield endpoint, keys, certs, sup
    finally:
        sup.stop_all()


def _session_as(certs: Path, name: str, endpoint: str) -> zenoh.Session:
    """A client session showing ``name``'s certificate (the process-wide setting, restored at once)."""
    security = TransportSecurity(str(certs / "ca.pem"), str(certs / f"{name}.pem"), str(certs / f"{name}.key"))
    zenoh_link.use_security(security)
    try:
        deadline = time.monotonic() + 20
        while True:
            try:
                return open_session("client", endpoint)
            except HubUnavailable:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)
    finally:
        zenoh_link.use_security(TransportSecurity())


def test_a_robot_certificate_speaks_only_for_its_robot_and_nobody_publishes_on_a_downlink(tls_air) -> None:
    endpoint, keys, certs, sup = tls_air
    operator = _session_as(certs, OPERATOR, endpoint)
    rogue = _session_as(certs, "robot-1", endpoint)
    try:
        _wait_both_attached(operator, keys, sup)
        heard: dict[str, list[bytes]] = {"down": [], "up": [], "own": [], "rogue reads": []}

        def into(name: str):
            return lambda sample: heard[name].append(sample.payload.to_bytes())

        # the operator may read everything, so it sees what the router lets through
        operator.declare_subscriber(keys.down("robot-2"), into("down"))
        operator.declare_subscriber(keys.up("robot-2"), into("up"))
        operator.declare_subscriber(keys.up("robot-1"), into("own"))
        rogue.declare_subscriber(keys.down("robot-2"), into("rogue reads"))
        time.sleep(0.5)
        for _ in range(20):
            rogue.put(keys.down("robot-2"), ROGUE)  # frames injected into robot-2's downlink
            rogue.put(keys.up("robot-2"), ROGUE)  # robot-1 speaking as robot-2
            rogue.put(keys.up("robot-1"), ROGUE)  # its own key: allowed
        time.sleep(1.5)
        assert heard["down"] and heard["up"], "the operator heard no traffic of robot-2"
        assert ROGUE not in heard["down"] and ROGUE not in heard["up"]
        assert ROGUE in heard["own"], "robot-1's certificate could not publish on its own key"
        # a session hears its own puts locally; what matters is that none of the hub's reached it
        assert set(heard["rogue reads"]) <= {ROGUE}, "robot-1's certificate read robot-2's downlink"
        answers = [r for r in rogue.get(keys.stats, timeout=2.0) if r.ok is not None]
        assert answers == [], "robot-1's certificate asked the hub's stats"
        assert not sup.dead(), {n: sup.log_tail(n) for n in sup.dead()}
    finally:
        rogue.close()
        operator.close()


def _wait_both_attached(session: zenoh.Session, keys: Keys, sup: Supervisor) -> None:
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        assert not sup.dead(), {n: sup.log_tail(n) for n in sup.dead()}
        try:
            nodes = query_hub(session, keys.stats, timeout=2.0)["nodes"]
        except HubUnavailable:
            nodes = {}
        if sum(1 for n in nodes.values() if n["attached"]) == 2 and nodes["robot-2"]["delivered"] > 0:
            return
        time.sleep(0.2)
    raise AssertionError("robots did not attach and ping over TLS:\n" + sup.log_tail("hub"))


@pytest.mark.parametrize(
    ("args", "why"),
    [
        (["--tls-cert", __file__], "--tls-cert and --tls-key go together"),
        (["--tls-ca", __file__], "the hub needs its own"),
        (["--tls-cert", __file__, "--tls-key", __file__], "needs a tls/ endpoint"),
    ],
)
def test_a_hub_refuses_tls_options_that_would_not_protect_it(args: list[str], why: str) -> None:
    argv = [sys.executable, "-m", "cli", "hub", "--listen", "tcp/127.0.0.1:1", *args]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=60, env=cross._env())
    assert done.returncode == 2 and why in done.stderr, done.stderr


def test_a_relay_gets_the_access_decision_of_the_same_request_asked_directly(tmp_path: Path) -> None:
    """A client with a robot's certificate (robot-3, not running) is denied the hub's stats and chaos directly;
    wrapped in a ``Relay`` on its own up key the same requests used to be answered (a loss fault with p = 1
    added, robot-1 told to stop). Now the hub refuses them, counted, and the robots go on."""
    certs = _certificates(tmp_path / "certs", "127.0.0.1", 3)
    endpoint, keys = f"tls/127.0.0.1:{free_tcp_port()}", Keys(f"tls{free_tcp_port()}")
    sup = Supervisor(tmp_path / "logs")
    sup.spawn("hub", ["hub", "--listen", endpoint, "--world", keys.world, *_hub_tls(certs)])
    where = ["--hub", endpoint, "--world", keys.world]
    for rid in (1, 2):
        argv = ["robot", "--id", str(rid), *where, *_tls(certs, f"robot-{rid}"), "--ping-interval", "0.2"]
        sup.spawn(f"robot-{rid}", argv)
    operator = _session_as(certs, OPERATOR, endpoint)
    rogue = _session_as(certs, "robot-3", endpoint)
    try:
        _wait_both_attached(operator, keys, sup)
        answers: list[wire.Message] = []
        rogue.declare_subscriber(keys.down("robot-3"), lambda s: answers.extend(wire.decode_all(s.payload.to_bytes())))
        token = rogue.liveliness().declare_token(keys.alive("robot-3", "r"))
        up = rogue.declare_publisher(keys.up("robot-3"))
        assert wait_for_up_key(up)
        assert [r for r in rogue.get(keys.stats, timeout=2.0) if r.ok is not None] == []  # directly: denied
        up.put(wire.Attach(short_addr=3, pan_id=0x1000, instance="r", n=1, s=9).encode())
        loss = {"op": "chaos", "request": {"op": "add", "fault": {"kind": "loss", "p": 1.0}}}
        for n, (to, body) in enumerate(
            (("hub", {"op": "stats"}), ("hub", loss), ("robot-1", {"cmd": "stop"})), start=2
        ):
            up.put(wire.Relay(to=to, body=msgpack.packb(body), n=n, s=9).encode())
        up.put(wire.Attach(short_addr=3, pan_id=0x1000, instance="r", kind="control", n=5, s=9).encode())
        stats = once_settled(lambda: query_hub(operator, keys.stats), lambda s: s["hub"]["relay_refused"] >= 4, 10)
        assert stats["hub"]["relay_refused"] == 4, stats["hub"]
        assert not [m for m in answers if isinstance(m, wire.Relayed)], answers
        assert query_hub(operator, keys.chaos, payload=msgpack.packb({"op": "list"}))["faults"] == []
        time.sleep(0.5)
        assert not sup.dead(), {n: sup.log_tail(n) for n in sup.dead()}  # robot-1 was not stopped
        token.undeclare()
    finally:
        rogue.close()
        operator.close()
        codes = sup.stop_all()
    assert all(code == 0 for code in codes.values()), codes
