"""The IR side of the environment: which module is in which mode, and the receivers' periodic readings.

Pure: the hub passes the model time and the poses in; readings come out for every receiving module, one
sweep per sample period while at least one module transmits. Overlaps (two or more transmitting at
once) are counted by ``OverlapCounter``; the readings of such moments are what the light makes of all
sources together, as a real module would see them.
"""

from __future__ import annotations

import numpy as np

from radio_hub.air.chaos import Chaos
from radio_hub.physics.light import (
    IrConfig,
    IrMode,
    OverlapCounter,
    beacon_gains,
    receiver_gains,
    receiver_readings,
    sense,
)

Pose = tuple[float, float, float]
"""x (m), y (m), heading (rad)."""


class IrAir:
    """Modes of every IR module and the sweeps of the receiving ones."""

    def __init__(self, config: IrConfig, rng: np.random.Generator) -> None:
        self.config = config.validate()
        self.rng = rng
        self.counter = OverlapCounter()
        self.period_us = max(round(1e6 / config.sample_rate_hz), 1)
        self.sweeps = 0
        """Receive sweeps made (the periodic sweeps while something transmits)."""
        self.beacon_sweeps = 0
        """Beacon sweeps made (the environment asks for them, with the body sensors)."""
        self.power: dict[str, float] = {}
        """Beacons brighter than a robot's module, by node (the person's: ``PERSON_BEACON_POWER``)."""
        self._next_us: int | None = None

    def set_mode(self, node_id: str, mode: str, now_us: int) -> None:
        """Switch a module; ValueError on an unknown mode."""
        self.counter.set_mode(node_id, IrMode(mode), now_us)
        self._schedule(now_us)

    def remove(self, node_id: str, now_us: int) -> None:
        """A node left: its module goes dark."""
        self.counter.remove(node_id, now_us)
        self._schedule(now_us)

    def next_event_us(self) -> int | None:
        """When the next sweep is due (None while nothing transmits)."""
        return self._next_us

    def take_due(self, now_us: int) -> bool:
        """True (once) when a sweep is due at ``now_us``; the next one is then scheduled."""
        if self._next_us is None or now_us < self._next_us:
            return False
        self._next_us += self.period_us
        return True

    def sweep(self, now_us: int, poses: dict[str, Pose], chaos: Chaos | None = None) -> dict[str, np.ndarray]:
        """Readings (12 ADC counts) of every receiving module with a known pose, if a sweep is due;
        ``chaos`` may blind receivers (every reading at full scale) or add noise to them."""
        return self.receive_sweep(poses, chaos) if self.take_due(now_us) else {}

    def receive_sweep(self, poses: dict[str, Pose], chaos: Chaos | None = None) -> dict[str, np.ndarray]:
        """One sweep of every module in receive mode, under every transmitting module's light."""
        modes = self.counter.modes
        sources = [poses[n] for n in self.counter.transmitters if n in poses]
        receivers = [n for n, mode in modes.items() if mode is IrMode.RECEIVE and n in poses]
        if not sources or not receivers:
            return {}
        self.sweeps += 1
        readings = receiver_readings(np.array(sources), np.array([poses[n] for n in receivers]), self.config, self.rng)
        if chaos is not None and chaos.faults:
            readings = self._disturb(readings, receivers, chaos)
        # quantisation is part of the model's noise floor, so readings travel unrounded
        return dict(zip(receivers, readings.astype(np.float32), strict=True))

    def beacon_sweep(
        self, poses: dict[str, Pose], chaos: Chaos | None = None
    ) -> dict[str, tuple[list[str], np.ndarray, list[float]]]:
        """For every module in beacon mode: the beacons it sees (sources in range), one demodulated sweep per
        source, shape (sources, 12), read at the gain its channel's AGC chose (``light.beacon_gain``), and
        those gains (the receiver divides by them)."""
        names = [n for n, mode in self.counter.modes.items() if mode is IrMode.BEACON and n in poses]
        if len(names) < 2:
            return {}
        self.beacon_sweeps += 1
        at = np.array([poses[n] for n in names], dtype=float)
        dx = at[None, :, 0] - at[:, None, 0]
        dy = at[None, :, 1] - at[:, None, 1]
        distance = np.hypot(dx, dy)
        np.fill_diagonal(distance, np.inf)  # a module does not see its own beacon
        strength = self._beacon_strength(distance, names)
        seen = strength > 0
        out: dict[str, tuple[list[str], np.ndarray, list[float]]] = {}
        counts = np.add.reduce(seen, axis=1, dtype=np.intp)  # np.count_nonzero along an axis: its Python path
        lit_rows = np.flatnonzero(counts).tolist()
        if not lit_rows:
            return out
        # the light of every (module, source) pair in sight, rows of one module together, modules in order
        module, source = np.nonzero(seen)
        lit = strength[seen][:, None] * receiver_gains(np.arctan2(dy[seen], dx[seen]) - at[module, 2])
        names_array = np.array(names, dtype=object)
        if chaos is not None and any(f.kind in ("ir_blind", "ir_noise") for f in chaos.faults.values()):
            # a disturbed module draws its noise right after its own readings: module by module
            for row in lit_rows:
                node = names[row]
                mine = lit[module == row]
                gains = beacon_gains(mine.max(axis=1), self.config)
                readings = sense(mine * gains[:, None], self.config, self.rng)
                readings = self._disturb(readings, [node] * len(readings), chaos)
                out[node] = (names_array[seen[row]].tolist(), readings.astype(np.float32), gains.tolist())
            return out
        # every module's sweep in one array, in module order: the same draws as module by module
        gains = beacon_gains(np.maximum.reduce(lit, axis=1), self.config)
        readings = sense(lit * gains[:, None], self.config, self.rng).astype(np.float32)
        sources, gain_list, ends = names_array[source].tolist(), gains.tolist(), np.cumsum(counts).tolist()
        for row in lit_rows:
            start, end = ends[row] - int(counts[row]), ends[row]
            out[names[row]] = (sources[start:end], readings[start:end], gain_list[start:end])
        return out

    def _beacon_strength(self, distance: np.ndarray, names: list[str]) -> np.ndarray:
        """On-axis strength of every source (column) at every module (row): the module's inverse-square law,
        times the source's power, out to the range that power reaches (the person's beacon is brighter)."""
        config = self.config
        power = np.array([self.power.get(n, 1.0) for n in names])[None, :]
        near = np.maximum(distance, config.near_field_m)
        reach = config.max_range_m * np.sqrt(power)
        return np.where(distance <= reach, power * config.power_counts_at_1m / near**2, 0.0)

    def _disturb(self, readings: np.ndarray, receivers: list[str], chaos: Chaos) -> np.ndarray:
        for row, node in enumerate(receivers):
            for fault in chaos.ir_faults(node):
                if fault.kind == "ir_blind":
                    readings[row] = self.config.saturation_counts  # a lamp straight into the module
                else:
                    noisy = readings[row] + self.rng.normal(0.0, fault.sigma, size=readings.shape[1])
                    readings[row] = np.clip(noisy, 0.0, self.config.saturation_counts)
        return readings

    def _schedule(self, now_us: int) -> None:
        # beacons are swept with the body sensors, on the world's ticks: only transmitters need the sweeps
        if not self.counter.transmitters:
            self._next_us = None
        elif self._next_us is None:
            self._next_us = now_us + self.period_us
