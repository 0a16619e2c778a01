"""Faults injected with ``petswarm chaos`` into a running hub, and what the robots then see."""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
import time

import msgpack
import pytest

from radio_hub.interface import query_hub

from ..waiting import wait_for
from . import swarm_of_four as rl
from .conftest import PING_UNTIL_S

pytestmark = [pytest.mark.process, pytest.mark.long]


def _chaos(air, *args: str) -> subprocess.CompletedProcess[str]:
    argv = [sys.executable, "-m", "cli", "chaos", *args, "--hub", air.endpoint, "--world", air.world]
    return subprocess.run(argv, capture_output=True, text=True, timeout=60)


def _senders(reply: dict) -> set[int]:
    return {r["from"] for r in reply["replies"]}


def test_partition_and_heal(make_air):
    air = make_air()
    for rid, x in ((1, 0.0), (2, 1.0), (3, 2.0)):
        air.robot(rid, (x, 0.0))
    cut = _chaos(air, "partition", "--group", "robot-3", "--json")
    assert cut.returncode == 0, cut.stderr
    assert json.loads(cut.stdout)["faults"] == [{"fault_id": 1, "kind": "partition", "group": ["robot-3"]}]
    assert air.heard(1, {2}, wait=0.4) == {2}
    assert air.node(3)["heard"] == 0
    healed = _chaos(air, "clear")
    assert healed.returncode == 0 and healed.stdout.splitlines() == ["cleared fault 1", "no fault active"]
    assert air.heard(1, {2, 3}, wait=0.4) == {2, 3}
    listed = _chaos(air, "list")
    assert listed.stdout.splitlines()[0] == "no fault active", listed.stdout
    assert "added fault 1: partition robot-3 | everyone else" in listed.stdout and "{" not in listed.stdout
    assert air.stats()["chaos"] == []
    hub_log = (air.sup.log_dir / "hub.log").read_text()
    assert "hub: chaos at model " in hub_log and "added fault 1: partition robot-3 | everyone else" in hub_log
    assert "{" not in "".join(line for line in hub_log.splitlines() if "chaos" in line)  # no Python dicts


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
    assert 2 in air.heard(1, {2}, wait=0.5)  # it answers again once it has the CPU back
    assert _chaos(air, "kill", "--robot", "2").returncode == 0
    deadline = time.monotonic() + 10
    while air.node(2)["attached"] and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not air.node(2)["attached"] and air.sup.children["robot-2"].poll() is not None


def _swarm_of_four(air) -> None:
    air.robot(1, (0.0, 0.0), 0x1000, 11, "--user", "1")
    for rid, x in ((2, 1.0), (3, 1.5), (4, 2.0)):
        air.robot(rid, (x, 0.5))
    rl.organize_all(air)


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
    statuses = _after_rounds(air, 1, (1, 2, 4))  # the token still goes round the survivors
    assert all(3 not in s["ir"]["chain"] for s in statuses.values()), {rid: s["ir"] for rid, s in statuses.items()}
    assert air.stats()["ir"]["overlap_episodes"] == 0


def test_the_master_dies_and_the_slaves_return_to_waiting(make_air):
    air = make_air()
    _swarm_of_four(air)
    assert _chaos(air, "kill", "--robot", "1").returncode == 0
    deadline = time.monotonic() + 10
    states = {}
    while time.monotonic() < deadline:
        states = {rid: air.cmd(rid, "status") for rid in (2, 3, 4)}
        if all(s["state"] == "waiting" for s in states.values()):
            break
        time.sleep(0.2)
    assert all(s["state"] == "waiting" and s["radio"]["pan_id"] == 0x1000 for s in states.values()), states
    assert all(s["ir"]["ir_mode"] == "idle" for s in states.values())  # nobody left shining
    # each left on its master-silence timeout (how soon after the kill is the machine's, not the protocol's)
    left = {rid: _last_state_event(air, rid) for rid in (2, 3, 4)}
    assert all(e["to"] == "waiting" and e.get("reason") == "master silent" for e in left.values()), left


def _last_state_event(air, rid: int) -> dict:
    """Robot ``rid``'s last recorded state transition (its reason says why it moved)."""
    return [e for e in air.cmd(rid, "events")["events"] if e["kind"] == "state"][-1]


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


def _attached_all(air) -> bool:
    nodes = air.stats()["nodes"]
    return all(nodes.get(f"robot-{rid}", {}).get("attached") for rid in (1, 2, 3, 4))


def _radios(air) -> tuple[dict[int, str], dict[str, int]]:
    """Each robot's state and PAN as it sees them, and each attached node's PAN as the hub has it."""
    robots = {rid: air.cmd(rid, "status") for rid in (1, 2, 3, 4)}
    mine = {rid: f"{s['state']} pan {s['radio']['pan_id']:#x}" for rid, s in robots.items()}
    return mine, {k: n["pan_id"] for k, n in air.stats()["nodes"].items() if n["attached"]}


def test_the_hub_restarts_and_the_robots_reattach_and_carry_on_or_reorganize(make_air):
    air = make_air()
    _swarm_of_four(air)
    air.restart_hub()
    # every robot attaches itself to the new hub, and the swarm settles whole or over: judged on one snapshot
    # (read again, a swarm seen whole can be mid-way to over: a member leaves before its radio is home)
    try:
        wait_for("every robot attached and a consistent swarm", lambda: _attached_all(air) and _consistent(air), 20)
    except AssertionError:
        # each robot's state and PAN, and the hub's, and why each moved last
        print(_radios(air), {rid: air.cmd(rid, "events")["events"][-12:] for rid in (1, 2, 3, 4)})
        raise
    if air.cmd(1, "status")["state"] == "master-driving":
        air.cmd(1, "disperse", timeout=30)
    wait_for("robots 2-4 home", lambda: rl._home(air), 10, every=0.2)  # not a fixed sleep: a starved one is late
    again = rl.organize_all(air)  # the user can form the swarm again (on the wall clock, within three asks)
    views = {rid: (air.cmd(rid, "status")["state"], air.node(rid)["pan_id"]) for rid in (1, 2, 3, 4)}
    if sorted(again["members"]) != [2, 3, 4]:  # say why: each robot's last events
        views["events"] = {rid: air.cmd(rid, "events")["events"][-12:] for rid in (1, 2, 3, 4)}
        print(again, views)  # pytest shortens the assertion's message; its captured output is whole
    assert sorted(again["members"]) == [2, 3, 4], (again, views)
    assert air.stats()["hub"]["transport_gaps"] == 0


def test_corruption_fails_unicast_and_the_receiver_counts_it(make_air):
    air = make_air()
    air.robot(1, (0.0, 0.0))
    air.robot(2, (1.0, 0.0))
    assert _chaos(air, "corrupt", "--link", "robot-1,robot-2").returncode == 0
    answer = air.cmd(1, "ping", dst=2, wait=0.2)
    assert answer["tx"]["status"] == "no_ack" and _senders(answer) == set()
    node = air.node(2)
    assert node["corrupted"] == 4 and node["chaos_lost"] == 0  # the first try and 3 MAC retries, all bad FCS
    assert node["heard"] == node["delivered"] + node["collided"] + node["lost"] + node["filtered"]
    assert _chaos(air, "clear").returncode == 0
    assert air.heard(1, {2}, dst=2, wait=0.2) == {2}


def test_duplication_hands_robot_2_each_frame_twice(make_air):
    air = make_air()
    air.robot(1, (0.0, 0.0))
    air.robot(2, (1.0, 0.0))
    assert _chaos(air, "duplicate", "--link", "robot-1,robot-2").returncode == 0
    air.cmd(1, "ping", wait=0.2)
    # the hub has sent both copies when the ping returns; robot 2 reads them when it gets the CPU
    pings = wait_for("robot 2 handed two pings", lambda: _pings_from_1(air), 10, every=0.1)
    assert len(pings) == 2 and pings[0] == pings[1]  # the same frame off the air, handed up twice
    assert air.node(2)["duplicated"] == 1 and air.node(2)["delivered"] == 1


def _pings_from_1(air) -> list[dict]:
    """Robot 1's pings robot 2 has handed up, once there are two or more (else an empty list: try again)."""
    pings = [f for f in air.cmd(2, "received")["frames"] if f["type"] == "ping" and f["src"] == 1]
    return pings if len(pings) >= 2 else []


def _best_rtt_ms(air, rounds: int = 2) -> float:
    """The shortest round trip of robot 1's pings to robot 2: ``rounds`` of them, and more (up to
    ``PING_UNTIL_S``) while none has a reply. The wait is only how long replies are collected, so a round trip
    that a loaded machine made longer than it is no reply at all; a longer one only raises the minimum."""
    rtts: list[float] = []
    deadline = time.monotonic() + PING_UNTIL_S
    for sent in itertools.count(1):
        answer = air.cmd(1, "ping", dst=2, wait=1.0)
        assert answer["tx"]["status"] == "success", answer  # the ACK keeps the air's timing
        rtts += [r["rtt_ms"] for r in answer["replies"]]
        if (sent >= rounds and rtts) or time.monotonic() > deadline:
            break
    assert rtts, f"no reply to robot 1's pings within {PING_UNTIL_S:g} s"
    return min(rtts)


def test_delay_faults_from_the_cli_hold_frames_back_on_their_path(make_air):
    """Over sockets, a frame held back 60 ms cannot come back sooner, whatever the machine's load; by how much
    exactly a delay lengthens a round trip is asserted in model time (tests/model/test_robot.py), where the
    wall clock's noise in the base round trip cannot blur it."""
    air = make_air()
    air.robot(1, (0.0, 0.0))
    air.robot(2, (1.0, 0.0))
    assert _chaos(air, "delay", "--ms", "60", "--link", "robot-1,robot-2").returncode == 0
    assert _best_rtt_ms(air) >= 60
    assert _chaos(air, "clear").returncode == 0
    assert _chaos(air, "delay", "--ms", "60", "--node", "robot-2").returncode == 0  # both ways
    assert _best_rtt_ms(air) >= 120
    # the delay is model time, not the hub being late: on the air, robot 2's pong starts 60 ms of model time
    # after robot 1's ping left the air (robot 2 got it that much later), whatever the hub's wall-clock lag
    log = [tx for tx in air.air_log() if tx["type"] == "data"]
    pong = next(tx for tx in reversed(log) if tx["sender"] == "robot-2")
    ping = next(tx for tx in reversed(log) if tx["sender"] == "robot-1" and tx["end_us"] <= pong["start_us"])
    assert pong["start_us"] - ping["end_us"] >= 60_000, (ping, pong)
    refused = query_hub(air.session, air.keys.chaos, payload=msgpack.packb({"op": "add", "fault": {"kind": "delay"}}))
    assert "needs ms" in refused["error"]  # the hub refuses a malformed fault on its own too


def _runs_of(outcomes: list[str]) -> list[int]:
    runs, length = [], 0
    for outcome in [*outcomes, "delivered"]:
        if outcome == "lost":
            length += 1
        elif length:
            runs.append(length)
            length = 0
    return runs


def test_burst_losses_from_the_cli_come_in_runs_on_real_frames(make_air):
    """The command line's burst fault reaches the hub with its parameters and acts on robot 1's frames to robot 2.
    The chain's statistics (loss rate, run lengths) are asserted on 3,000 frames in
    tests/unit/test_chaos_delay_burst.py, tighter than 400 frames here allowed, by the same medium."""
    air = make_air()
    air.robot(1, (0.0, 0.0), 0x1000, 11, "--ping-interval", "0.01")
    air.robot(2, (1.0, 0.0))
    assert _chaos(air, "burst", "--link", "robot-1,robot-2", "--p-gb", "0.1", "--p-bg", "0.2").returncode == 0
    added = query_hub(air.session, air.keys.chaos)["log"][-1]  # logged with the model time it began
    assert (added["kind"], added["p_gb"], added["p_bg"]) == ("burst", 0.1, 0.2), added
    # at the chain's stationary loss of 1/3, 100 frames without a loss or without a delivery would be a fault
    judged = wait_for("100 judged frames", lambda: _judged_after(air, added["model_us"], 100), timeout=60)
    assert "lost" in judged and "delivered" in judged, judged
    assert max(_runs_of(judged)) >= 2, judged  # bad spells last 5 frames on average
    assert air.node(2)["chaos_lost"] >= judged.count("lost")


def _judged_after(air, model_us: int, enough: int) -> list[str]:
    """Robot 2's outcomes of robot 1's data frames since ``model_us`` (delivered or lost), once there are
    ``enough`` of them; else an empty list (try again)."""
    judged = [
        tx["outcomes"]["robot-2"]
        for tx in air.air_log()
        if tx["sender"] == "robot-1" and tx["type"] == "data" and tx["start_us"] >= model_us
    ]
    judged = [o for o in judged if o in ("delivered", "lost")]
    return judged if len(judged) >= enough else []


def _after_rounds(air, rounds: int, rids=tuple(rl.POSES)) -> dict[int, dict]:
    """Statuses once each of ``rids`` has held the token ``rounds`` more times: every fix is that fresh."""
    held = {rid: air.cmd(rid, "status")["ir"]["rounds_held"] for rid in rids}
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        statuses = {rid: air.cmd(rid, "status") for rid in rids}
        if all(s["ir"]["rounds_held"] >= held[rid] + rounds for rid, s in statuses.items()):
            return statuses
        time.sleep(0.1)
    raise AssertionError({rid: s["ir"] for rid, s in statuses.items()})


def test_ir_faults_from_the_cli_reach_the_hub_with_their_parameters(make_air):
    """What the IR faults do to the robots' fixes is asserted in model time
    (tests/model/test_token.py::test_ir_blinding_and_noise_spoil_the_fixes_until_cleared), on the environment the
    hub runs; here, the command line's path to a running hub, and its clear."""
    air = make_air()
    assert _chaos(air, "ir-blind", "--node", "robot-2").returncode == 0
    assert _chaos(air, "ir-noise", "--node", "robot-3", "--sigma", "150").returncode == 0
    faults = query_hub(air.session, air.keys.chaos)["faults"]
    assert [(f["kind"], f["node"], f.get("sigma")) for f in faults] == [
        ("ir_blind", "robot-2", None),
        ("ir_noise", "robot-3", 150.0),
    ], faults
    assert _chaos(air, "clear").returncode == 0
    assert query_hub(air.session, air.keys.chaos)["faults"] == []
