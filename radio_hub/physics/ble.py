"""BLE links between a user's wearables and robots: latency, jitter, range and loss, on the model clock.

Pure: the hub passes the model time, positions and its RNG. A BLE connection event comes every
connection interval, so a message waits up to one interval before it goes; the link layer retransmits
until it gets through, so loss here is what is left after that (a message given up on), and a message
beyond range is dropped. Messages between one pair keep their order (BLE's link layer is in order).
"""

from __future__ import annotations

import heapq
import itertools
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from radio_hub.config import build_config
from radio_hub.lazy import lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

MAX_PAYLOAD = 512
"""The longest BLE message the air carries (the wearables' messages are a few dozen bytes)."""


@dataclass
class BleConfig:
    """The link's constants (chosen: a 7.5 ms connection interval, the shortest BLE allows, as a wearable
    streaming to its robot would negotiate)."""

    interval_ms: float = 7.5
    """Connection interval: a message waits for the next connection event."""
    latency_ms: float = 2.0
    """Fixed cost on top: radio turnaround and the stacks at both ends."""
    loss: float = 0.0
    """Probability that a message is given up on after the link layer's retries."""
    range_m: float = 10.0
    """Beyond it the connection is lost and messages are dropped."""

    def validate(self) -> BleConfig:
        """Raise ValueError naming the first field out of range."""
        for name in ("interval_ms", "latency_ms"):
            if getattr(self, name) < 0:
                raise ValueError(f"ble.{name} must be >= 0, got {getattr(self, name)}")
        if not 0.0 <= self.loss <= 1.0:
            raise ValueError(f"ble.loss must be a probability in [0, 1], got {self.loss}")
        if not self.range_m > 0:
            raise ValueError(f"ble.range_m must be > 0, got {self.range_m}")
        return self

    def to_dict(self) -> dict[str, Any]:
        """Plain values, for stats and run records."""
        return dict(self.__dict__)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> BleConfig:
        """From a config table; unknown keys and bad values are errors naming the key."""
        return build_config(cls, data, "ble.").validate()


@dataclass(frozen=True)
class BleDelivery:
    """A message due at ``due_us`` for ``dst``."""

    due_us: int
    dst: str
    src: str
    payload: bytes


@dataclass
class BleCounters:
    """What became of the messages sent."""

    sent: int = 0
    delivered: int = 0
    lost: int = 0
    out_of_range: int = 0

    def to_dict(self) -> dict[str, int]:
        """Plain counts."""
        return dict(self.__dict__)


@dataclass
class BleAir:
    """Messages in flight on every BLE link."""

    config: BleConfig
    rng: np.random.Generator
    counters: BleCounters = field(default_factory=BleCounters)
    _queue: list[tuple[int, int, BleDelivery]] = field(default_factory=list)
    _order: itertools.count = field(default_factory=itertools.count)
    _last_due: dict[tuple[str, str], int] = field(default_factory=dict)

    def send(self, src: str, dst: str, payload: bytes, now_us: int, distance_m: float) -> None:
        """Queue ``payload`` from ``src`` to ``dst``; ValueError when it is longer than ``MAX_PAYLOAD``."""
        if len(payload) > MAX_PAYLOAD:
            raise ValueError(f"a BLE payload is at most {MAX_PAYLOAD} bytes, not {len(payload)}")
        """Queue a message; lost or out-of-range messages are only counted."""
        cfg = self.config
        self.counters.sent += 1
        if not math.isfinite(distance_m) or distance_m > cfg.range_m:
            self.counters.out_of_range += 1
            return
        if cfg.loss and self.rng.random() < cfg.loss:
            self.counters.lost += 1
            return
        wait_us = self.rng.uniform(0.0, cfg.interval_ms * 1000.0) + cfg.latency_ms * 1000.0
        due = max(now_us + round(wait_us), self._last_due.get((src, dst), 0))  # in order per link
        self._last_due[(src, dst)] = due
        heapq.heappush(self._queue, (due, next(self._order), BleDelivery(due, dst, src, payload)))

    def next_event_us(self) -> int | None:
        """When the next message is due."""
        return self._queue[0][0] if self._queue else None

    def due(self, now_us: int) -> list[BleDelivery]:
        """Every message due by ``now_us``, in order."""
        out = []
        while self._queue and self._queue[0][0] <= now_us:
            out.append(heapq.heappop(self._queue)[2])
        self.counters.delivered += len(out)
        return out
