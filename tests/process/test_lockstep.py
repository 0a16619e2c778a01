"""Lockstep time over real processes: hub and robot processes on loopback, model time owned by the hub."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from petswarm import control
from petswarm.lab.metrics import read_world
from petswarm.lab.processes import Supervisor, free_tcp_port
from petswarm.lab.records import read_events
from radio_hub.interface import Keys, open_session, query_hub
from radio_hub.link import wire
from radio_hub.link.zenoh_link import reliable_publisher
from radio_hub.values import HubUnavailable

from ..model.test_driving import FORMATION_MEDIAN_BOUND_M
from ..waiting import wait_for
from .procfs import FLOOD_RSS_BOUND_MB, peak_rss_mb

pytestmark = [pytest.mark.process, pytest.mark.long]
ROOT = Path(__file__).resolve().parents[2]


def _run(tmp: Path, clock: str, *extra: str) -> dict:
    argv = [sys.executable, "-m", "cli", "run", "--robots", "4", "--organize", "2", "--duration", "2", "--seed", "5"]
    done = subprocess.run(
        [*argv, *extra, "--clock", clock, "--json", "--record", str(tmp / clock)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
    )
    assert done.stdout, done.stderr[-2000:]
    return _with_exit_codes(json.loads(done.stdout), tmp / clock)


@pytest.fixture(scope="module")
def model_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, Path]:
    """The ideal profile's model-time run (summary and record folder) that two tests compare with: run once."""
    tmp = tmp_path_factory.mktemp("ideal")
    return _run(tmp, "model"), tmp / "model"


@pytest.mark.timeout(400)
def test_robot_processes_in_lockstep_do_exactly_what_the_model_time_run_does(
    tmp_path: Path, model_run: tuple[dict, Path]
) -> None:
    """Four robot processes and a hub over zenoh, the hub granting model time: the record is the model-time
    run's, event for event and frame for frame, whatever the machine's load does to the processes."""
    model, model_record = model_run
    lockstep = _run(tmp_path, "lockstep")
    assert model["ok"] and lockstep["ok"], (model["problems"], lockstep["problems"])
    assert lockstep["clock"] == "lockstep" and lockstep["model_time_s"] == model["model_time_s"]
    assert lockstep["digest"] == model["digest"]
    assert lockstep["organization"]["members"] == model["organization"]["members"]
    # the processes really were separate: each robot reports its own process's memory
    assert all(node["peak_rss_mb"] for node in lockstep["nodes"].values())
    assert set(lockstep["exit_codes"].values()) == {0}, lockstep["exit_codes"]  # every process ended cleanly
    assert lockstep["deaths"] == []  # nodes leaving once model time is over are not deaths
    # the hub's rounds are reported: at least one per instant a node's timer was due over the 2 s
    assert lockstep["lockstep"]["rounds"] > 100 and lockstep["lockstep"]["stale_idles"] == 0
    assert (tmp_path / "lockstep" / "air.pcap").read_bytes() == (model_record / "air.pcap").read_bytes()


@pytest.mark.timeout(400)
def test_the_kim2017_profile_delays_frames_the_same_in_lockstep_processes_as_in_model_time(
    tmp_path: Path, model_run: tuple[dict, Path]
) -> None:
    """The profile's MCU and UART delays are timers of each robot's own loop, drawn from its seed: robot
    processes in lockstep run what the model-time run runs, and the profile really slows the organization."""
    runs = {clock: _run(tmp_path / "kim2017", clock, "--profile", "kim2017") for clock in ("model", "lockstep")}
    model, lockstep = runs["model"], runs["lockstep"]
    assert model["ok"] and lockstep["ok"], (model["problems"], lockstep["problems"])
    assert lockstep["digest"] == model["digest"]
    ideal, _ = model_run
    assert ideal["digest"] != model["digest"]
    # the step deadline alone is 0.5 s under the profile, against 0.1 s ideal
    assert model["organization"]["organize_time_s"] > ideal["organization"]["organize_time_s"] + 0.3


FOLLOWING_TURN_SHORT = """
name = "following-turn-short"
description = "scenarios/following-turn.toml with its walks shortened: 3 m north, 90 degrees right, 4 m east"
duration_s = 25
[user]
owner = 1
start = [0.0, 0.0, 90.0]
walk_at = 11
path = [{ walk = 3.0, speed = 0.8 }, { turn = -90, rate = 60 }, { walk = 4.0, speed = 0.8 }, { stop = 2.0 }]
watch = [
  { at = 5.0, request = "follow" },
  { at = 7.0, request = "organize", robots = 3, shape = "column", spacing = 0.6 },
  { at = 24.0, request = "disperse" },
]
[robots]
count = 4
formation = "column"
positions = [[0.0, -0.8, 90.0], [0.4, -1.5, 90.0], [-0.4, -2.1, 90.0], [0.3, -2.7, 90.0]]
"""
"""The shipped scenario with 5 s less wait before the walk and half its first walk (25 s of model time, not 45):
what is under test here is that robot and user processes in lockstep do what the model-time run does, through
every part of driving (pairing over LF and BLE, organizing, following, the turn). The shipped scenario's
documented bounds are asserted in model time (tests/model/test_driving.py), where the run is the same."""


@pytest.mark.timeout(600)
def test_a_following_swarm_of_robot_processes_keeps_its_formation_through_the_turn(tmp_path: Path) -> None:
    """A following swarm through a turn in model time and as a hub, four robot processes and a user process in
    lockstep: the driving bounds hold, in processes because the run is the model-time run (same digest), not a
    late copy."""
    scenario = tmp_path / "following-turn-short.toml"
    scenario.write_text(FOLLOWING_TURN_SHORT)
    model, lockstep = (_scenario(tmp_path, str(scenario), clock, seed=5) for clock in ("model", "lockstep"))
    assert lockstep["ok"], lockstep["problems"]
    assert lockstep["digest"] == model["digest"]
    driving = lockstep["driving"]
    assert driving["collisions"] == 0
    assert driving["formation_error_all_m"]["median"] < FORMATION_MEDIAN_BOUND_M, driving["formation_error_all_m"]
    assert set(driving["formation_error_m"]) == {"robot-2", "robot-3", "robot-4"}
    # the user's rotation reached every slave: each heard it in the master's broadcast and turned
    [reaction] = driving["reactions"]
    assert reaction["master"] == "robot-1"
    assert all(s is not None for s in reaction["slaves_s"].values()), reaction
    record = tmp_path / "lockstep"
    for rid in (2, 3, 4):
        events = read_events(record / "events" / f"robot-{rid}.jsonl")
        assert any(e["kind"] == "user_activity_heard" and e["user_rate"] != 0 for e in events), rid
    # the swarm really moved with the user: the column's tail came along the 3 m walk north and round the turn
    track = [b for tick in read_world(record / "world.jsonl") for b in tick["bodies"] if b["id"] == "robot-4"]
    assert track[-1]["y"] - track[0]["y"] > 2.5 and track[-1]["x"] > track[0]["x"], (track[0], track[-1])
    processes = {"hub", "user", "robot-1", "robot-2", "robot-3", "robot-4"}
    assert lockstep["exit_codes"] == dict.fromkeys(processes, 0)
    assert all(node["peak_rss_mb"] for node in lockstep["nodes"].values())
    puts = lockstep["lockstep"]
    assert puts["down_puts"] == puts["grants"] < puts["down_messages"]  # a node's round, grant last, in one put
    assert puts["up_puts"] <= puts["grants"] + 2 * 6  # and one back (six nodes: run, user, robots; attach, leave)


def _scenario(tmp: Path, scenario: str, clock: str, seed: int) -> dict:
    argv = [sys.executable, "-m", "cli", "run", scenario, "--seed", str(seed), "--clock", clock, "--json"]
    done = subprocess.run([*argv, "--record", str(tmp / clock)], capture_output=True, text=True, timeout=880, cwd=ROOT)
    assert done.stdout, done.stderr[-2000:]
    return _with_exit_codes(json.loads(done.stdout), tmp / clock)


def _with_exit_codes(summary: dict, record: Path) -> dict:
    """The printed summary, with the processes' exit codes that the record's summary.json adds at the end."""
    return {**summary, "exit_codes": json.loads((record / "summary.json").read_text()).get("exit_codes", {})}


@pytest.mark.timeout(120)
def test_a_node_that_never_comes_does_not_stall_the_start_forever(tmp_path: Path) -> None:
    """A lockstep hub expecting two nodes, and only one robot process: after --start-within seconds model time
    starts without the missing node, which the hub records as gone; the robot present runs on."""
    endpoint, world = f"tcp/127.0.0.1:{free_tcp_port()}", "never-comes"
    sup = Supervisor(tmp_path / "logs")
    lockstep_hub = ["hub", "--listen", endpoint, "--world", world, "--clock", "lockstep", "--expect", "2"]
    sup.spawn("hub", [*lockstep_hub, "--start-within", "3"])
    sup.spawn("robot-1", ["robot", "--id", "1", "--hub", endpoint, "--world", world, "--clock", "lockstep"])
    session = None
    try:
        deadline = time.monotonic() + 60
        lockstep: dict = {}
        while time.monotonic() < deadline:
            time.sleep(0.5)
            try:
                session = session or open_session("client", endpoint)
                lockstep = query_hub(session, Keys(world).stats, timeout=2.0)["lockstep"]
            except HubUnavailable:
                continue
            if lockstep["model_time_s"] > 1.0:
                break
        assert lockstep.get("model_time_s", 0) > 1.0, (lockstep, sup.log_tail("hub"))
        [missing] = lockstep["dead"]
        assert missing["node"] == "missing" and missing["model_time_s"] == 0.0
        assert "1 of 2 expected nodes did not come within 3 s" in missing["why"]
        assert not sup.dead(), {name: sup.log_tail(name) for name in sup.dead()}
    finally:
        if session is not None:
            session.close()
        sup.stop_all()


@pytest.mark.timeout(120)
def test_a_flood_on_a_lockstep_robots_down_key_while_the_hub_withholds_its_grant_is_dropped_not_held(
    tmp_path: Path,
) -> None:
    """A lockstep robot holds the hub's messages until its next grant. With robot 2 stopped (SIGSTOP), the hub
    waits for its idle and grants nobody; a rogue session then puts 2,000 x 100 kB messages on robot 1's down
    key. Robot 1 drops and counts what passes a wall-clock link's bounds instead of holding it all, and once
    robot 2 goes on, model time goes on for both."""
    endpoint, world = f"tcp/127.0.0.1:{free_tcp_port()}", "held-flood"
    keys = Keys(world)
    sup = Supervisor(tmp_path / "logs")
    sup.spawn("hub", ["hub", "--listen", endpoint, "--world", world, "--clock", "lockstep", "--expect", "2"])
    for rid in (1, 2):
        where = ["--hub", endpoint, "--world", world, "--clock", "lockstep", "--ping-interval", "0.1"]
        sup.spawn(f"robot-{rid}", ["robot", "--id", str(rid), "--pos", f"{2.0 * rid},0", *where])
    session = rogue = None
    try:
        session = wait_for(f"a hub at {endpoint}", lambda: open_session("client", endpoint), 30, every=0.2)
        _model_time_past(session, keys, 1.0)
        robot_2 = sup.children["robot-2"].pid
        os.kill(robot_2, signal.SIGSTOP)
        time.sleep(0.5)  # robot 2's grant, if one was on its way, is out: the hub now waits on its idle
        stopped_at = query_hub(session, keys.stats)["lockstep"]["model_time_s"]
        robot_1 = sup.children["robot-1"].pid
        before = peak_rss_mb(robot_1)
        rogue = open_session("client", endpoint)
        down = reliable_publisher(rogue, keys.down("robot-1"))  # blocks rather than drops: every one arrives
        heavy = wire.LfHeard(data=b"\xaa" * 100_000, n=1).encode()
        for _ in range(2000):
            down.put(heavy)
        down.undeclare()
        time.sleep(1.0)
        grown = peak_rss_mb(robot_1) - before
        print(f"robot 1 peak RSS grew {grown:.1f} MB under the flood")
        assert query_hub(session, keys.stats)["lockstep"]["model_time_s"] == stopped_at  # no grant meanwhile
        os.kill(robot_2, signal.SIGCONT)
        _model_time_past(session, keys, stopped_at + 1.0)
        assert grown <= FLOOD_RSS_BOUND_MB, f"robot 1's peak RSS grew {grown:.0f} MB under the flood"
        dropped = control.command(session, keys, 1, "status", 10.0)["radio_dropped"]
        assert dropped["link"] > 0, dropped  # refused, and counted
        assert not sup.dead(), {name: sup.log_tail(name) for name in sup.dead()}
    finally:
        with contextlib.suppress(ProcessLookupError, KeyError):
            os.kill(sup.children["robot-2"].pid, signal.SIGCONT)
        for s in (rogue, session):
            if s is not None:
                s.close()
        sup.stop_all()


def _model_time_past(session: Any, keys: Keys, seconds: float) -> None:
    """Wait (30 s of wall time at most) until the lockstep hub's model time is past ``seconds``."""
    stats = keys.stats
    wait_for(
        f"model time past {seconds} s",
        lambda: query_hub(session, stats, timeout=2.0)["lockstep"]["model_time_s"] > seconds,
        30,
        every=0.2,
    )
