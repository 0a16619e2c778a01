"""A model run's surround robots stepped together (``petswarm/controllers/surround_batch.py``) do, bit for bit, what
each robot stepping alone does: the run's digest, every robot's record and command are the same both ways."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from petswarm.controllers.surround_batch import step_pilots
from petswarm.controllers.surround_driver import SurroundTask
from petswarm.controllers.surround_pilot import SurroundDriverConfig, SurroundPilot
from radio_hub.interface import BeaconSweep, OwnSensors
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
