"""Many surround pilots' steps at one instant, as one set of array operations: a model-time run's robots.

In model time every surround robot of a run steps at the same instants (the hub's 25 Hz body-sensor samples),
and twenty pilots each doing a few hundred small float operations per step cost most of the run. Here their
steps go through numpy together: the tracker (``BeaconTracker.predict_all``/``update_all``), the sensing
(``surround_sensing.sense_all``), the paper's law (``SurroundController.step_all``) and the ring's safety stage
(``EchoRanges.floats_all``, ``SafetyStage.translation_all``).

The rule that keeps one digest: each robot's numbers are, bit for bit, what its own ``SurroundPilot.step`` gives
(a lockstep run steps each robot alone, in its own process). So every batched stage does the single robot's
IEEE operations in the single robot's order, elementwise across robots; a sum runs in order from its first term
(``np.add.accumulate``, never numpy's pairwise ``sum``); functions whose libm and numpy versions may round
differently (``math.hypot``, ``np.dot``) are left to the single robot's own code; and anything out of the
ordinary (another law, a filter, a bad sample, a sweep that changes the tracked beacons) goes the single
robot's way. ``tests/model/test_surround_batch.py`` holds the two equal.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from petswarm.controllers.driving_core import EchoRanges
from petswarm.controllers.pet_controller import SafetyStage
from petswarm.controllers.surround import SurroundController
from petswarm.controllers.surround_pilot import SENSOR_PERIOD_S, SurroundPilot
from petswarm.controllers.surround_sensing import BeaconTracker, sense_all
from radio_hub.values import BeaconSweep, OwnSensors, lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

Result = tuple[float, float] | Exception | None
"""A pilot's step: its command, None for none, or the error its step raised."""


def step_pilots(
    pilots: list[SurroundPilot], samples: list[tuple[OwnSensors, BeaconSweep]], now_s: float
) -> list[Result]:
    """``SurroundPilot.step`` of many pilots on their samples at one instant, each bit for bit as its own step:
    pilots of the paper's law with ordinary samples go together (``step_together``); the rest, and a lone one,
    step alone. A pilot's error is its result: the others still step, as each robot's own step would."""
    ring = len(samples[0][0].angles_rad) if samples else 0
    config = pilots[0].config if pilots else None
    together = [
        i
        for i, (pilot, (sensors, _)) in enumerate(zip(pilots, samples, strict=True))
        if config is not None and pilot.batchable(sensors, config, ring)
    ]
    ranges = [samples[i][0].ranges_list() for i in together]
    # a ring that reads as no ring does (a negative range) fails alone; the others go on together
    keep = [k for k, r in enumerate(ranges) if len(r) == ring and not any(x < 0 for x in r)]
    together, ranges = [together[k] for k in keep], [ranges[k] for k in keep]
    if len(together) < 2:
        together, ranges = [], []
    results: list[Result] = [None] * len(pilots)
    chosen = set(together)
    for i, (pilot, (sensors, sweep)) in enumerate(zip(pilots, samples, strict=True)):
        if i not in chosen:
            results[i] = _step_alone(pilot, sensors, sweep, now_s)
    if together:
        stepped = step_together([pilots[i] for i in together], [samples[i] for i in together], ranges, now_s)
        for i, result in zip(together, stepped, strict=True):
            results[i] = result
    return results


def _step_alone(pilot: SurroundPilot, sensors: OwnSensors, sweep: BeaconSweep, now_s: float) -> Result:
    """``pilot.step``, its error as its result."""
    try:
        return pilot.step(sensors, sweep, now_s)
    except Exception as err:  # one robot's bad sample fails that robot's step only
        return err


def step_together(
    pilots: list[SurroundPilot], samples: list[tuple[OwnSensors, BeaconSweep]], ranges: list[list[float]], now_s: float
) -> list[Result]:
    """``SurroundPilot.step`` of each pilot (the paper's law, one config, rings of one size and no negative
    range, checked by ``step_pilots``) on its sample and sweep, all at once; ``ranges``: each
    sample's ``ranges_list()``."""
    results: list[Result] = [None] * len(pilots)
    live, dts, own = _track(pilots, samples, now_s, results)
    if live:
        # the sensing, law and ring stages redo plain-float code, which never warns (inf - inf is nan, silently):
        # their numpy must not either (under -W error a warning would fail every robot of the batch)
        with np.errstate(all="ignore"):
            _drive(pilots, samples, ranges, live, dts, own, results)
    return results


def _drive(
    pilots: list[SurroundPilot],
    samples: list[tuple[OwnSensors, BeaconSweep]],
    ranges: list[list[float]],
    live: list[int],
    dts: list[float],
    own: np.ndarray,
    results: list[Result],
) -> None:
    """``SurroundPilot._drive`` of the pilots ``live`` (their time steps ``dts`` and own velocities ``own``):
    each one's command, or error, in ``results``."""
    chosen = [pilots[i] for i in live]
    sensors = [samples[i][0] for i in live]
    ranges = [ranges[i] for i in live]
    ring = np.array([p._ring(s.angles_rad) for p, s in zip(chosen, sensors, strict=True)]).transpose(1, 0, 2)
    human_id = chosen[0].config.human_id
    sensed = sense_all([p.tracker for p in chosen], np.array(ranges), ring, human_id, chosen[0]._sensing)
    seen = sensed.human_seen.tolist()
    # a robot drives from the first step that sees its human on (the rest of its step is skipped until then)
    driving = [k for k, pilot in enumerate(chosen) if pilot.engaged or seen[k]]
    if not driving:
        return
    rows = np.array(driving)
    commands = SurroundController.step_all(
        [chosen[k].controller for k in driving],  # type: ignore[misc]  # the paper's law: batchable
        sensed.terms[rows],
        sensed.neighbours[rows],
        sensed.count[rows],
        sensed.human[rows],
        sensed.human_seen[rows],
        own[rows],
        np.array(dts)[rows],
    )
    angles, latest, receding, known = EchoRanges.floats_all(
        [chosen[k]._echoes for k in driving], [sensors[k] for k in driving], [ranges[k] for k in driving]
    )
    safe = SafetyStage.translation_all([chosen[k]._safety for k in driving], commands, angles, latest, receding, known)
    for k, command in zip(driving, safe, strict=True):
        pilot = chosen[k]
        pilot.engaged = True
        if isinstance(command, Exception):  # its safety stage raised, as in its own step: engaged, no command
            results[live[k]] = command
            continue
        pilot._command = command
        counters = pilot.counters
        counters["steps"] += 1
        counters["human_seen"] += seen[k]
        counters["echoes_dropped"] += sensed.dropped[k]
        counters["beacons"] = len(pilot.tracker._names)
        results[live[k]] = command


def _track(
    pilots: list[SurroundPilot], samples: list[tuple[OwnSensors, BeaconSweep]], now_s: float, results: list[Result]
) -> tuple[list[int], list[float], np.ndarray]:
    """``SurroundPilot.step``'s time step and ``_track`` of each pilot: the pilots that step on (their
    indices, time steps and own velocities (n, 2)); a sample from before the last one steps no further, and a
    sweep that fails its estimate fails its robot's step (``results``)."""
    live, dts = [], []
    for i, (pilot, (sensors, _)) in enumerate(zip(pilots, samples, strict=True)):
        last = pilot._last_us
        dt = SENSOR_PERIOD_S if last is None else (sensors.t_us - last) / 1e6
        pilot._last_us = sensors.t_us
        if dt > 0:
            live.append(i)
            dts.append(dt)
    if not live:
        return [], [], np.zeros((0, 2))
    own = np.array([samples[i][0].odometry[:2] for i in live], dtype=float)
    BeaconTracker.predict_all([pilots[i].tracker for i in live], own, dts)
    kept, updating, fixes = [], [], []
    for k, i in enumerate(live):
        try:
            new = pilots[i]._new_fixes(samples[i][1], now_s)
        except Exception as err:  # this robot's sweep: its step fails, as alone
            results[i] = err
            continue
        kept.append(k)
        if new is not None:
            updating.append(k)
            fixes.append(new)
    if updating:
        BeaconTracker.update_all([pilots[live[k]].tracker for k in updating], fixes, own[updating])
    return [live[k] for k in kept], [dts[k] for k in kept], own[kept]
