"""The surround driver's sans-IO core (petswarm/controllers/surround_core.py) stepped by hand with an explicit
``now``."""

from __future__ import annotations

import asyncio
import math
from typing import Any

import numpy as np
import pytest

from petswarm.controllers.driving_core import Drive, Log, Telemetry
from petswarm.controllers.motion import MotorCommand
from petswarm.controllers.surround_core import BEACON_RETRY_S, TELEMETRY_EVERY, SetIrMode, SurroundCore
from petswarm.controllers.surround_pilot import SurroundDriverConfig
from radio_hub.values import BeaconSweep, OwnSensors

NO_BEACONS = BeaconSweep(0, {}, {})


def sample(t: float) -> OwnSensors:
    angles = np.linspace(0.0, 2 * math.pi, 8, endpoint=False)
    return OwnSensors(int(t * 1e6), np.full(8, math.nan), angles, 0.0, (0.0, 0.0, 0.0))


class StubPilot:
    """Stands in for the pure pilot (its own tests cover the law): sees the human from its second step on."""

    def __init__(self) -> None:
        self.engaged = False
        self.counters = {"beacons": 2}
        self.steps = 0

    def step(self, sensors: OwnSensors, sweep: BeaconSweep, now_s: float) -> tuple[float, float] | None:
        self.steps += 1
        if self.steps < 2:
            return None
        self.engaged = True
        return 0.2, -0.1


def test_beacon_mode_is_asked_once_and_again_0_5_s_after_a_refusal() -> None:
    core = SurroundCore(SurroundDriverConfig(human_id="user"))
    core.start(0.0)
    assert core.actions() == [SetIrMode("beacon")]
    core.start(0.0)
    assert core.actions() == []  # one request at a time
    core.ir_mode_failed("hub away", 0.1)
    assert core.actions() == [Log("error", {"where": "surround_beacon_mode", "error": "hub away"})]
    assert core.next_timer() == 0.1 + BEACON_RETRY_S
    core.handle_timer(0.5)
    assert core.actions() == []
    core.handle_timer(0.6)
    assert core.actions() == [SetIrMode("beacon")] and core.next_timer() is None
    core.ir_mode_set(0.62)
    assert core.actions() == [Log("surround_start", {"human": "user"})] and core.beaconing


def test_samples_before_beacon_mode_are_not_stepped_and_without_the_human_nothing_is_sent() -> None:
    core = SurroundCore(SurroundDriverConfig())
    core.sensors_sample(sample(0.04), NO_BEACONS, 0.04)
    assert core.pilot.counters["steps"] == 0 and core.actions() == []
    core.start(0.04)
    core.ir_mode_set(0.05)
    core.actions()
    for k in range(1, 6):
        core.sensors_sample(sample(0.05 + 0.04 * k), NO_BEACONS, 0.05 + 0.04 * k)
    assert core.actions() == [] and not core.pilot.engaged  # holds still until it first sees its human


def test_an_engaged_robot_drives_every_sample_records_engaging_once_and_tells_viewers_every_12_steps() -> None:
    core = SurroundCore(SurroundDriverConfig())
    core.pilot = StubPilot()  # type: ignore[assignment]
    core.start(0.0)
    core.ir_mode_set(0.0)
    core.actions()
    actions: list[Any] = []
    for k in range(1, 2 + 2 * TELEMETRY_EVERY):
        core.sensors_sample(sample(0.04 * k), NO_BEACONS, 0.04 * k)
        actions += core.actions()
    drives = [a for a in actions if isinstance(a, Drive)]
    assert len(drives) == 2 * TELEMETRY_EVERY and set(drives) == {Drive(MotorCommand(0.2, -0.1, 0.0))}
    assert [a for a in actions if isinstance(a, Log)] == [Log("surround_engaged", {"beacons": 2})]
    assert [a for a in actions if isinstance(a, Telemetry)] == [Telemetry("surround", "", "", None, "surround")] * 2
    assert isinstance(actions[-1], Telemetry)  # after the 24th step's command


class _Radio:
    """The one thing a ``SweepBatch`` reads of a robot's radio: its latest beacon sweep."""

    def __init__(self) -> None:
        self.beacons = NO_BEACONS


def _sweep_of(rng: np.random.Generator, t_us: int, names: list[str]) -> BeaconSweep:
    from radio_hub.physics.light import IrConfig, receiver_gains, strength_at
    from radio_hub.physics.light import sense as light_sense

    config = IrConfig()
    distances = rng.uniform(0.15, 1.5, size=len(names))
    light = strength_at(distances, config)[:, None] * receiver_gains(rng.uniform(0, 2 * math.pi, size=len(names)))
    return BeaconSweep.of_block(t_us, names, light_sense(light, config, rng), [1.0] * len(names))


def test_a_sweep_batch_steps_every_robot_as_its_own_estimate_would() -> None:
    from petswarm.controllers.surround_driver import SweepBatch
    from petswarm.controllers.surround_pilot import SurroundPilot

    rng = np.random.default_rng(4)
    config = SurroundDriverConfig(human_id="user")
    robots = ["robot-1", "robot-2", "robot-3"]
    batched = [SurroundPilot(config) for _ in robots]
    alone = [SurroundPilot(config) for _ in robots]
    radios = [_Radio() for _ in robots]
    batch = SweepBatch()
    for pilot, radio in zip(batched, radios, strict=True):
        batch.join(pilot, radio)
    commands: list[tuple[Any, Any]] = []
    for step in range(1, 30):
        t_us = step * 40_000
        for me, radio in zip(robots, radios, strict=True):  # a lone beacon now and then: estimated alone
            others = [n for n in [*robots, "user"] if n != me][: 1 if step % 7 == 0 else None]
            radio.beacons = _sweep_of(rng, t_us, others)
        for pilot, own, radio in zip(batched, alone, radios, strict=True):
            batch.prepare(pilot, radio.beacons)
            assert pilot.sweep_job(radio.beacons) is None  # given: the step will not estimate it again
            commands.append(
                (
                    pilot.step(sample(t_us / 1e6), radio.beacons, t_us / 1e6),
                    own.step(sample(t_us / 1e6), radio.beacons, t_us / 1e6),
                )
            )
            assert pilot.tracker.names == own.tracker.names
            assert np.array_equal(pilot.tracker.positions, own.tracker.positions)
    assert all(mine == theirs for mine, theirs in commands)
    assert sum(mine is not None for mine, _ in commands) > 60  # the robots saw their human and drove
    batch.leave(batched[0])
    radios[0].beacons = _sweep_of(rng, 30 * 40_000, ["user", "robot-2"])
    batch.prepare(batched[1], radios[1].beacons)
    assert batched[0].sweep_job(radios[0].beacons) is not None  # a robot that left is not estimated for


def test_a_samples_ranges_as_floats_are_its_array_bit_for_bit() -> None:
    # what the pilot reads (OwnSensors.ranges_list, from the wire's bytes) against what it read before
    rng = np.random.default_rng(8)
    special = np.array([np.nan, np.inf, -np.inf, -0.0, 0.0, 1e-45, 3.4e38], dtype="<f4")
    for _ in range(500):
        values = rng.uniform(0.0, 3.0, 8).astype("<f4")
        picks = rng.random(8) < 0.3
        values[picks] = rng.choice(special, int(picks.sum()))
        sensors = OwnSensors.of_wire(0, values.tobytes(), lambda: np.zeros(8), 0.0, (0.0, 0.0, 0.0))
        got = sensors.ranges_list()
        want = OwnSensors.of_wire(0, values.tobytes(), lambda: np.zeros(8), 0.0, (0.0, 0.0, 0.0)).ranges_m.tolist()
        assert np.array(got).tobytes() == np.array(want).tobytes()
        assert sensors.ranges_m.tolist() == got or np.isnan(got).any()  # the array is still there to read


class _StepRadio(_Radio):
    """What ``SurroundTask`` uses of a robot's radio: its sample callbacks and latest sweep."""

    def __init__(self) -> None:
        super().__init__()
        self.on_sensors: list[Any] = []

    def sample_comes(self) -> None:
        for callback in self.on_sensors:
            callback(None)


class _StepDriver:
    """Stands in for a ``SurroundDriver``: notes when it is stepped, fails when told to."""

    def __init__(self, name: str, steps: list[str]) -> None:
        from petswarm.controllers.surround_pilot import SurroundPilot

        self.name, self.steps = name, steps
        self.pilot = SurroundPilot(SurroundDriverConfig())
        self.radio = _StepRadio()
        self.fail = False

    def step(self, sweeps: Any, now: float) -> None:
        self.steps.append(self.name)
        if self.fail:
            raise RuntimeError(f"{self.name} broke")


def test_one_task_steps_every_robot_in_the_order_their_samples_came(monkeypatch: pytest.MonkeyPatch) -> None:
    from petswarm.controllers.surround_driver import SurroundTask

    # the task's own rules, with stand-in drivers stepping one by one (stepped together, the robots' cores go
    # through SurroundCore.sensors_samples: tests/model/test_surround_batch.py)
    monkeypatch.setattr(SurroundTask, "together", False)

    async def scenario() -> tuple[list[list[str]], BaseException | None, bool]:
        steps: list[str] = []
        drivers = [_StepDriver(f"robot-{i}", steps) for i in (1, 2, 3)]
        surround = SurroundTask.of_loop(asyncio.get_running_loop())

        async def robot(driver: _StepDriver) -> None:
            stepped = surround.join(driver)  # type: ignore[arg-type]
            try:
                await stepped
            finally:
                surround.leave(driver)  # type: ignore[arg-type]

        tasks = [asyncio.create_task(robot(d)) for d in drivers]
        await asyncio.sleep(0)
        rounds: list[list[str]] = []

        async def one_round(*order: int) -> None:
            for i in order:
                drivers[i].radio.sample_comes()
            drivers[order[0]].radio.sample_comes()  # twice in a round: one step
            for _ in range(3):
                await asyncio.sleep(0)
            rounds.append(list(steps))
            steps.clear()

        await one_round(2, 0, 1)
        drivers[1].fail = True
        await one_round(0, 1, 2)  # robot 2's error ends its task only
        await one_round(1, 2, 0)
        tasks[2].cancel()  # robot 3 killed: it is not stepped even before its task unwinds
        drivers[2].radio.sample_comes()
        await one_round(0)
        error = tasks[1].exception() if tasks[1].done() else None
        alive = not tasks[0].done()
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        await asyncio.sleep(0)
        return rounds, error, alive and surround._task is not None and surround._task.done()

    rounds, error, ended = asyncio.run(scenario())
    assert rounds == [
        ["robot-3", "robot-1", "robot-2"],
        ["robot-1", "robot-2", "robot-3"],
        ["robot-3", "robot-1"],
        ["robot-1"],
    ]
    assert isinstance(error, RuntimeError) and str(error) == "robot-2 broke"
    assert ended  # robot 1 lived until the end, and the task ended with its last member


def test_the_stepping_task_lets_its_loop_go_and_fails_members_left_when_it_is_cancelled() -> None:
    """A process doing run after run (tests, sweeps) must not keep each run's loop; a stepping task cancelled
    under its members (its loop closing) must not leave their robots waiting for good."""
    from petswarm.controllers.surround_driver import SurroundTask

    async def one_run() -> None:
        driver = _StepDriver("robot-1", [])
        surround = SurroundTask.of_loop(asyncio.get_running_loop())
        stepped = surround.join(driver)  # type: ignore[arg-type]
        driver.radio.sample_comes()
        await asyncio.sleep(0)
        surround.leave(driver)  # type: ignore[arg-type]
        await asyncio.sleep(0)
        await asyncio.sleep(0)
        assert asyncio.get_running_loop() not in SurroundTask._of_loop
        assert not stepped.done()  # left in good order: nothing to fail

    async def cancelled() -> BaseException | None:
        driver = _StepDriver("robot-1", [])
        surround = SurroundTask.of_loop(asyncio.get_running_loop())
        stepped = surround.join(driver)  # type: ignore[arg-type]
        await asyncio.sleep(0)
        assert surround._task is not None
        surround._task.cancel()
        await asyncio.sleep(0)
        await asyncio.sleep(0)
        return stepped.exception() if stepped.done() else None

    for _ in range(3):
        asyncio.run(one_run())
    assert isinstance(asyncio.run(cancelled()), RuntimeError)


def test_a_fault_of_the_shared_step_fails_that_rounds_robots_and_the_task_steps_on(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from petswarm.controllers.surround_driver import SurroundTask

    calls: list[int] = []

    def shared_step(cores: list[Any], samples: list[Any], now: float) -> list[Exception | None]:
        calls.append(len(cores))
        if len(calls) == 1:
            raise RuntimeError("the shared step broke")
        return [None] * len(cores)

    monkeypatch.setattr(SurroundCore, "sensors_samples", staticmethod(shared_step))

    async def scenario() -> tuple[list[BaseException | None], list[bool]]:
        drivers = [_StepDriver(f"robot-{i}", []) for i in (1, 2, 3, 4)]
        for driver in drivers:
            driver.radio.sensors = sample(0.04)  # type: ignore[attr-defined]
            driver.core = SurroundCore(SurroundDriverConfig())  # type: ignore[attr-defined]
        surround = SurroundTask.of_loop(asyncio.get_running_loop())
        futures = [surround.join(d) for d in drivers]  # type: ignore[arg-type]
        for driver in drivers[:2]:  # a round of robots 1 and 2: the shared step fails
            driver.radio.sample_comes()
        for _ in range(3):
            await asyncio.sleep(0)
        for driver in drivers[2:]:  # then a round of robots 3 and 4: it steps them
            driver.radio.sample_comes()
        for _ in range(3):
            await asyncio.sleep(0)
        errors = [f.exception() if f.done() else None for f in futures]
        alive = [not f.done() for f in futures]
        for driver in drivers:
            surround.leave(driver)  # type: ignore[arg-type]
        await asyncio.sleep(0)
        return errors, alive

    errors, alive = asyncio.run(scenario())
    assert [str(e) if e else None for e in errors] == ["the shared step broke"] * 2 + [None, None]
    assert alive == [False, False, True, True] and calls == [2, 2]
