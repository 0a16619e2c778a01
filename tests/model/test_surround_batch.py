"""A model run's surround robots stepped together (``petswarm/controllers/surround_batch.py``) do, bit for bit, what
each robot stepping alone does: the run's digest, every robot's record and command are the same both ways."""

from __future__ import annotations

import math
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest

from petswarm.controllers.surround import SurroundConfig
from petswarm.controllers.surround_batch import step_pilots
from petswarm.controllers.surround_driver import SurroundTask
from petswarm.controllers.surround_pilot import SurroundDriverConfig, SurroundPilot
from radio_hub.values import BeaconSweep, OwnSensors
from tests.model.harness import SCENARIOS, record_events, run_scenario


@pytest.mark.parametrize(("name", "seed"), [("surround-cylinder", 1), ("surround-corridor", 2)])
def test_a_scenario_gives_one_digest_whether_its_robots_step_together_or_alone(
    name: str, seed: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # 8 s: the swarm gathers, the human walks off and the first robots meet the obstacle's walls
    together = run_scenario(SCENARIOS / f"{name}.toml", seed, tmp_path / "together", duration_s=8.0)
    monkeypatch.setattr(SurroundTask, "together", False)
    alone = run_scenario(SCENARIOS / f"{name}.toml", seed, tmp_path / "alone", duration_s=8.0)
    assert together["ok"] and alone["ok"]
    assert together["digest"] == alone["digest"]
    for robot in ("robot-1", "robot-7", "robot-20"):
        assert record_events(tmp_path / "together", robot) == record_events(tmp_path / "alone", robot)
    engaged = [e for e in record_events(tmp_path / "together", "robot-7") if e["kind"] == "surround_engaged"]
    assert len(engaged) == 1  # it drove: the digest covers the world log, where its commands took it


def _sample(t_us: int, rng: np.random.Generator, ranges: np.ndarray | None = None) -> OwnSensors:
    angles = np.radians(np.arange(8) * 45.0)
    if ranges is None:
        ranges = np.where(rng.random(8) < 0.5, rng.uniform(0.0, 0.6, 8), np.nan)
    return OwnSensors(t_us, ranges, angles, 0.0, (*rng.uniform(-0.8, 0.8, 2).tolist(), 0.0))


def _sweep(t_us: int, rng: np.random.Generator, names: list[str]) -> BeaconSweep:
    from radio_hub.physics.light import IrConfig, receiver_gains, strength_at
    from radio_hub.physics.light import sense as light_sense

    config = IrConfig()
    distances = rng.uniform(0.2, 1.4, size=len(names))
    light = strength_at(distances, config)[:, None] * receiver_gains(rng.uniform(0, 2 * np.pi, size=len(names)))
    return BeaconSweep.of_block(t_us, names, light_sense(light, config, rng), [1.0] * len(names))


def test_pilots_stepped_together_keep_each_ones_numbers_through_odd_samples() -> None:
    """Sweeps that change who is seen, a lost human, stale sweeps, a sample from the past and a negative range:
    each pilot's commands, tracks and counters stay those of its twin stepping alone."""
    rng = np.random.default_rng(11)
    config = SurroundDriverConfig(human_id="user")
    robots = [f"robot-{i}" for i in range(1, 6)]
    together = [SurroundPilot(config) for _ in robots]
    alone = [SurroundPilot(SurroundDriverConfig(human_id="user")) for _ in robots]
    sweeps = {r: BeaconSweep(0, {}, {}) for r in robots}
    for step in range(1, 120):
        t_us = step * 40_000 if step != 60 else 30_000  # step 60: a sample from before the last one
        samples = []
        for i, me in enumerate(robots):
            if step % 9 != i:  # now and then a robot's sweep is late: it steps on its tracks
                others = [n for n in [*robots, "user"] if n != me]
                if step > 40 and i == 2:
                    others = others[: (step % 4) + 1]  # the beacons it sees change from sweep to sweep
                if 70 < step < 80 and i == 1:
                    others = [n for n in others if n != "user"]  # its human out of sight
                sweeps[me] = _sweep(t_us, rng, others) if not 90 < step < 100 or i != 4 else sweeps[me]
            ranges = np.array([0.3, -0.1, *[np.nan] * 6]) if step == 50 and i == 3 else None
            samples.append((_sample(t_us, rng, ranges), sweeps[me]))
        now = t_us / 1e6
        results = step_pilots(together, samples, now)
        for pilot, twin, (sensors, sweep), result in zip(together, alone, samples, results, strict=True):
            try:
                expected = twin.step(sensors, sweep, now)
            except ValueError as err:
                assert isinstance(result, ValueError) and str(result) == str(err)
                continue
            assert result == expected
            assert pilot.tracker.names == twin.tracker.names
            assert pilot.tracker.positions.tobytes() == twin.tracker.positions.tobytes()
            assert pilot.tracker.velocities.tobytes() == twin.tracker.velocities.tobytes()
            assert pilot.counters == twin.counters and pilot.engaged == twin.engaged
            assert pilot.controller._forces == twin.controller._forces
    assert all(p.counters["steps"] > 80 for p in together)  # they drove
    assert together[3].counters["steps"] < together[0].counters["steps"] + 1  # the bad ring's step failed alone


def _bits(value: object) -> object:
    """``value`` with every float as its bytes (the sign of zero and nan's payload count) and every array as its
    dtype, shape and bytes: two equal ``_bits`` are the same numbers bit for bit."""
    if isinstance(value, float):
        return struct.pack("<d", value)
    if isinstance(value, np.ndarray):
        return value.dtype.str, value.shape, np.ascontiguousarray(value).tobytes()
    if isinstance(value, list | tuple):
        return tuple(_bits(v) for v in value)
    if isinstance(value, dict):
        return tuple((k, _bits(v)) for k, v in value.items())
    if isinstance(value, Exception):
        return type(value), str(value)
    return value


def _state(pilot: SurroundPilot) -> object:
    """Everything of ``pilot`` a step may change (the ring's history as its times and ranges)."""
    tracker, controller = pilot.tracker, pilot.controller
    return _bits(
        (
            tracker.names,
            tracker.positions,
            tracker.velocities,
            tracker._since_fix,
            controller._g,
            controller._rate,
            controller._count,
            controller._differenced,
            controller._forces,
            [(t_us, ranges) for t_us, _, ranges in pilot._echoes._history],
            pilot.counters,
            pilot.engaged,
            pilot._command,
            pilot._last_us,
        )
    )


def _step_both(
    together: list[SurroundPilot],
    alone: list[SurroundPilot],
    samples: list[tuple[OwnSensors, BeaconSweep]],
    now: float,
) -> list[object]:
    """``step_pilots`` on ``together`` and each of ``alone`` stepping alone on the same samples: asserts that
    each result and each pilot's state are the same bit for bit; the results."""
    results = step_pilots(together, samples, now)
    for k, (twin, (sensors, sweep)) in enumerate(zip(alone, samples, strict=True)):
        try:
            expected: object = twin.step(sensors, sweep, now)
        except Exception as err:
            expected = err
        assert _bits(results[k]) == _bits(expected), f"robot {k}: {results[k]!r} together, {expected!r} alone"
        assert _state(together[k]) == _state(twin), f"robot {k}: its state"
    return results


_RING = np.radians(np.arange(8) * 45.0)
_NO_ECHO = np.full(8, np.nan)


def _pilots(n: int) -> tuple[list[SurroundPilot], list[SurroundPilot]]:
    return [SurroundPilot(SurroundDriverConfig()) for _ in range(n)], [
        SurroundPilot(SurroundDriverConfig()) for _ in range(n)
    ]


def _fixed_sweep(t_us: int, fixes: dict[str, list[float]], pilots: list[SurroundPilot]) -> BeaconSweep:
    """A sweep whose fixes every one of ``pilots`` is given (``give_fixes``): beacons where the test puts them."""
    sweep = BeaconSweep(t_us, {name: np.zeros(12) for name in fixes}, {})
    for pilot in pilots:
        pilot.give_fixes(sweep, list(fixes), np.array(list(fixes.values()), dtype=float))
    return sweep


def test_a_sample_again_at_the_instant_of_a_failed_step_fails_as_it_does_alone() -> None:
    """A hub whose clock went back steps a robot again at an instant its ring already holds a sample of: its
    ring reads that held sample's ranges (here a negative one), and the safety stage raises, as alone."""
    together, alone = _pilots(3)
    everyone = together + alone
    sweep = _fixed_sweep(40_000, {"user": [0.8, 0.3], "robot-b": [0.5, -0.2]}, everyone)
    odometry = (0.1, 0.0, 0.0)
    _step_both(together, alone, [(OwnSensors(40_000, _NO_ECHO, _RING, 0.0, odometry), sweep)] * 3, 0.04)
    bad = np.array([0.3, -0.1, *[np.nan] * 6])
    samples = [(OwnSensors(80_000, bad, _RING, 0.0, odometry), sweep)]
    samples += [(OwnSensors(80_000, _NO_ECHO, _RING, 0.0, odometry), sweep)] * 2
    assert isinstance(_step_both(together, alone, samples, 0.08)[0], ValueError)  # robot 0's negative range
    samples[0] = (OwnSensors(40_000, _NO_ECHO, _RING, 0.0, odometry), sweep)  # the hub's clock went back
    _step_both(together, alone, samples, 0.12)
    samples[0] = (OwnSensors(80_000, _NO_ECHO, _RING, 0.0, odometry), sweep)  # and on to where it was
    _step_both(together, alone, samples, 0.16)


def test_a_sample_again_at_the_instant_of_another_ring_fails_only_its_robot() -> None:
    """As above, the held sample from a ring of another size (the hub attached the robot again in between):
    alone the robot's safety stage raises; together that must not fail the other robots' steps."""
    together, alone = _pilots(3)
    everyone = together + alone
    sweep = _fixed_sweep(40_000, {"user": [0.8, 0.3], "robot-b": [0.5, -0.2]}, everyone)
    odometry = (0.1, 0.0, 0.0)
    four = np.radians(np.arange(4) * 90.0)
    samples = [(OwnSensors(40_000, np.full(4, 0.5), four, 0.0, odometry), sweep)]
    samples += [(OwnSensors(40_000, _NO_ECHO, _RING, 0.0, odometry), sweep)] * 2
    _step_both(together, alone, samples, 0.04)
    samples = [(OwnSensors(20_000, _NO_ECHO, _RING, 0.0, odometry), sweep)]  # the clock went back
    samples += [(OwnSensors(80_000, _NO_ECHO, _RING, 0.0, odometry), sweep)] * 2
    _step_both(together, alone, samples, 0.08)
    samples = [(OwnSensors(40_000, _NO_ECHO, _RING, 0.0, odometry), sweep)]  # at the 4-sensor sample's instant
    samples += [(OwnSensors(120_000, _NO_ECHO, _RING, 0.0, odometry), sweep)] * 2
    results = _step_both(together, alone, samples, 0.12)
    assert isinstance(results[0], ValueError) and not isinstance(results[1], Exception)


def test_robots_without_an_ultrasonic_ring_step_together_as_alone() -> None:
    """A world whose robots have no ultrasonic sensors (``ultrasonic_angles_deg = []``, which its config takes):
    each robot steps on its beacons alone, and so together."""
    together, alone = _pilots(2)
    sweep = _fixed_sweep(40_000, {"user": [0.8, 0.3], "robot-b": [0.5, -0.2]}, together + alone)
    none = np.zeros(0)
    samples = [(OwnSensors(40_000, none, none, 0.0, (0.1, 0.0, 0.0)), sweep)] * 2
    results = _step_both(together, alone, samples, 0.04)
    assert all(isinstance(r, tuple) for r in results)


def test_a_track_driven_to_infinity_gives_the_command_it_gives_alone() -> None:
    """Odometry the wire takes (finite, -1e308) over a 2 s gap in the hub's clock drives a neighbour's track to
    infinity: alone the law's clip keeps the finite part of a half-nan force (``min(1.0, nan)`` is 1.0), and so
    must the robots' clip together (``np.minimum(1.0, nan)`` is nan)."""
    together, alone = _pilots(2)
    everyone = together + alone
    odometry = (0.1, 0.0, 0.0)
    sweep = _fixed_sweep(40_000, {"user": [0.8, 0.3], "robot-b": [0.5, -0.2]}, everyone)
    _step_both(together, alone, [(OwnSensors(40_000, _NO_ECHO, _RING, 0.0, odometry), sweep)] * 2, 0.04)
    sweep = _fixed_sweep(80_000, {"robot-b": [0.5, -0.2]}, everyone)  # the human out of sight: still driving
    _step_both(together, alone, [(OwnSensors(80_000, _NO_ECHO, _RING, 0.0, odometry), sweep)] * 2, 0.08)
    samples = [(OwnSensors(2_080_000, _NO_ECHO, _RING, 0.0, (-1e308, 0.0, 0.0)), sweep)]
    samples.append((OwnSensors(2_080_000, _NO_ECHO, _RING, 0.0, odometry), sweep))
    with np.errstate(all="ignore"):
        results = _step_both(together, alone, samples, 0.12)
    assert math.isnan(results[0][0]) and results[0][1] == 0.0  # type: ignore[index]


def test_pilots_of_configs_equal_but_for_the_sign_of_zero_keep_each_ones_forces() -> None:
    """``SurroundDriverConfig`` equality takes -0.0 for 0.0, but a law of ``surround_force = -0.0`` gives f_G of -0.0
    where 0.0 gives 0.0: a pilot stepped with another's config must not get that one's signs."""
    zero, negative = SurroundConfig(surround_force=0.0), SurroundConfig(surround_force=-0.0)
    configs = [SurroundDriverConfig(law=negative), SurroundDriverConfig(law=zero)]
    assert configs[0] == configs[1]
    together = [SurroundPilot(c) for c in configs]
    alone = [SurroundPilot(c) for c in configs]
    sweep = _fixed_sweep(40_000, {"user": [0.8, 0.3]}, together + alone)
    _step_both(together, alone, [(OwnSensors(40_000, _NO_ECHO, _RING, 0.0, (0.0, 0.0, 0.0)), sweep)] * 2, 0.04)


def test_an_overflow_in_one_robots_safety_stage_fails_only_that_robot() -> None:
    """A hub's absurd odometry (1e150 m/s, finite, so the wire takes it) on a ring with two sensors 1e-5 degrees
    apart: the safety stage's corner of their limits overflows ``** 2`` (OverflowError). Alone it fails that
    robot's step; together the others must still step, as each would alone."""
    together, alone = _pilots(2)
    ring = np.radians([0.0, 1e-5, 90.0, 135.0, 180.0, -135.0, -90.0, -45.0])
    sweep = _fixed_sweep(40_000, {"user": [0.8, 0.3]}, together + alone)
    before = np.array([np.nan, 0.5, *[np.nan] * 6])
    for step in range(1, 6):  # 0.2 s of ring history: the echoes' receding speeds are known
        samples = [(OwnSensors(step * 40_000, before, ring, 0.0, (0.1, 0.0, 0.0)), sweep)] * 2
        _step_both(together, alone, samples, step * 0.04)
    sweep = BeaconSweep(240_000, {}, {})  # nothing seen: the tracks go (and do not run off to infinity)
    after = np.array([0.05, 0.5, *[np.nan] * 6])  # an echo ahead, new: the command is over its limit
    samples = [(OwnSensors(240_000, after, ring, 0.0, (1e150, 0.0, 0.0)), sweep)]
    samples.append((OwnSensors(240_000, before, ring, 0.0, (0.1, 0.0, 0.0)), sweep))
    results = _step_both(together, alone, samples, 0.24)
    assert isinstance(results[0], OverflowError) and isinstance(results[1], tuple)


def test_an_infinite_range_steps_together_without_a_warning_a_robot_alone_never_gives() -> None:
    """A range of +inf (float32 on the wire: a hub may send it) is no echo to a robot alone, in plain floats and
    silent; together numpy must not warn of it either (0 * inf in the echo's point, inf - inf in its rate): under
    ``-W error`` a warning is an exception, and it would fail every robot of the batch."""
    together, alone = _pilots(2)
    sweep = _fixed_sweep(40_000, {"user": [0.8, 0.3]}, together + alone)
    ranges = np.array([np.inf, 0.5, *[np.nan] * 6])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for step in range(1, 6):
            samples = [(OwnSensors(step * 40_000, ranges, _RING, 0.0, (0.1, 0.0, 0.0)), sweep)] * 2
            results = _step_both(together, alone, samples, step * 0.04)
            assert all(isinstance(r, tuple) for r in results)
