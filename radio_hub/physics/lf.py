"""The LF field: 125 kHz bursts from a robot's two antennas and the RSSI a belt measures from each.

Pure: positions in, RSSI out, randomness from a numpy Generator the caller seeds.

Physical picture (Pet-Bot paper, spec pet-bot-wearable.md): LF at 125 kHz is a magnetic near field, so
its strength falls with the cube of distance (60 dB per decade, against 20 dB in free far-field space)
and it passes through people and furniture: there is no occlusion. That steep, occlusion-free fall is
what makes LF good for ranging at arm's length and bad beyond a few metres. The robot carries two
antennas side by side on its body y axis (0.20 m apart); it fires them in turn, so the belt measures one
RSSI per antenna per round. Each burst carries a 16-bit wake-up pattern; a wearable wakes only when the
pattern matches its register, so a robot's bursts wake its owner's belt and no other.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from radio_hub.config import build_config
from radio_hub.lazy import lazy_numpy

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import ArrayLike
else:
    np = lazy_numpy(__name__)

PATTERN_BITS = 16
"""Length of a wake-up pattern (the LF wake-up receivers of this kind correlate a 16-bit Manchester pattern)."""
_PATTERN_MASK = (1 << PATTERN_BITS) - 1
_PATTERN_MULTIPLIER = 0x9E37
"""Odd, so multiplying by it modulo 2^16 is a bijection: distinct robot ids get distinct patterns. It is
the 16-bit golden-ratio constant, which spreads consecutive ids over many differing bits."""
_PATTERN_OFFSET = 0x5A3C
"""XOR-ed in so that robot 0 does not get the all-zero pattern (an unset register reads 0)."""


@dataclass
class LfConfig:
    """Constants of the emulated LF link, shared by the field (truth) and the belt (calibration).

    The paper gives no numbers; the defaults describe a 125 kHz wake-up receiver of the AS3933 kind
    (about 80 dB of RSSI range, 1 dB steps) and are tuned so that a burst is heard to about 3 m, the
    2 m tracking range sits inside it with margin, and the fix's accuracy at 25-200 cm is a few cm.
    """

    rssi_at_1m_dbm: float = -50.0
    """Mean RSSI at 1 m from an antenna. With ``decade_loss_db`` it places the 3 m edge at -78.6 dBm and
    25 cm at -13.9 dBm, both inside a wake-up receiver's 80 dB RSSI range."""
    decade_loss_db: float = 60.0
    """Loss per decade of distance: the magnetic near field falls as 1/d^3 (60 dB per decade)."""
    noise_db: float = 0.3
    """Standard deviation of one burst's RSSI (Gaussian, independent per burst and antenna): about the
    quantisation noise of a receiver that reports RSSI in 1 dB steps (1/sqrt(12) = 0.29 dB). Through the
    60 dB/decade law it is a 1.2 % distance error per burst; with a 0.20 m baseline the bearing of one
    round is then good to about 5 degrees at 1 m and 10 at 2 m (see tests/unit/test_lf.py)."""
    sensitivity_dbm: float = -78.0
    """Below it a burst is not heard at all: -50 - 60 log10(3) = -78.6 dBm, so bursts are heard to
    about 3 m (to 2.9-3.1 m, the noise blurs the edge)."""
    antenna_baseline_m: float = 0.20
    """Distance between the robot's two LF antennas (spec: d_W = 0.20 m), centred on the robot."""
    wake_range_m: float = 1.0
    """An authorizing belt wakes only within this distance (spec: owner detection within 1 m)."""
    near_field_m: float = 0.05
    """Below this distance the RSSI stops growing (the antenna coil is a few cm across, so the dipole law
    no longer holds; a belt cannot be closer to the antenna than the robot's shell anyway)."""

    def validate(self) -> LfConfig:
        """Raise ValueError naming the field on a non-physical setting; returns self so it can be chained."""
        if self.decade_loss_db <= 0:
            raise ValueError(f"decade_loss_db must be > 0, got {self.decade_loss_db}")
        if self.noise_db < 0:
            raise ValueError(f"noise_db must be >= 0, got {self.noise_db}")
        if self.sensitivity_dbm >= self.rssi_at_1m_dbm:
            raise ValueError(
                f"sensitivity_dbm ({self.sensitivity_dbm}) must be below rssi_at_1m_dbm ({self.rssi_at_1m_dbm})"
            )
        if self.antenna_baseline_m <= 0:
            raise ValueError(f"antenna_baseline_m must be > 0, got {self.antenna_baseline_m}")
        if not 0 < self.near_field_m < self.wake_range_m:
            raise ValueError(f"near_field_m must be in (0, wake_range_m), got {self.near_field_m}")
        if self.wake_range_m >= self.range_m:
            raise ValueError(
                f"wake_range_m ({self.wake_range_m}) must be inside the heard range ({self.range_m:.2f} m)"
            )
        return self

    @property
    def range_m(self) -> float:
        """Distance at which the mean RSSI falls to the sensitivity: the edge of hearing."""
        return float(10 ** ((self.rssi_at_1m_dbm - self.sensitivity_dbm) / self.decade_loss_db))

    @property
    def wake_threshold_dbm(self) -> float:
        """Mean RSSI at ``wake_range_m``: a belt replies to a matching burst only at or above it."""
        return float(mean_rssi_dbm(self.wake_range_m, self))

    def noise_free(self) -> LfConfig:
        """The same link without burst noise (for exact tests)."""
        return dataclasses.replace(self, noise_db=0.0)

    def to_dict(self) -> dict[str, Any]:
        """Plain dict, as accepted by ``from_dict``."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> LfConfig:
        """Build from a table; unknown keys raise ValueError naming them."""
        return build_config(cls, data, "lf.").validate()


def mean_rssi_dbm(distance_m: ArrayLike, config: LfConfig) -> np.ndarray:
    """Mean RSSI at ``distance_m`` from an antenna: P(1 m) - loss x log10(max(d, near field)). Vectorised."""
    d = np.maximum(np.asarray(distance_m, dtype=float), config.near_field_m)
    return config.rssi_at_1m_dbm - config.decade_loss_db * np.log10(d)


def antenna_positions(pose: ArrayLike, baseline_m: float = 0.20) -> tuple[np.ndarray, np.ndarray]:
    """World xy of the left and right LF antennas of a robot at ``pose`` (x, y, yaw).

    They sit ``baseline_m / 2`` to either side of the centre along the body y axis (y is left).
    """
    x, y, yaw = _pose(pose)
    half = baseline_m / 2
    body_left = np.array([-np.sin(yaw), np.cos(yaw)])
    centre = np.array([x, y])
    return centre + half * body_left, centre - half * body_left


def lf_rssi(antenna_xy: ArrayLike, belt_xy: ArrayLike, config: LfConfig, rng: np.random.Generator) -> float | None:
    """RSSI (dBm) one burst from the antenna at ``antenna_xy`` produces at the belt, or None if not heard.

    No occlusion: LF passes through bodies and obstacles. The burst's noise is drawn before the
    sensitivity test, so near the edge of range a burst is heard some of the time.
    """
    antenna = _xy(antenna_xy, "antenna_xy")
    belt = _xy(belt_xy, "belt_xy")
    rssi = float(mean_rssi_dbm(np.hypot(*(belt - antenna)), config))
    if config.noise_db > 0:
        rssi += config.noise_db * float(rng.standard_normal())
    return rssi if rssi >= config.sensitivity_dbm else None


def wake_pattern(robot_id: int) -> int:
    """The 16-bit wake-up pattern of robot ``robot_id`` (0..65535): distinct ids give distinct patterns."""
    if not 0 <= robot_id <= _PATTERN_MASK:
        raise ValueError(f"robot_id must be in 0..{_PATTERN_MASK}, got {robot_id}")
    return ((robot_id * _PATTERN_MULTIPLIER) & _PATTERN_MASK) ^ _PATTERN_OFFSET


def wakes(belt_register: int, burst_pattern: int) -> bool:
    """True when a burst carrying ``burst_pattern`` wakes a wearable whose register holds ``belt_register``.

    The receiver correlates the whole pattern, so only an exact match wakes it.
    """
    for name, value in (("belt_register", belt_register), ("burst_pattern", burst_pattern)):
        if not 0 <= value <= _PATTERN_MASK:
            raise ValueError(f"{name} must be a 16-bit pattern, got {value}")
    return belt_register == burst_pattern


def _pose(pose: ArrayLike) -> tuple[float, float, float]:
    array = np.asarray(pose, dtype=float).ravel()
    if array.size < 3 or not np.all(np.isfinite(array[:3])):
        raise ValueError(f"pose must be finite (x, y, yaw), got {pose!r}")
    return float(array[0]), float(array[1]), float(array[2])


def _xy(point: ArrayLike, name: str) -> np.ndarray:
    array = np.asarray(point, dtype=float).ravel()
    if array.size < 2 or not np.all(np.isfinite(array[:2])):
        raise ValueError(f"{name} must be a finite (x, y), got {point!r}")
    return array[:2]
