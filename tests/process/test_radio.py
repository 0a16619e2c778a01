"""The emulated radio through real processes: a hub process, robot processes, zenoh on loopback."""

from __future__ import annotations

import time
from functools import partial

import msgpack
import pytest

from petswarm import control
from radio_hub.air.mac import Frame, FrameType
from radio_hub.link import wire
from radio_hub.link.up_keys import wait_for_up_key

from ..waiting import wait_for
from .conftest import LOSSLESS

pytestmark = pytest.mark.process


def _senders(reply: dict) -> set[int]:
    return {r["from"] for r in reply["replies"]}


def test_broadcast_and_unicast_delivery_among_three_robots(make_air):
    air = make_air()
    for rid, x in ((1, 0.0), (2, 1.5), (3, 3.0)):
        air.robot(rid, (x, 0.0))
    broadcast = air.cmd(1, "ping", wait=0.5)
    assert broadcast["tx"]["status"] == "success"
    assert _senders(broadcast) | air.heard(1, {2, 3}, wait=0.5) == {2, 3}  # late replies on a loaded machine: ping on
    filtered_before = air.node(3)["filtered"]
    unicast = air.cmd(1, "ping", dst=2, wait=0.5)
    assert unicast["tx"]["status"] == "success"  # acknowledged by robot 2's MAC
    assert _senders(unicast) | air.heard(1, {2}, dst=2, wait=0.5) == {2}
    assert air.node(3)["filtered"] >= filtered_before + 1  # robot 3 heard it and its MAC dropped it
    assert air.node(2)["acks_sent"] >= 1
    codes = air.close()
    assert set(codes.values()) == {0}, codes  # every process shut down cleanly


def test_two_pans_do_not_hear_each_other_and_a_pan_switch_takes_effect(make_air):
    air = make_air()
    air.robot(1, (0.0, 0.0), pan=0x1000)
    air.robot(2, (1.0, 0.0), pan=0x1000)
    air.robot(3, (2.0, 0.0), pan=0x2000)
    assert air.heard(1, {2}, wait=0.5) == {2}
    assert _senders(air.cmd(3, "ping", wait=0.5)) == set()
    assert all(f["src"] != 1 for f in air.cmd(3, "received")["frames"])

    switched = air.cmd(3, "configure", pan_id=0x1000)
    assert switched["radio"]["pan_id"] == 0x1000
    assert air.node(3)["pan_id"] == 0x1000
    assert air.heard(1, {2, 3}, wait=0.5) == {2, 3}


def test_configure_with_a_bad_channel_is_refused_clearly(make_air):
    air = make_air()
    air.robot(1)
    answer = air.cmd(1, "configure", channel=30)
    assert "RadioError" in answer["error"] and "11-26" in answer["error"]
    assert air.node(1)["channel"] == 11


def _overlap(a: dict, b: dict) -> bool:
    return a["start_us"] < b["end_us"] and b["start_us"] < a["end_us"]


def _data_sent(air) -> list[dict]:
    """Data frames robots 1 and 2 have put on the air, oldest first (the hub keeps the last 4,096)."""
    return [t for t in air.air_log() if t["type"] == "data" and t["sender"] in ("robot-1", "robot-2")]


def _newest_if_both_sent(air, before: list[dict]) -> list[dict]:
    """The newest data frame of each of robots 1 and 2, once each has sent one more than ``before``; else []."""
    now = _data_sent(air)
    newest = {t["sender"]: t for t in now[len(before) :]}
    return sorted(newest.values(), key=lambda t: t["start_us"]) if len(newest) == 2 else []


def test_simultaneous_sends_collide_as_the_model_says(make_air):
    # Without CSMA-CA two robots told to send at once overlap on the air whenever their requests reach
    # the hub within one airtime (about 3.7 ms for these frames).
    air = make_air({**LOSSLESS, "mac": {"csma_enabled": False}})
    air.robot(1, (0.0, 0.0))
    air.robot(2, (2.0, 0.0))
    air.robot(3, (1.0, 0.0))
    overlaps = 0
    for tag in range(1, 11):
        before = _data_sent(air)
        control.broadcast(air.session, air.keys, "send", payload_len=100, ack=False, tag=tag, only=[1, 2])
        # both frames on the air: each robot sends when its process gets the CPU, not within a fixed 0.3 s
        sent = wait_for("robots 1 and 2 sent", partial(_newest_if_both_sent, air, before), 10, every=0.05)
        at_3 = {t["outcomes"]["robot-3"] for t in sent}
        if _overlap(*sent):
            overlaps += 1
            # robot 3 is 1 m from both: it stays on the frame that started first (the later one, no stronger,
            # only interferes) and each sender, transmitting, hears nothing of the other (docs/AIR.md)
            first, later = sorted(sent, key=lambda t: (t["start_us"], t["tx_id"]))
            assert later["outcomes"]["robot-3"] == "collided"
            assert first["outcomes"]["robot-3"] in ("delivered", "collided")
            assert sent[0]["outcomes"]["robot-2" if sent[0]["sender"] == "robot-1" else "robot-1"] == "collided"
        else:
            assert at_3 == {"delivered"}
        if overlaps >= 2:
            break
    assert overlaps >= 1, "no two sends ever overlapped"
    node3 = air.node(3)
    assert node3["heard"] == node3["delivered"] + node3["collided"] + node3["lost"] + node3["filtered"]


def test_malformed_and_oversize_input_from_a_raw_client_is_counted_and_dropped(make_air):
    air = make_air()
    air.robot(1, (0.0, 0.0))
    air.robot(2, (1.0, 0.0))
    session, keys = air.session, air.keys
    replies: list[wire.Message] = []
    sub = session.declare_subscriber(
        keys.down("raw-1"), lambda s: replies.extend(wire.decode_all(s.payload.to_bytes()))
    )
    # a raw client with a liveliness token, as every node has: the hub listens on the up keys of such ids only
    alive = session.liveliness().declare_token(keys.alive("raw-1", "r1"))
    raw = session.declare_publisher(keys.up("raw-1"))
    assert wait_for_up_key(raw)
    for junk in (b"", b"\xc1\xc1", msgpack.packb({"v": 9, "t": "transmit"}), msgpack.packb([1, 2, 3])):
        raw.put(junk)
    session.put(keys.up("robot-1"), b"\xff garbage on a robot's own key")
    attach = wire.Attach(ext_addr=1, short_addr=77, pan_id=0x1000, channel=11, instance="r1", n=1)
    raw.put(attach.encode())
    oversize = Frame(FrameType.DATA, 1, 0x1000, 0xFFFF, 0x1000, 77, bytes(60)).encode() + bytes(70)
    raw.put(wire.Transmit(token=5, psdu=oversize, n=2).encode())
    raw.put(wire.Transmit(token=6, psdu=b"\x41\x88\x01\x00\x10", n=3).encode())
    session.put(control.robot_key(keys, 2), b"not msgpack")
    session.put(control.all_robots_key(keys), b"\x93\x01")
    time.sleep(0.5)
    sub.undeclare()
    raw.undeclare()
    alive.undeclare()

    hub = air.stats()["hub"]
    assert hub["malformed"] == 5
    done = {m.token: m for m in replies if isinstance(m, wire.TxDone)}
    assert done[5].status == "refused" and "127" in done[5].reason
    assert done[6].status == "refused" and "FCS" in done[6].reason
    assert sum(isinstance(m, wire.Error) for m in replies) == 4
    assert air.stats()["nodes"]["raw-1"]["refused"] == 2
    assert not air.sup.dead()
    assert air.heard(1, {2}, wait=0.5) == {2}  # the robots still talk


def test_oversize_payload_from_a_robot_gets_a_clear_error(make_air):
    air = make_air()
    air.robot(1)
    answer = air.cmd(1, "send", payload_len=200)
    assert "FrameError" in answer["error"] and "127" in answer["error"]
    assert air.cmd(1, "status")["robot_id"] == 1


def test_a_killed_robot_is_detached_and_unicast_to_it_gets_no_ack(make_air):
    air = make_air()
    air.robot(1, (0.0, 0.0))
    air.robot(2, (1.0, 0.0))
    air.sup.children["robot-2"].kill()
    deadline = time.monotonic() + 10
    while air.node(2)["attached"] and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not air.node(2)["attached"]
    answer = air.cmd(1, "ping", dst=2, wait=0.2)
    assert answer["tx"]["status"] == "no_ack" and answer["tx"]["retries"] == 3
    assert air.cmd(1, "status")["robot_id"] == 1


def test_robots_started_with_id_auto_claim_distinct_ids(make_air):
    air = make_air()
    for n in range(3):
        air.sup.spawn(f"auto-{n}", ["robot", "--id", "auto", "--hub", air.endpoint, "--world", air.world])
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        attached = sorted(name for name, n in air.stats()["nodes"].items() if n["attached"])
        if len(attached) == 3:
            break
        time.sleep(0.1)
    logs = {f"auto-{n}": air.sup.log_tail(f"auto-{n}") for n in range(3)}
    assert attached == ["robot-1", "robot-2", "robot-3"], logs
    assert not air.sup.dead()
    assert air.stats()["hub"]["detaches"] == 0  # a refused claim did not knock out the robot that holds the id
    assert air.cmd(1, "ping", wait=0.3)["tx"]["status"] == "success"
    assert air.stats()["hub"]["transport_gaps"] == 0  # nor did it disturb robot 1's message numbering


def test_stats_command_shows_every_node_and_channel(make_air):
    import json
    import subprocess
    import sys

    air = make_air()
    air.robot(1, (0.0, 0.0))
    air.robot(2, (1.0, 0.0), 0x2000)
    air.cmd(1, "ping", wait=0.2)
    args = [sys.executable, "-m", "cli", "stats", "--hub", air.endpoint, "--world", air.world]
    table = subprocess.run(args, capture_output=True, text=True, timeout=60)
    assert table.returncode == 0, table.stderr
    assert "robot-1" in table.stdout and "0x2000" in table.stdout and "channel 11" in table.stdout
    raw = json.loads(subprocess.run([*args, "--json"], capture_output=True, text=True, timeout=60).stdout)
    assert raw["nodes"]["robot-1"]["sent"] == 1 and raw["nodes"]["robot-2"]["filtered"] == 1
