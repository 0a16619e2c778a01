"""The robot runtime (petswarm/robot.py) in model time: pings and pongs counted on both sides, control commands
that are wrong answered with an error while the robot keeps serving, and the ends of a robot (stop, kill)."""

from __future__ import annotations

from typing import Any

import pytest

from petswarm.robot import DEFAULT_PAN
from radio_hub.values import BROADCAST, MediumConfig

from .harness import LOSSLESS, ModelWorld, run_model_time

CORNERS = {1: (0.0, 0.0), 2: (1.0, 0.0), 3: (0.0, 1.0), 4: (1.0, 1.0)}


async def _robots(w: ModelWorld, **config: Any) -> None:
    for rid, pos in CORNERS.items():
        await w.robot(rid, pos, **config)


def test_a_broadcast_ping_is_answered_by_every_robot_and_counted_on_both_sides() -> None:
    async def body(w: ModelWorld) -> None:
        await _robots(w)
        answer = await w.command(1, "ping", dst=BROADCAST, wait=0.5)
        assert answer["tx"]["status"] == "success"
        assert sorted(r["from"] for r in answer["replies"]) == [2, 3, 4]
        # a round trip is at least two frames' airtime (a ping and a pong of ~20 bytes: ~1 ms each) and came
        # back within the wait
        assert all(2.0 < r["rtt_ms"] < 500.0 for r in answer["replies"]), answer
        assert w.status(1)["pings_sent"] == 1 and w.status(1)["heard_from"] == {2: 1, 3: 1, 4: 1}
        assert [w.status(rid)["pings_answered"] for rid in (2, 3, 4)] == [1, 1, 1]
        # a ping to one robot is answered by that robot only
        unicast = await w.command(1, "ping", dst=3, wait=0.5)
        assert [r["from"] for r in unicast["replies"]] == [3]
        assert w.status(1)["heard_from"] == {2: 1, 3: 2, 4: 1}
        assert [w.status(rid)["pings_answered"] for rid in (2, 3, 4)] == [1, 2, 1]

    run_model_time(body, config=LOSSLESS)


@pytest.mark.parametrize(
    ("fault", "delay_ms"), [({"link": ["robot-1", "robot-2"]}, 60.0), ({"node": "robot-2"}, 120.0)]
)
def test_a_delay_lengthens_the_round_trip_by_exactly_the_delay_on_its_path(fault: dict, delay_ms: float) -> None:
    """Moved from tests/process/test_chaos.py, whose wall-clock round trips carried the machine's load (a base
    measured late made a 60 ms delay look like 54 ms). A round trip also carries two random CSMA backoffs (the
    ping's and the pong's, on an idle channel one attempt each at the MAC's minimum exponent): against the same
    seed's world without the fault it differs by the delay on the path (one way on the link, both ways through
    robot 2), give or take those two backoffs, and by nothing the machine does."""

    def round_trip(delayed: bool) -> float:
        rtts: list[float] = []

        async def body(w: ModelWorld) -> None:
            await w.robot(1, CORNERS[1])
            await w.robot(2, CORNERS[2])
            if delayed:
                w.fault("delay", ms=60, **fault)
            answer = await w.command(1, "ping", dst=2, wait=0.5)
            assert answer["tx"]["status"] == "success"  # the ACK keeps the air's timing
            rtts.extend(r["rtt_ms"] for r in answer["replies"])

        run_model_time(body, config=LOSSLESS, seed=3)
        [rtt] = rtts
        return rtt

    mac = MediumConfig().mac
    backoffs_ms = 2 * (2**mac.min_be - 1) * mac.unit_backoff_us / 1000
    assert abs(round_trip(delayed=True) - round_trip(delayed=False) - delay_ms) <= backoffs_ms


def test_a_pong_lost_on_its_way_back_is_not_counted_as_answered() -> None:
    async def body(w: ModelWorld) -> None:
        await _robots(w)
        w.fault("loss", p=1.0, link=["robot-2", "robot-1"])  # robot 2's frames never reach robot 1
        assert (await w.command(1, "ping", dst=2, wait=0.5))["replies"] == []
        two = w.status(2)
        # it heard the ping (once per MAC attempt of robot 1, whose ACKs were lost too) and answered every copy;
        # no pong was acknowledged, so none counts as an answered ping
        assert two["heard_from"] == {} and two["messages_received"] >= 1
        assert two["tx_results"] == {"no_ack": two["messages_received"]} and two["pings_answered"] == 0, two
        # the same exchange with robot 3, whose frames do arrive, counts on both sides
        assert [r["from"] for r in (await w.command(1, "ping", dst=3, wait=0.5))["replies"]] == [3]
        assert w.status(3)["pings_answered"] == 1 and w.status(3)["tx_results"] == {"success": 1}
        assert w.status(1)["heard_from"] == {3: 1} and w.status(1)["pings_sent"] == 2

    run_model_time(body, config=LOSSLESS)


def test_robots_pinging_on_their_own_hear_every_other_robot() -> None:
    interval, seconds = 0.5, 6.0

    async def body(w: ModelWorld) -> None:
        await _robots(w, ping_interval=interval)
        await w.advance(seconds)
        statuses = {rid: w.status(rid) for rid in CORNERS}
        for rid, s in statuses.items():
            assert set(s["heard_from"]) == set(CORNERS) - {rid}, (rid, s["heard_from"])
            # the pauses are uniform in 0.5-1.5 intervals after a first one of up to an interval
            assert seconds / (1.5 * interval) - 1 <= s["pings_sent"] <= seconds / (0.5 * interval), s["pings_sent"]
        # an acknowledged pong was received by its pinger (an ACK answers a received frame), not always conversely
        heard = sum(sum(s["heard_from"].values()) for s in statuses.values())
        answered = sum(s["pings_answered"] for s in statuses.values())
        assert 0 < answered <= heard

    run_model_time(body, config=LOSSLESS)


WRONG_COMMANDS = [
    ("fly", {}, "unknown command 'fly'"),
    ("organize", {"count": "many"}, "ValueError"),
    ("organize", {"count": 0}, "FormationError: a swarm has 1 to"),
    ("organize", {"count": 2}, "only a robot driving with its user can organize"),
    ("disperse", {}, "not the master of a swarm"),
    ("ping", {"dst": "everyone"}, "ValueError"),
    ("ping", {"wait": None}, "TypeError"),
    ("send", {"payload_len": 500}, "FrameError"),
    ("send", {"only": 5}, "TypeError"),
    ("configure", {"pan_id": "x"}, "ValueError"),
    ("configure", {"channel": 99}, "RadioError"),
    ("connect", {"mode": "swim"}, "ValueError: need user >= 1"),
    ("connect", {"user": 0}, "ValueError: need user >= 1"),
]


WRONG_IDS = [f"{cmd}-{'-'.join(args)}" for cmd, args, _ in WRONG_COMMANDS]


@pytest.mark.parametrize(("cmd", "args", "error"), WRONG_COMMANDS, ids=WRONG_IDS)
def test_a_wrong_control_command_is_answered_with_an_error_and_the_robot_keeps_serving(
    cmd: str, args: dict[str, Any], error: str
) -> None:
    async def body(w: ModelWorld) -> None:
        await w.robot(1, (0.0, 0.0))
        await w.robot(2, (1.0, 0.0))
        before = w.status(1)
        answer = await w.command(1, cmd, **args)
        assert error in answer.get("error", ""), answer
        # nothing changed and nothing stopped: same state and radio, the robot's tasks run, it answers pings
        after = w.status(1)
        assert (after["state"], after["radio"]) == (before["state"], before["radio"])
        assert after["radio"]["pan_id"] == DEFAULT_PAN and after["radio"]["channel"] == 11
        assert not w.running[1].task.done()
        assert [r["from"] for r in (await w.command(2, "ping", dst=1, wait=0.2))["replies"]] == [1]

    run_model_time(body, config=LOSSLESS)


def test_a_command_without_a_name_is_an_unknown_command() -> None:
    async def body(w: ModelWorld) -> None:
        robot = await w.robot(1, (0.0, 0.0))
        assert (await robot.handle({"count": 3}))["error"].startswith("unknown command None")

    run_model_time(body, config=LOSSLESS)


def test_the_stop_command_ends_the_robot_and_a_killed_robot_goes_silent_at_once() -> None:
    async def body(w: ModelWorld) -> None:
        await _robots(w)
        assert await w.command(4, "stop") == {"stopping": True}
        await w.advance(0.1)
        assert w.running[4].task.done() and w.running[4].task.exception() is None
        await w.kill(3)
        assert w.events(3)[-1]["kind"] != "stop"  # a killed process writes no last event
        assert not w.stats()["nodes"]["robot-3"]["attached"]  # the hub forgot it, as when its liveliness ends
        answer = await w.command(1, "ping", wait=0.5)
        assert [r["from"] for r in answer["replies"]] == [2]  # robot 4 no longer serves its radio either

    run_model_time(body, config=LOSSLESS)
