"""Driving with the user (petswarm/controllers/driving.py) in model time: the scenario files end to end through
``petswarm run SCENARIO --clock model`` (the hub's environment, every robot and the user as the objects their
processes run), and small worlds of the harness.

Every robot drives on its own sensing only: the LF distances its owner's belt reports over BLE, its IR fixes of
the master, the master's DriveState broadcasts, its AHRS and ultrasonic sensors from the environment. Moved from
tests/process/test_driving.py with its bounds; the model-time runs are the same for a seed on any machine.

tests/process/test_lockstep.py runs a shortened following-turn as lockstep processes beside its model-time twin
(equal digests) and asserts the bounds of this file's following-turn test on both.
"""

from __future__ import annotations

import functools
import math
import tomllib
from pathlib import Path
from typing import Any

import pytest

from petswarm.lab.metrics import read_world
from petswarm.scenario import load, parse

from .harness import SCENARIOS, ModelWorld, record_events, run_model_time, run_scenario

pytestmark = pytest.mark.long


def _run(name: str, record: Path, seed: int) -> dict[str, Any]:
    summary = run_scenario(SCENARIOS / f"{name}.toml", seed, record)
    assert summary["ok"], summary["problems"]
    return summary


@functools.lru_cache(maxsize=1)
def _world(record: Path) -> list[dict[str, Any]]:
    """The run's ground truth, parsed once per run (a 48 s run's log is some 2400 ticks; the checks read it often)."""
    return read_world(record / "world.jsonl")


def _track(record: Path, body: str) -> list[dict[str, Any]]:
    return [b for tick in _world(record) for b in tick["bodies"] if b["id"] == body]


def _timed(record: Path, body: str) -> list[tuple[float, dict[str, Any]]]:
    return [(t["t_us"] / 1e6, b) for t in _world(record) for b in t["bodies"] if b["id"] == body]


FORMATION_MEDIAN_BOUND_M = 0.25
"""Documented bound (README, docs/RESULTS.md) on the median formation error of the following-turn scenario:
IR fixes refresh once per token round (about 0.55 s for 4 robots) and the slaves dead-reckon between them."""


@pytest.mark.timeout(300)
def test_a_following_swarm_keeps_its_formation_through_the_turn(tmp_path: Path) -> None:
    """scenarios/following-turn.toml: a column of 4 follows its user 6 m north, round a 90 degree right turn and
    4 m east, within the documented formation bound, and every slave hears the user's rotation and turns."""
    record = tmp_path / "run"
    driving = _run("following-turn", record, seed=5)["driving"]
    assert driving["collisions"] == 0
    assert driving["formation_error_all_m"]["median"] < FORMATION_MEDIAN_BOUND_M, driving["formation_error_all_m"]
    assert set(driving["formation_error_m"]) == {"robot-2", "robot-3", "robot-4"}
    assert 0.8 < driving["user_master_distance_m"]["median"] < 1.3
    [reaction] = driving["reactions"]
    assert reaction["master"] == "robot-1"
    assert all(s is not None for s in reaction["slaves_s"].values()), reaction
    for rid in (2, 3, 4):
        assert any(
            e["kind"] == "user_activity_heard" and e["user_rate"] != 0 for e in record_events(record, f"robot-{rid}")
        )
    # the column's tail came along the walk north and round the turn
    track = _track(record, "robot-4")
    assert track[-1]["y"] - track[0]["y"] > 5.0 and track[-1]["x"] > track[0]["x"], (track[0], track[-1])


@pytest.mark.timeout(300)
def test_leading_the_robot_drives_an_arc_when_the_user_turns(tmp_path: Path) -> None:
    record = tmp_path / "run"
    driving = _run("leading-arcs", record, seed=2)["driving"]
    assert driving["collisions"] == 0
    left, right = driving["reactions"]  # the user turns 90 degrees left, later 90 degrees right
    for turn in (left, right):
        assert turn["master"] == "robot-1" and turn["master_s"] is not None and turn["master_s"] < 1.0, turn
    turn_at = left["user_turn_at_s"]
    timed = _timed(record, "robot-1")
    before = next(b for t, b in timed if t >= turn_at)
    after = next(b for t, b in timed if t >= turn_at + 3.0)
    # an arc: the heading turned with the user and the robot moved sideways round them, not in place
    turned = math.degrees(math.atan2(math.sin(after["yaw"] - before["yaw"]), math.cos(after["yaw"] - before["yaw"])))
    assert 60 < turned < 120, turned
    assert math.hypot(after["x"] - before["x"], after["y"] - before["y"]) > 0.8
    # paired with its owner, then leading on the watch's request
    states = [e for e in record_events(record, "robot-1") if e["kind"] == "state"]
    assert [e["to"] for e in states][:2] == ["command-waiting", "leading"], states


def _bodies_at(record: Path, t: float) -> dict[str, dict[str, Any]]:
    """Every body of the first world tick at or after model time ``t`` (events' ``mono`` is the same clock)."""
    tick = next(tick for tick in _world(record) if tick["t_us"] / 1e6 >= t)
    return {b["id"]: b for b in tick["bodies"]}


def _in_frame(master: dict[str, Any], point: list[float]) -> tuple[float, float]:
    """``point`` (world) in the frame of the master's true pose: x ahead, y to its left."""
    dx, dy = point[0] - master["x"], point[1] - master["y"]
    c, s = math.cos(master["yaw"]), math.sin(master["yaw"])
    return (c * dx + s * dy, -s * dx + c * dy)


def _places(bodies: dict[str, dict[str, Any]], master: int, robots: tuple[int, ...]) -> dict[int, list[float]]:
    """Where each robot belongs in the formation: the master's own position, each slave's reference."""
    return {
        rid: [bodies[f"robot-{rid}"]["x"], bodies[f"robot-{rid}"]["y"]]
        if rid == master
        else bodies[f"robot-{rid}"]["reference"]
        for rid in robots
    }


KEPT_PLACE_M = 0.3
"""Table 3's Change column keeps every robot's place relative to the new master; off by at most the new master's
heading error (a turn-about ends within 10 degrees of its target) over the column's 1.2 m."""


def _kept_places(record: Path, at: float, old_master: int, new_master: int, robots: tuple[int, ...]) -> None:
    """Change column: from just before the request at ``at`` to 5 s later (every robot has turned round by then),
    each slave's reference relative to the new master is where it stood relative to it before."""
    before, after = _bodies_at(record, at - 0.1), _bodies_at(record, at + 5.0)
    assert after[f"robot-{new_master}"]["role"] == "master"
    places = _places(before, old_master, robots)
    anchor_before, anchor_after = places[new_master], [after[f"robot-{new_master}"][k] for k in ("x", "y")]
    for rid in robots:
        if rid == new_master:
            continue
        slave = after[f"robot-{rid}"]
        assert slave["role"] == "slave", rid
        was = [places[rid][k] - anchor_before[k] for k in (0, 1)]
        now = [slave["reference"][k] - anchor_after[k] for k in (0, 1)]
        assert math.dist(was, now) < KEPT_PLACE_M, (rid, was, now)


def _mirrored(record: Path, at: float, master: int, slaves: tuple[int, ...]) -> None:
    """No-change column: the same master; from just before the request at ``at`` to 5 s later (every robot has
    turned round), each slave's slot in the master's frame goes to its other side: x -> -x, y kept."""
    before, after = _bodies_at(record, at - 0.1), _bodies_at(record, at + 5.0)
    assert after[f"robot-{master}"]["role"] == "master"
    for rid in slaves:
        joined = next(e for e in record_events(record, f"robot-{rid}") if e.get("to") == "slave-driving")
        depth = 0.6 * joined["number"]  # a column 0.6 m apart, in member order
        slave_before, slave_after = before[f"robot-{rid}"], after[f"robot-{rid}"]
        assert slave_before["role"] == slave_after["role"] == "slave"
        xb, yb = _in_frame(before[f"robot-{master}"], slave_before["reference"])
        xa, ya = _in_frame(after[f"robot-{master}"], slave_after["reference"])
        assert abs(xb) == pytest.approx(depth, abs=0.01) and xa == pytest.approx(-xb, abs=0.01), (rid, xb, xa)
        assert ya == pytest.approx(yb, abs=0.01)
    assert all(math.sin(after[f"robot-{rid}"]["yaw"]) < -0.9 for rid in (master, *slaves))  # facing south


def _turned_round_and_led_back(record: Path) -> None:
    """Every robot turned round, and the swarm then led the user back south, ahead of him."""
    for rid in (1, 2, 3):
        track = _track(record, f"robot-{rid}")
        assert math.sin(track[0]["yaw"]) > 0.9 and math.sin(track[-1]["yaw"]) < -0.9, rid
    user = _track(record, "user")
    assert user[-1]["y"] < 0.5  # the user walked back south
    assert all(_track(record, f"robot-{rid}")[-1]["y"] < user[-1]["y"] for rid in (1, 2, 3))


@pytest.mark.timeout(300)
def test_turn_about_switches_following_to_leading_with_the_master_per_table_3(tmp_path: Path) -> None:
    """Table 3, following -> leading, No change column: the master stays, the neighbours' references change
    (the slots are mirrored to the master's other side); the slaves follow the new references."""
    record = tmp_path / "run"
    summary = _run("turn-about", record, seed=4)
    assert summary["driving"]["collisions"] == 0
    events = record_events(record, "robot-1")
    [change] = [e for e in events if e["kind"] == "mode_change"]
    assert change["frm"] == "following" and change["to"] == "leading" and change["applied"] == "no-change"
    assert not change["change_master_requested"]
    assert any(e["kind"] == "turn_about_done" for e in events)
    dispersed = next(e for e in events if e["kind"] == "state" and e["frm"] == "master-driving")
    assert dispersed["to"] == "leading"  # dispersed into the mode the user chose
    # the slaves: still slaves of robot 1 (no handover), their references now the mirrored slots
    for rid in (2, 3):
        slave = record_events(record, f"robot-{rid}")
        assert not any(e["kind"] == "handover" for e in slave), rid
        assert [e["to"] for e in slave if e["kind"] == "state"] == ["organizing", "slave-driving", "waiting"], rid
    # the slots in the master's frame, just before the request and once every robot has turned round (the user
    # stands still meanwhile): from behind the master (x < 0) to ahead of it, at the same depth and side
    [done] = [e for e in events if e["kind"] == "turn_about_done"]
    assert done["mono"] < change["mono"] + 5.0
    _mirrored(record, change["mono"], 1, (2, 3))
    after = _bodies_at(record, change["mono"] + 5.0)
    assert all(_in_frame(after["robot-1"], after[f"robot-{r}"]["reference"])[0] > 0.3 for r in (2, 3))  # now ahead
    _turned_round_and_led_back(record)


@pytest.mark.timeout(300)
def test_turn_about_with_a_master_change_hands_the_master_role_to_the_farthest_robot(tmp_path: Path) -> None:
    """Table 3, following -> leading, Change column: the highest in the hierarchy (the robot farthest from the
    user) becomes the master; every robot keeps its place, so the neighbours' references are unchanged."""
    record = tmp_path / "run"
    summary = _run("turn-about-change", record, seed=4)
    assert summary["driving"]["collisions"] == 0
    old = record_events(record, "robot-1")
    # which of robots 2 and 3 is farthest depends on the order they joined the column in (their answers'
    # timing), so it is read from robot 1's estimate, not assumed
    [change] = [e for e in old if e["kind"] == "mode_change"]
    assert change["applied"] == "change" and change["change_master_requested"]
    farthest = int(max(change["distances"], key=change["distances"].get))
    assert farthest in (2, 3)
    other = 5 - farthest
    new = record_events(record, f"robot-{farthest}")
    handed = next(e for e in old if e["kind"] == "state" and e.get("cause") == "handover")
    taken = next(e for e in new if e["kind"] == "state" and e.get("cause") == "handover")
    assert (handed["frm"], handed["to"], handed["master"]) == ("master-driving", "slave-driving", farthest)
    assert (taken["frm"], taken["to"]) == ("slave-driving", "master-driving")
    assert any(e["kind"] == "owner_handed_over" and e["to"] == farthest for e in old)
    # the third robot followed the handover as a slave of the new master
    third = [e for e in record_events(record, f"robot-{other}") if e["kind"] == "handover"]
    assert third and third[0]["to"] == farthest, third
    # every robot kept its place relative to the new master; it leads (farthest from the user), the others
    # follow it, between it and the user
    _kept_places(record, change["mono"], 1, farthest, (1, 2, 3))
    after = _bodies_at(record, change["mono"] + 5.0)
    assert all(_in_frame(after[f"robot-{farthest}"], after[f"robot-{r}"]["reference"])[0] < -0.3 for r in (1, other))
    # the belt re-paired: the new master woke it with its own pattern and tracked the user over LF
    assert any(e["kind"] == "repaired" and e["to"] == f"robot-{farthest}" for e in record_events(record, "user"))
    assert any(e["kind"] == "owner_tracked" for e in new)
    [stop] = [e for e in new if e["kind"] == "stop"]
    assert stop["driving"]["lf_fixes"] > 20, stop  # the new master never had an owner before the handover
    _turned_round_and_led_back(record)
    # dispersal from the new master: both members back to waiting, the new master leading its user
    dispersed = next(e for e in new if e["kind"] == "dispersed")
    assert dispersed["restored"] == "leading" and dispersed["unconfirmed"] == []
    assert sorted(dispersed["members"]) == sorted([1, other])
    for rid in (1, other):
        last = [e for e in record_events(record, f"robot-{rid}") if e["kind"] == "state"][-1]
        assert (last["to"], last.get("reason")) == ("waiting", "dispersed"), rid
    assert [e for e in new if e["kind"] == "state"][-1]["to"] == "leading"


LEADING_TO_FOLLOWING = """
name = "lead-follow"
description = "a leading swarm of 3; the user stops, asks for following mode and turns about, walks back"
duration_s = 27
[user]
owner = 1
start = [0.0, 0.0, 90.0]
walk_at = 11
path = [
  { walk = 2.0, speed = 0.6 },
  { stop = 1.5 },
  { turn = 180, rate = 90 },
  { stop = 3.0 },
  { walk = 2.0, speed = 0.6 },
  { stop = 2.0 },
]
watch = [
  { at = 5.0, request = "lead" },
  { at = 7.0, request = "organize", robots = 2, shape = "column", spacing = 0.6 },
  { at = 15.0, request = "mode", mode = "following", change_master = CHANGE },
  { at = 26.0, request = "disperse" },
]
[robots]
count = 3
positions = [[0.0, 0.8, 90.0], [0.8, 0.3, 90.0], [-0.8, 0.3, 90.0]]
"""


@pytest.mark.timeout(300)
@pytest.mark.parametrize("change_master", [True, False], ids=["change", "no-change"])
def test_leading_to_following_on_a_turn_about_per_table_3(tmp_path: Path, change_master: bool) -> None:
    """Table 3, leading -> following. Change: the robot closest to the user becomes the master, every robot keeps
    its place. No change: the master (the leading robot, farthest from the user) stays, the slots are mirrored.
    Either way the swarm then follows the user back south."""
    scenario = tmp_path / "lead-follow.toml"
    scenario.write_text(LEADING_TO_FOLLOWING.replace("CHANGE", str(change_master).lower()))
    record = tmp_path / "run"
    summary = _run_file(scenario, record)
    assert summary["driving"]["collisions"] == 0
    [change] = [e for e in record_events(record, "robot-1") if e["kind"] == "mode_change"]
    assert (change["frm"], change["to"], change["change_master_requested"]) == ("leading", "following", change_master)
    # robot 1, the user's robot, leads the column: the farthest from the user as it estimates
    assert max(change["distances"], key=change["distances"].get) == "1"
    closest = int(min(change["distances"], key=change["distances"].get))
    if change_master:
        assert change["applied"] == "change" and closest != 1
        master = closest
        taken = next(e for e in record_events(record, f"robot-{master}") if e.get("cause") == "handover")
        assert (taken["frm"], taken["to"]) == ("slave-driving", "master-driving")
        _kept_places(record, change["mono"], 1, master, (1, 2, 3))
        assert any(e["kind"] == "repaired" and e["to"] == f"robot-{master}" for e in record_events(record, "user"))
    else:
        assert change["applied"] == "no-change" and change["table3_master"] == 0
        master = 1
        _mirrored(record, change["mono"], 1, (2, 3))
    # the swarm followed the user back south: everyone moved south and stays behind (north of) him, the master
    # still the one Table 3 chose
    walked_at, end = _bodies_at(record, change["mono"] + 5.0), _bodies_at(record, 25.9)
    user = end["user"]
    assert user["y"] < walked_at["user"]["y"] - 1.5
    for rid in (1, 2, 3):
        robot = end[f"robot-{rid}"]
        assert robot["y"] < walked_at[f"robot-{rid}"]["y"] - 1.0 and robot["y"] > user["y"] + 0.5, rid
        assert robot["role"] == ("master" if rid == master else "slave"), rid


REMOTE = """
name = "remote"
duration_s = 16
[user]
owner = 1
start = [0.0, 0.0, -90.0]
walk_at = 11
path = [{ walk = 1.5, speed = 0.5 }, { stop = 2.0 }]
watch = [
  { at = 4.0, request = "remote" },
  { at = 5.0, gesture = "forward" },
  { at = 8.0, gesture = "up" },
  { at = 14.0, gesture = "circle" },
]
[robots]
count = 1
positions = [[0.0, 0.6, 90.0]]
"""


@pytest.mark.timeout(120)
def test_remote_control_moves_the_robot_by_gestures_only_and_a_circle_cancels(tmp_path: Path) -> None:
    """Remote control: each gesture moves the robot for REMOTE_HOLD_S and then it stops; it does not follow the
    user, who walks away meanwhile; a circle cancels back to command-waiting."""
    scenario = tmp_path / "remote.toml"
    scenario.write_text(REMOTE)
    record = tmp_path / "run"
    _run_file(scenario, record)
    states = [(e["to"], e.get("cause")) for e in record_events(record, "robot-1") if e["kind"] == "state"]
    assert states == [("command-waiting", None), ("remote-control", "watch"), ("command-waiting", "cancel")], states
    timed = _timed(record, "robot-1")

    def pose(at: float) -> dict[str, Any]:
        return next(b for t, b in timed if t >= at)

    # forward at 5 s: 0.3 m/s for 1.5 s along its heading (north), then still
    start, moved, still = pose(4.9), pose(7.0), pose(7.9)
    assert 0.35 < moved["y"] - start["y"] < 0.55 and abs(moved["x"] - start["x"]) < 0.05, (start, moved)
    assert math.hypot(still["x"] - moved["x"], still["y"] - moved["y"]) < 0.01
    # up at 8 s: a quarter turn counter-clockwise in place
    turned = pose(10.5)
    dyaw = math.degrees(math.atan2(math.sin(turned["yaw"] - still["yaw"]), math.cos(turned["yaw"] - still["yaw"])))
    assert 75 < dyaw < 105 and math.hypot(turned["x"] - still["x"], turned["y"] - still["y"]) < 0.05, dyaw
    # the user walked 1.5 m away (south, his back to the robot) from 11 s; the robot stayed where it was
    end, user = pose(15.9), _track(record, "user")[-1]
    assert math.hypot(end["x"] - turned["x"], end["y"] - turned["y"]) < 0.05 and user["y"] < -1.4


def _run_file(scenario: Path, record: Path) -> dict[str, Any]:
    summary = run_scenario(load(scenario), 3, record)
    assert summary["ok"], summary["problems"]
    return summary


def _user(name: str, owner: int, start: tuple[float, float, float]) -> Any:
    """A user standing still at ``start`` holding robot ``owner``'s wake-up pattern."""
    text = f'name = "{name}"\nduration_s = 12\n[user]\nid = "{name}"\nowner = {owner}\nstart = {list(start)}\n'
    plan = parse(tomllib.loads(text)).user
    assert plan is not None
    return plan


def test_another_users_belt_does_not_wake_the_robot() -> None:
    async def body(w: ModelWorld) -> None:
        await w.robot(1, (0.0, 0.0))
        await w.robot(2, (5.0, 0.0))
        # alice holds robot 2's pattern but stands 0.5 m from robot 1; bob holds robot 1's pattern, 4 m away
        alice = w.user(_user("alice", 2, (0.5, 0.0, 180.0)), 30.0)
        w.user(_user("bob", 1, (0.0, 4.0, 0.0)), 30.0)
        await w.advance(7.0)  # two wake-up periods of 3 s
        one, two = w.status(1), w.status(2)
        assert one["state"] == "waiting" and one["driving"]["owner"] is None
        assert one["driving"]["wake_bursts"] >= 2
        assert two["state"] == "waiting" and two["driving"]["owner"] is None  # alice is 4.5 m from robot 2
        assert w.stats()["lf"]["heard"] > 0
        # alice's belt heard robot 1's bursts (a pattern not hers) and stayed asleep
        assert not any(e["kind"] == "owner_reply" for e in alice.events)
        # now alice2 stands by her own robot: it wakes and takes her as its owner within a wake-up period
        w.user(_user("alice2", 2, (5.6, 0.0, 180.0)), 30.0)
        owned = await w.until(lambda: w.status(2)["driving"]["owner"] is not None, 10.0)
        assert owned is not None
        two = w.status(2)
        assert two["driving"]["owner"] == "alice2" and two["state"] == "command-waiting"
        assert w.status(1)["driving"]["owner"] is None

    run_model_time(body)
