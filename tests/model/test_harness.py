"""The model-time harness itself: a run is a function of its seed (so a bound asserted in tests/model holds on
every machine), and a robot's end (kill, stop) ends everything it had started."""

from __future__ import annotations

import asyncio
from typing import Any

from .harness import LOSSLESS, ModelWorld, run_model_time

POSITIONS = {1: (0.0, 0.0), 2: (1.0, 0.0), 3: (0.0, 1.0), 4: (1.0, 1.0)}


async def _swarm_for_two_seconds(w: ModelWorld) -> dict[int, list[dict[str, Any]]]:
    for rid, pos in POSITIONS.items():
        await w.robot(rid, pos, user=1 if rid == 1 else 0, ping_interval=0.5)
    await w.command(1, "organize", count=3)
    await w.advance(2.0)  # rosters, token rounds, IR fixes, pings
    return {rid: list(w[rid].log.events) for rid in POSITIONS}


def test_the_same_seed_gives_the_same_run_and_another_seed_another() -> None:
    first = run_model_time(_swarm_for_two_seconds, config=LOSSLESS, seed=3)
    again = run_model_time(_swarm_for_two_seconds, config=LOSSLESS, seed=3)
    other = run_model_time(_swarm_for_two_seconds, seed=4)
    # a busy two seconds: the swarm formed and IR fixes were taken (with the default noise, drawn from the seed)
    assert any(e["kind"] == "ir_fix" for events in first.values() for e in events)
    assert any(e["kind"] == "organized" for e in first[1])
    assert first == again  # every event of every robot, with its model time
    assert first != other


def test_a_killed_robot_leaves_no_task_behind_and_a_stopped_one_records_its_end() -> None:
    async def body(w: ModelWorld) -> None:
        for rid, pos in POSITIONS.items():
            await w.robot(rid, pos, user=1 if rid == 1 else 0)
        await w.command(1, "organize", count=3)
        await w.advance(1.0)
        master = w.running[1]
        assert master.tasks  # its loops, and the rosters and token rounds organizing started
        await w.kill(1)
        assert all(task.done() for task in master.tasks)
        assert master.task is not None and master.task.cancelled()
        events = len(w.events(1))
        await w.advance(1.0)
        assert len(w.events(1)) == events and master.tasks == set()  # dead: nothing more happens in it
        assert not w.stats()["nodes"]["robot-1"]["attached"]
        await w.stop(2)
        assert w.events(2)[-1]["kind"] == "stop"
        await w.advance(0.01)
        assert w.running[2].tasks == set()  # its leftover tasks (rosters, rounds) ended with it

    run_model_time(body, config=LOSSLESS)


def test_sensor_and_motor_messages_are_handed_over_in_memory_and_checked_as_their_bytes_would_be() -> None:
    import math

    from radio_hub.link import wire

    async def body(w: ModelWorld) -> None:
        await w.robot(1, (0.0, 0.0))
        await w.advance(0.2)
        radio = w[1].rf.radio
        assert w.air.coordinator.takes_messages and radio.sensors is not None  # samples came, without bytes
        seen, malformed = radio.sensors, radio.malformed
        bad = wire.Sensors(t_us=seen.t_us + 1, ranges=b"", yaw=math.nan, odometry=[0.0, 0.0, 0.0], n=10_000)
        radio._on_down(bad)  # as the memory link hands a message over
        assert radio.malformed == malformed + 1 and radio.sensors is seen  # dropped, as ...
        with_bytes = wire.Sensors(t_us=seen.t_us + 1, ranges=b"", yaw=1e300 * 10, odometry=[0.0, 0.0, 0.0]).encode()
        radio._on_down(with_bytes)
        assert radio.malformed == malformed + 2 and radio.sensors is seen  # ... its bytes are
        # and up: a motor command goes to the environment as it is, checked as its bytes would be
        hub = w.air.env.counters
        refused = hub.malformed
        radio.drive(0.1, 0.0, 0.0)
        radio.drive(math.nan, 0.0, 0.0)
        await w.advance(0.04)
        assert hub.malformed == refused + 1

    run_model_time(body, config=LOSSLESS, seed=1)


def test_the_environments_own_sensor_messages_reach_a_radio_without_the_check_its_bytes_would_need() -> None:
    from radio_hub.link import wire

    async def body(w: ModelWorld) -> None:
        await w.robot(1, (0.0, 0.0))
        radio = w[1].rf.radio
        checked: list[str] = []
        real_check = wire.check

        def counting(msg: wire.Message) -> wire.Message:
            checked.append(msg.TYPE)
            return real_check(msg)

        wire.check = counting  # type: ignore[assignment]
        try:
            await w.advance(0.2)
        finally:
            wire.check = real_check  # type: ignore[assignment]
        assert radio.sensors is not None and radio.malformed == 0
        assert "sensors" not in checked  # built by the environment in this process: past the check
        assert "drive" in checked  # what a node hands up is still checked

    run_model_time(body, config=LOSSLESS, seed=1)


def test_a_nodes_messages_of_a_round_come_in_order_and_one_that_fails_does_not_stop_the_next() -> None:
    async def deliver(w: ModelWorld) -> tuple[list[str], list[dict[str, Any]]]:
        loop = asyncio.get_running_loop()
        errors: list[dict[str, Any]] = []
        loop.set_exception_handler(lambda _loop, context: errors.append(context))
        heard: list[str] = []

        def on_down(data: Any) -> None:
            heard.append(data)
            if data == "bad":
                raise ValueError("a handler failed")

        w.air.opened("probe", on_down)
        w.air.coordinator.send("probe", b"one")  # type: ignore[arg-type]
        w.air.coordinator.send("probe", "bad")  # type: ignore[arg-type]
        w.air.coordinator.send("probe", b"two")  # type: ignore[arg-type]
        await w.advance(0.01)
        return heard, errors

    heard, errors = run_model_time(deliver, config=LOSSLESS, seed=1)
    assert heard == [b"one", "bad", b"two"]
    assert [type(e["exception"]) for e in errors] == [ValueError]


def test_a_finite_but_huge_drive_is_refused_and_the_body_and_its_sensors_stay_finite() -> None:
    """A finite but huge motor command (1.5e308 m/s) overflowed the world's rotation of it (inf, then nan once
    clipped): the body's truth was nan from then on and its Sensors were dropped as malformed for good. The world
    now refuses a command beyond ``MAX_RATE`` as it refuses a nan one: counted, answered with an error, and the
    robot's own next command drives it on."""
    import math

    async def body(w: ModelWorld) -> tuple[int, int, int, bool]:
        await w.robot(1, (0.0, 0.0), heading_deg=45.0)
        await w.advance(0.2)
        radio = w[1].rf.radio
        malformed, refused = radio.malformed, w.air.env.counters.config_errors
        for _ in range(10):  # the robot's own commands come too: one of these is the last before a tick
            radio.drive(1.5e308, -1.5e308, 0.0)
            await w.advance(0.01)
        await w.advance(0.2)
        truth = w.air.env.world.bodies["robot-1"].velocity
        odometry = radio.sensors.odometry if radio.sensors is not None else (math.nan,)
        refused = w.air.env.counters.config_errors - refused
        return (
            radio.malformed - malformed,
            refused,
            sum(math.isnan(v) for v in truth),
            all(map(math.isfinite, odometry)),
        )

    dropped, refused, nan_in_truth, finite_odometry = run_model_time(body, config=LOSSLESS, seed=1)
    assert refused == 10 and not nan_in_truth
    assert dropped == 0 and finite_odometry  # every sample since came, and was taken
