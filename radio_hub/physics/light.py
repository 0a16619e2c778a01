"""The light: IR emission and the readings of every robot's 12 phototransistors, from true geometry.

Pure and vectorised: poses in, readings out, randomness from a numpy Generator the caller seeds.

Physical picture (swarm paper section 3.3, spec section 4): the IR module sits at the robot's centre;
its LED ring emits in every direction at once (isotropic in the plane, so a transmitter's heading does
not matter); 12 phototransistors around the rim, numbered 0..11 counter-clockwise from the robot's
heading, 30 degrees apart, each see a source with a cosine response to the angle between the source
and the receiver's axis, and nothing from behind. Irradiance falls with the square of distance; all
active transmitters superpose, so two at once give readings that belong to neither (only the token
schedule prevents that). Readings are in ADC counts of a 10-bit converter: ambient light, noise and
saturation are added in that unit.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field
from enum import StrEnum
from typing import TYPE_CHECKING, Any

from radio_hub.config import build_config
from radio_hub.lazy import lazy_numpy

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import ArrayLike
else:
    np = lazy_numpy(__name__)

RECEIVERS = 12
"""Phototransistors per IR module."""
RECEIVER_SPACING_RAD = math.pi / 6  # the same float as np.pi / 6


@functools.cache
def receiver_axes_rad() -> np.ndarray:
    """Axis of receiver k relative to the robot's heading: k x 30 degrees, counter-clockwise.

    Also ``RECEIVER_AXES_RAD``, built at its first read so that importing this module imports no numpy."""
    return np.arange(RECEIVERS) * RECEIVER_SPACING_RAD


def __getattr__(name: str) -> Any:
    """Array constants, built at first read (a robot that only pings never reads them)."""
    if name == "RECEIVER_AXES_RAD":
        return receiver_axes_rad()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


@dataclass
class IrConfig:
    """Constants of the emulated IR module, shared by the light model (truth) and the estimator (calibration).

    The defaults describe a module of a few 940 nm LEDs and 12 phototransistors read through a
    multiplexed 10-bit ADC, tuned so that the paper's experiment (40-200 cm) sits well inside the
    working range: no saturation beyond about 25 cm and a signal five noise sigmas above the floor at
    the maximum range.
    """

    power_counts_at_1m: float = 60.0
    """Emitted power, as the strength (ADC counts above ambient) an on-axis receiver reads at 1 m.
    With the inverse-square law this gives 375 counts at 40 cm, 15 at 2 m and 7.7 at the 2.8 m range edge,
    that is 5 x ``noise_floor_counts``: the edge of range is where the signal sinks into the floor."""
    near_field_m: float = 0.10
    """Below this distance strength stops growing (reads as at ``near_field_m``): the LED ring and the
    receivers' apertures are a few cm across, so the point-source inverse-square law no longer holds.
    Robots cannot come this close anyway (their bodies touch first), and the module saturates well before."""
    max_range_m: float = 2.8
    """Maximum range: beyond it a transmitter adds no light at all. A hard cutoff rather than a soft
    fade keeps 'in range' a crisp yes/no for the hub and the tests; it sits where the inverse-square
    signal has fallen to a few noise sigmas (IR modules of this kind reach 2.5-3 m)."""
    relative_noise: float = 0.03
    """Standard deviation of the multiplicative noise of each reading, as a fraction of its strength:
    LED drive ripple, phototransistor gain spread and reflections, about 3 % per sample."""
    noise_floor_counts: float = 1.5
    """Standard deviation of the additive noise of each reading, in counts: ADC quantisation (0.3 counts)
    plus dark current and amplifier noise; dominates beyond about 1.2 m."""
    emitter_noise: float = 0.0
    """Standard deviation of a multiplicative variation common to all 12 readings of one sweep, as a fraction
    of the light: the emitter's drive current and the receiver's ADC reference drifting between sweeps. It
    moves the strength (distance) but not the ratios between receivers (direction). 0 by default (an ideal
    emitter); the kim2017 profile sets it (docs/PROFILES.md)."""
    ambient_counts: float = 30.0
    """Mean reading with no transmitter (indoor light through the IR filter, about 3 % of full scale).
    The module knows it (a dark reading taken at start-up), so estimators subtract it."""
    saturation_counts: float = 1023.0
    """Full scale of the 10-bit ADC: a reading never exceeds it (nor goes below 0)."""
    sample_rate_hz: float = 100.0
    """Sweeps of all 12 receivers per second: 12 multiplexed channels, each with about 0.5 ms of
    phototransistor settling and a few averaged conversions, take about 10 ms."""
    detection_sigmas: float = 4.0
    """The estimator's no-signal threshold, in noise-floor sigmas above ambient: with 12 receivers a
    false detection from noise alone has a probability of about 4e-4 per sweep."""

    def validate(self) -> IrConfig:
        """Raise ValueError on a non-physical setting; returns self so it can be chained."""
        if self.power_counts_at_1m <= 0:
            raise ValueError("power_counts_at_1m must be > 0")
        if not 0 < self.near_field_m < self.max_range_m:
            raise ValueError("need 0 < near_field_m < max_range_m")
        noises = (self.relative_noise, self.noise_floor_counts, self.emitter_noise)
        if min(*noises, self.ambient_counts, self.detection_sigmas) < 0:
            raise ValueError("noise, ambient and detection_sigmas must be >= 0")
        if self.saturation_counts <= self.ambient_counts:
            raise ValueError("saturation_counts must be above ambient_counts")
        if self.sample_rate_hz <= 0:
            raise ValueError("sample_rate_hz must be > 0")
        return self

    @property
    def detection_threshold_counts(self) -> float:
        """Strength above ambient that the strongest receiver must exceed for a source to count as seen."""
        return self.detection_sigmas * self.noise_floor_counts

    @property
    def noiseless(self) -> bool:
        """True when readings carry no random noise."""
        return self.relative_noise == 0 and self.noise_floor_counts == 0 and self.emitter_noise == 0

    def brighter(self, factor: float) -> IrConfig:
        """The same receivers calibrated for an emitter ``factor`` times as bright: strength scales with it
        and the range with its square root (the inverse-square signal reaches the same floor further out)."""
        if not factor > 0:
            raise ValueError(f"factor must be > 0, got {factor}")
        return dataclasses.replace(
            self, power_counts_at_1m=self.power_counts_at_1m * factor, max_range_m=self.max_range_m * factor**0.5
        )

    def noise_free(self) -> IrConfig:
        """The same module with both noise terms off (ambient and saturation stay: they are not random)."""
        return dataclasses.replace(self, relative_noise=0.0, noise_floor_counts=0.0, emitter_noise=0.0)

    def to_dict(self) -> dict[str, Any]:
        """Plain dict, as accepted by ``from_dict``."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> IrConfig:
        """Build from a table; unknown keys raise ValueError naming them."""
        return build_config(cls, data, "ir.").validate()


def strength_at(distance_m: ArrayLike, config: IrConfig) -> np.ndarray:
    """On-axis strength (counts above ambient) at ``distance_m``: P / max(d, near field)^2, 0 beyond range."""
    d = np.asarray(distance_m, dtype=float)
    strength = config.power_counts_at_1m / np.maximum(d, config.near_field_m) ** 2
    return np.where(d <= config.max_range_m, strength, 0.0)


def receiver_gains(bearing_rad: ArrayLike) -> np.ndarray:
    """Cosine response of the 12 receivers to a source at ``bearing_rad`` from the heading, clipped at 0.

    Shape: the bearing's shape plus a last axis of 12.
    """
    relative = np.asarray(bearing_rad, dtype=float)[..., None] - receiver_axes_rad()
    return np.maximum(np.cos(relative), 0.0)  # np.clip at 0 from below, without its checks


def incident_light(transmitters: ArrayLike, receivers: ArrayLike, config: IrConfig) -> np.ndarray:
    """Noise-free strength at every receiver, summed over all transmitters: shape (receivers, 12).

    ``transmitters``: (T, 2) or (T, 3) world poses x, y[, heading] in metres and radians (the heading
    is ignored: the emitter is isotropic). ``receivers``: (R, 3) poses x, y, heading. A transmitter at
    the very position of a receiver (its own module) adds nothing.
    """
    tx = _poses(transmitters, 2)
    rx = _poses(receivers, 3)
    dx = tx[None, :, 0] - rx[:, None, 0]
    dy = tx[None, :, 1] - rx[:, None, 1]
    distance = np.hypot(dx, dy)
    bearing = np.arctan2(dy, dx) - rx[:, None, 2]
    strength = np.where(distance > 0, strength_at(distance, config), 0.0)
    return np.einsum("rt,rtk->rk", strength, receiver_gains(bearing))


def sense(light: ArrayLike, config: IrConfig, rng: np.random.Generator) -> np.ndarray:
    """What the ADC reads for incident ``light`` (counts): ambient plus noise, clipped to 0..saturation.

    Noise is Gaussian and independent per receiver and sample, with standard deviation
    sqrt(floor^2 + (relative x light)^2); with ``emitter_noise`` a variation common to the 12 readings of a
    sweep comes on top.
    """
    light = np.asarray(light, dtype=float)
    sigma = np.hypot(config.noise_floor_counts, config.relative_noise * light)
    raw = config.ambient_counts + light + sigma * rng.standard_normal(light.shape)
    if config.emitter_noise:  # drawn only when set: an ideal emitter leaves the draws (and runs) as they were
        raw += config.emitter_noise * light * rng.standard_normal((*light.shape[:-1], 1))
    return np.minimum(np.maximum(raw, 0.0), config.saturation_counts)  # np.clip's values, without its checks


def receiver_readings(
    transmitters: ArrayLike, receivers: ArrayLike, config: IrConfig, rng: np.random.Generator
) -> np.ndarray:
    """One sweep of the 12 readings of every receiver while all ``transmitters`` are on: (receivers, 12)."""
    return sense(incident_light(transmitters, receivers, config), config, rng)


def _poses(poses: ArrayLike, columns: int) -> np.ndarray:
    array = np.asarray(poses, dtype=float)
    if array.size == 0:
        return np.zeros((0, columns))
    array = np.atleast_2d(array)
    if array.ndim != 2 or array.shape[1] < columns:
        raise ValueError(f"poses must have shape (N, {columns}) or wider, got {array.shape}")
    return array


BEACON_GAINS = tuple(2.0**-k for k in range(7))
"""The gains a beacon channel's automatic gain control steps through (1 down to 1/64, a factor 2 each)."""
AGC_HEADROOM = 0.8
"""The AGC keeps a channel's brightest reading below this fraction of full scale (noise and motion within
a sweep must not clip it)."""


def beacon_gain(peak_light: float, config: IrConfig) -> float:
    """The gain a beacon channel's AGC picks for a source whose strongest receiver sees ``peak_light``: the
    largest of ``BEACON_GAINS`` keeping ambient plus the gained light under ``AGC_HEADROOM`` of full scale.

    Why: every beacon is demodulated on its own channel, so each can have its own gain, as IR receivers'
    AGC does. Without it the person's beacon (9x a robot's) saturated every facing receiver within 0.74 m,
    just where the surround formation holds its robots: the estimator could only say "0.74 m or nearer",
    up to 0.44 m off. Gains reach down to 1/64, so even a beacon at the near field (0.1 m) stays readable.
    """
    limit = AGC_HEADROOM * config.saturation_counts - config.ambient_counts
    for gain in BEACON_GAINS:
        if gain * peak_light <= limit:
            return gain
    return BEACON_GAINS[-1]


def beacon_gains(peak_light: ArrayLike, config: IrConfig) -> np.ndarray:
    """``beacon_gain`` of every peak in an array at once."""
    peak = np.asarray(peak_light, dtype=float)
    limit = AGC_HEADROOM * config.saturation_counts - config.ambient_counts
    # gain 2^-k fits when 2^-k peak <= limit, that is (scaling by a power of two being exact) when
    # peak <= limit 2^k: the first of those thresholds at or above the peak is the gain's index
    gains = _gains()
    step = np.searchsorted(limit / gains, peak, side="left")
    return gains[np.minimum(step, len(gains) - 1)]


@functools.cache
def _gains() -> np.ndarray:
    """``BEACON_GAINS`` as an array."""
    return np.array(BEACON_GAINS)


# == who is transmitting ==============================================================================


PERSON_BEACON_POWER = 9.0
"""How much brighter the person's IR beacon is than a robot's module (surround formation): a belt-worn
ring of high-power LEDs, so every robot of a 20-robot swarm sees its human (range 3 x 2.8 = 8.4 m) while
robots see each other only within the module's 2.8 m. The surround law needs the human's direction at
every robot; with the robots' own range the swarm's rear lost him and the swarm fell behind or split."""


class IrMode(StrEnum):
    """What a robot's IR module manager has set its module to."""

    IDLE = "idle"
    RECEIVE = "receive"
    TRANSMIT = "transmit"
    BEACON = "beacon"
    """Surround formation: the module emits its own coded beacon (each robot's LEDs modulated at their
    own frequency) and demodulates every other beacon separately, so all can shine at once."""


def overlapping(transmitting: ArrayLike) -> np.ndarray:
    """Per sample (row of a (samples, robots) boolean array), True when more than one robot transmits."""
    return np.count_nonzero(np.atleast_2d(np.asarray(transmitting, dtype=bool)), axis=-1) > 1


@dataclass
class OverlapCounter:
    """Counts the moments two or more modules transmit at once, on the hub's model clock (us).

    An *episode* starts whenever the number of transmitters rises from at most one to two or more;
    ``overlap_us`` is the model time spent with two or more on.
    """

    modes: dict[str, IrMode] = field(default_factory=dict)
    episodes: int = 0
    overlap_us: int = 0
    max_transmitters: int = 0
    _since_us: int | None = field(default=None, repr=False)

    @property
    def transmitters(self) -> list[str]:
        """Nodes whose module transmits now, sorted."""
        return sorted(node for node, mode in self.modes.items() if mode is IrMode.TRANSMIT)

    @property
    def overlapping(self) -> bool:
        """True while two or more modules transmit."""
        return self._since_us is not None

    def set_mode(self, node: str, mode: IrMode, now_us: int) -> bool:
        """Record ``node``'s new mode at ``now_us``; True when this change starts an overlap episode."""
        self.modes[node] = IrMode(mode)
        return self._update(now_us)

    def remove(self, node: str, now_us: int) -> None:
        """A node left (detached, died): its module stops."""
        self.modes.pop(node, None)
        self._update(now_us)

    def as_dict(self, now_us: int) -> dict[str, Any]:
        """Counters for the hub's stats, with an open episode counted up to ``now_us``."""
        open_us = now_us - self._since_us if self._since_us is not None else 0
        return {
            "overlap_episodes": self.episodes,
            "overlap_us": self.overlap_us + open_us,
            "max_transmitters": self.max_transmitters,
            "transmitting": self.transmitters,
        }

    def _update(self, now_us: int) -> bool:
        count = len(self.transmitters)
        self.max_transmitters = max(self.max_transmitters, count)
        if count > 1 and self._since_us is None:
            self._since_us = now_us
            self.episodes += 1
            return True
        if count <= 1 and self._since_us is not None:
            self.overlap_us += now_us - self._since_us
            self._since_us = None
        return False
