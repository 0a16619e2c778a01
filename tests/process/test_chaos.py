"""Faults injected with ``petswarm chaos`` into a running hub, and what the robots then see."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest

pytestmark = pytest.mark.process


def _chaos(air, *args: str) -> subprocess.CompletedProcess[str]:
    argv = [sys.executable, "-m", "cli", "chaos", *args, "--hub", air.endpoint, "--world", air.world]
    return subprocess.run(argv, capture_output=True, text=True, timeout=60)


def _senders(reply: dict) -> set[int]:
    return {r["from"] for r in reply["replies"]}


def test_partition_and_heal(make_air):
    air = make_air()
    for rid, x in ((1, 0.0), (2, 1.0), (3, 2.0)):
        air.robot(rid, (x, 0.0))
    cut = _chaos(air, "partition", "--group", "robot-3")
    assert cut.returncode == 0, cut.stderr
    assert json.loads(cut.stdout)[0]["kind"] == "partition"
    assert _senders(air.cmd(1, "ping", wait=0.4)) == {2}
    assert air.node(3)["heard"] == 0
    healed = _chaos(air, "clear")
    assert healed.returncode == 0 and json.loads(healed.stdout) == []
    assert _senders(air.cmd(1, "ping", wait=0.4)) == {2, 3}
    log = json.loads(_chaos(air, "list").stdout or "[]")
    assert log == []
    assert air.stats()["chaos"] == []


def test_loss_on_a_node_makes_unicast_fail_and_a_bad_fault_is_refused(make_air):
    air = make_air()
    air.robot(1, (0.0, 0.0))
    air.robot(2, (1.0, 0.0))
    assert _chaos(air, "loss", "--node", "robot-2", "--p", "1").returncode == 0
    answer = air.cmd(1, "ping", dst=2, wait=0.2)
    assert answer["tx"]["status"] == "no_ack" and _senders(answer) == set()
    assert air.node(2)["chaos_lost"] >= 4
    bad = _chaos(air, "partition", "--group", "")
    assert bad.returncode == 1 and "needs a group" in bad.stderr


def test_pause_resume_and_kill_a_robot(make_air):
    air = make_air()
    air.robot(1, (0.0, 0.0))
    air.robot(2, (1.0, 0.0))
    assert _chaos(air, "pause", "--robot", "2").returncode == 0
    assert _senders(air.cmd(1, "ping", wait=0.5)) == set()  # a stopped process answers nothing
    assert _chaos(air, "resume", "--robot", "2").returncode == 0
    time.sleep(0.3)
    assert 2 in _senders(air.cmd(1, "ping", wait=0.5))
    assert _chaos(air, "kill", "--robot", "2").returncode == 0
    deadline = time.monotonic() + 10
    while air.node(2)["attached"] and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not air.node(2)["attached"] and air.sup.children["robot-2"].poll() is not None


def _swarm_of_four(air) -> None:
    air.robot(1, (0.0, 0.0), 0x1000, 11, "--user", "1")
    for rid, x in ((2, 1.0), (3, 1.5), (4, 2.0)):
        air.robot(rid, (x, 0.5))
    assert air.cmd(1, "organize", timeout=30, count=3)["members"] == [2, 3, 4]


def test_a_slave_dies_the_master_drops_it_and_the_token_skips_it(make_air):
    air = make_air()
    _swarm_of_four(air)
    time.sleep(1.0)
    assert _chaos(air, "kill", "--robot", "3").returncode == 0
    deadline = time.monotonic() + 15
    while 3 in (air.cmd(1, "status")["swarm"] or {}).get("members", [3]) and time.monotonic() < deadline:
        time.sleep(0.2)
    master = air.cmd(1, "status")
    assert master["swarm"]["members"] == [2, 4], master["swarm"]
    assert master["state"] == "master-driving"
    held = {rid: air.cmd(rid, "status")["ir"]["rounds_held"] for rid in (1, 2, 4)}
    time.sleep(2.0)
    for rid in (1, 2, 4):  # the token still goes round the survivors
        s = air.cmd(rid, "status")
        assert s["ir"]["rounds_held"] > held[rid] and 3 not in s["ir"]["chain"], s["ir"]
    assert air.stats()["ir"]["overlap_episodes"] == 0


def test_the_master_dies_and_the_slaves_return_to_waiting(make_air):
    air = make_air()
    _swarm_of_four(air)
    assert _chaos(air, "kill", "--robot", "1").returncode == 0
    killed = time.monotonic()
    deadline = killed + 10
    states = {}
    while time.monotonic() < deadline:
        states = {rid: air.cmd(rid, "status") for rid in (2, 3, 4)}
        if all(s["state"] == "waiting" for s in states.values()):
            break
        time.sleep(0.2)
    assert all(s["state"] == "waiting" and s["radio"]["pan_id"] == 0x1000 for s in states.values()), states
    assert time.monotonic() - killed < 2.0 + 3.0  # the members' master-silence timeout, plus margin
    assert all(s["ir"]["ir_mode"] == "idle" for s in states.values())  # nobody left shining


def _consistent(air) -> bool:
    """Either the swarm goes on whole, or it is over for everyone (members home on the waiting PAN)."""
    master = air.cmd(1, "status")
    others = [air.cmd(rid, "status") for rid in (2, 3, 4)]
    if master["state"] == "master-driving":
        members = master["swarm"]["members"]
        return members == [2, 3, 4] and all(s["state"] == "slave-driving" for s in others)
    home = all(s["state"] == "waiting" and s["radio"]["pan_id"] == 0x1000 for s in others)
    hub_home = all(n["pan_id"] == 0x1000 for n in air.stats()["nodes"].values() if n["attached"])
    return master["state"] == "following" and master["radio"]["pan_id"] == 0x1000 and home and hub_home


def test_the_hub_restarts_and_the_robots_reattach_and_carry_on_or_reorganize(make_air):
    air = make_air()
    _swarm_of_four(air)
    air.restart_hub()
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        nodes = air.stats()["nodes"]
        attached = all(nodes.get(f"robot-{rid}", {}).get("attached") for rid in (1, 2, 3, 4))
        if attached and _consistent(air):
            break
        time.sleep(0.3)
    assert attached, nodes  # every robot attached itself to the new hub
    assert _consistent(air), [air.cmd(rid, "status")["state"] for rid in (1, 2, 3, 4)]
    if air.cmd(1, "status")["state"] == "master-driving":
        air.cmd(1, "disperse", timeout=30)
        time.sleep(0.3)
    again = air.cmd(1, "organize", timeout=30, count=3)  # the user can form the swarm again
    views = {rid: (air.cmd(rid, "status")["state"], air.node(rid)["pan_id"]) for rid in (1, 2, 3, 4)}
    assert sorted(again["members"]) == [2, 3, 4], (again, views)
    assert air.stats()["hub"]["transport_gaps"] == 0
