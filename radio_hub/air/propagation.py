"""Who hears whom, how strongly, and how often a frame is lost on the way. Pure, seeded by the caller."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from radio_hub.config import GilbertElliottConfig, PathLossConfig, RangeConfig
from radio_hub.lazy import lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

Position = tuple[float, float]


def distance(a: Position, b: Position) -> float:
    """Euclidean distance in metres."""
    return math.hypot(a[0] - b[0], a[1] - b[1])


def mean_rssi_dbm(cfg: PathLossConfig, dist_m: float) -> float:
    """Log-distance path loss without shadowing; distances under 1 m count as 1 m (near field)."""
    return cfg.tx_power_dbm - cfg.loss_at_1m_db - 10.0 * cfg.exponent * math.log10(max(dist_m, 1.0))


def lqi_from_rssi(cfg: PathLossConfig, rssi_dbm: float) -> int:
    """Map RSSI linearly onto 0..255 between the sensitivity and -20 dBm, as CC2420-class radios do."""
    span = -20.0 - cfg.sensitivity_dbm
    return round(min(max((rssi_dbm - cfg.sensitivity_dbm) / span, 0.0), 1.0) * 255)


def reception_probability(cfg: RangeConfig, dist_m: float) -> float:
    """Cooja UDGM-style success ratio: 1 at 0 m falling to ``success_ratio_rx`` at the tx range edge."""
    if dist_m > cfg.tx_range_m:
        return 0.0
    return 1.0 - (1.0 - cfg.success_ratio_rx) * (dist_m / cfg.tx_range_m) ** 2


class GilbertElliott:
    """Burst loss: one two-state Markov chain per directed link, all starting in the good state."""

    def __init__(self, cfg: GilbertElliottConfig) -> None:
        self.cfg = cfg
        self._bad: dict[tuple[str, str], bool] = {}

    def lost(self, link: tuple[str, str], rng: np.random.Generator) -> bool:
        """Step the link's chain once and say whether this frame is lost."""
        cfg = self.cfg
        if not cfg.enabled:
            return False
        bad = self._bad.get(link, False)
        bad = rng.random() >= cfg.p_bad_to_good if bad else rng.random() < cfg.p_good_to_bad
        self._bad[link] = bad
        return rng.random() < (cfg.loss_bad if bad else cfg.loss_good)

    def forget(self, node_id: str) -> None:
        """Drop the chains of a node that left."""
        self._bad = {k: v for k, v in self._bad.items() if node_id not in k}

    def mean_loss(self) -> float:
        """Stationary loss probability of the chain, for checking statistics."""
        cfg = self.cfg
        total = cfg.p_good_to_bad + cfg.p_bad_to_good
        p_bad = cfg.p_good_to_bad / total if total else 0.0
        return p_bad * cfg.loss_bad + (1 - p_bad) * cfg.loss_good
