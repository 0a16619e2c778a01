"""The IR side of the environment: which module is in which mode, and the receivers' periodic readings.

Pure: the hub passes the model time and the poses in; readings come out for every receiving module, one
sweep per sample period while at least one module transmits. Overlaps (two or more transmitting at
once) are counted by ``OverlapCounter``; the readings of such moments are what the light makes of all
sources together, as a real module would see them.
"""

from __future__ import annotations

import numpy as np

from radio_hub.chaos import Chaos
from radio_hub.light import IrConfig, IrMode, OverlapCounter, receiver_readings

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

    def sweep(self, now_us: int, poses: dict[str, Pose], chaos: Chaos | None = None) -> dict[str, np.ndarray]:
        """Readings (12 ADC counts) of every receiving module with a known pose, if a sweep is due;
        ``chaos`` may blind receivers (every reading at full scale) or add noise to them."""
        if self._next_us is None or now_us < self._next_us:
            return {}
        self._next_us += self.period_us
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
        if not self.counter.transmitters:
            self._next_us = None
        elif self._next_us is None:
            self._next_us = now_us + self.period_us
