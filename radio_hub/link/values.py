"""The radio's values, shared by a node and the hub: frames' outcomes, what a radio and a body's sensors
hand a node, the errors a node sees. Plain data: no zenoh, no asyncio, no threads, so a pure core (a robot's
managers and controllers) takes them without loading any I/O.
"""

from __future__ import annotations

import array
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from radio_hub.air.mac import Frame, TxStatus
from radio_hub.lazy import lazy_numpy
from radio_hub.physics.light import RECEIVERS as IR_RECEIVERS

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

MODEL_EPOCH_S = 1_700_000_000.0
"""The wall-clock time model and lockstep runs report for model time 0, on both sides (a fixed date: records of
equal seeds are equal, pcap stamps included)."""


class HubUnavailable(ConnectionError):
    """No hub answers at the endpoint, or it stopped answering."""


class RadioError(RuntimeError):
    """The hub refused a request (bad channel, address, PAN...)."""


@dataclass(frozen=True)
class RadioIdentity:
    """A node's radio: ids, addresses, PAN, channel and (until the world model) a fixed position."""

    node_id: str
    ext_addr: int
    short_addr: int
    pan_id: int
    channel: int = 11
    position: tuple[float, float] = (0.0, 0.0)
    heading_deg: float = 0.0
    """Where the body faces when it attaches (the world moves it from then on)."""
    kind: str = "robot"
    """``robot``, ``user`` (a person's wearables: BLE, the belt's LF receiver, an IR beacon; no 802.15.4) or
    ``control`` (a run's orchestrator: it only relays)."""


@dataclass(frozen=True)
class RxFrame:
    """A frame this node's MAC received, with its signal and model times (microseconds)."""

    frame: Frame
    rssi_dbm: float
    lqi: int
    start_us: int
    end_us: int
    submitted_us: int


@dataclass(frozen=True)
class TxResult:
    """The MAC's answer to ``send``."""

    status: TxStatus
    retries: int = 0
    backoffs: int = 0
    submitted_us: int = 0
    done_us: int = 0
    reason: str = ""

    @property
    def ok(self) -> bool:
        """True when the frame went out (and, for acknowledged unicast, was acknowledged)."""
        return self.status == TxStatus.SUCCESS


class OwnSensors:
    """A robot's own body sensors at model time ``t_us``: ultrasonic ranges (m, nan = no echo) at
    ``angles_rad`` from its heading, AHRS yaw (rad), wheel odometry (vx, vy, omega in its frame).

    As they come off the air (``of_wire``), the ranges stay bytes and the angles a getter until first
    read: the hub sends them to every robot at 25 Hz, and one that only pings never reads them (and so
    never imports numpy for them)."""

    __slots__ = ("_angles_rad", "_ranges_m", "odometry", "t_us", "yaw_rad")

    def __init__(
        self,
        t_us: int,
        ranges_m: np.ndarray,
        angles_rad: np.ndarray,
        yaw_rad: float,
        odometry: tuple[float, float, float],
    ) -> None:
        self.t_us = t_us
        self._ranges_m: np.ndarray | bytes = ranges_m
        self._angles_rad: np.ndarray | Callable[[], np.ndarray] = angles_rad
        self.yaw_rad = yaw_rad
        self.odometry = odometry

    @classmethod
    def of_wire(
        cls,
        t_us: int,
        ranges: bytes,
        angles: Callable[[], np.ndarray],
        yaw_rad: float,
        odometry: tuple[float, float, float],
    ) -> OwnSensors:
        """Sensors of ``ranges`` as sent (little-endian float32) and ``angles`` as given when first read."""
        sensors = cls.__new__(cls)
        sensors.t_us = t_us
        sensors._ranges_m = ranges
        sensors._angles_rad = angles
        sensors.yaw_rad = yaw_rad
        sensors.odometry = odometry
        return sensors

    @property
    def ranges_m(self) -> np.ndarray:
        """Ultrasonic ranges (m, nan = no echo), one per sensor of the ring."""
        if isinstance(self._ranges_m, bytes):
            self._ranges_m = np.frombuffer(self._ranges_m, dtype="<f4").astype(float)
        return self._ranges_m

    def ranges_list(self) -> list[float]:
        """``ranges_m`` as Python floats, the same values: from the bytes as they came (float32, widened exactly)
        without an array, for a control step that reads them in plain floats."""
        raw = self._ranges_m
        if isinstance(raw, bytes):
            values = array.array("f", raw)
            if sys.byteorder != "little":  # the wire's float32 are little-endian
                values.byteswap()
            return values.tolist()
        return np.asarray(raw, dtype=float).tolist()

    @property
    def angles_rad(self) -> np.ndarray:
        """Each ultrasonic sensor's axis from the heading (rad)."""
        if callable(self._angles_rad):
            self._angles_rad = self._angles_rad()
        return self._angles_rad


class BeaconSweep:
    """One beacon-mode sweep at model time ``t_us``: each coded beacon's 12 readings (counts) and the gain its
    channel's AGC read them at (divide the light above ambient by it).

    Made from maps (``BeaconSweep(t_us, readings, gains)``) or, as it comes off the air, from one (sources, 12)
    block (``of_block``); either way ``readings``/``gains`` are the maps and ``arrays()`` the block, each
    worked out from the other only when asked for (a robot reads the block on each body-sensor sample, 25 Hz)."""

    __slots__ = ("_block", "_gain_list", "_gains", "_readings", "_sources", "t_us")

    def __init__(self, t_us: int, readings: dict[str, np.ndarray], gains: dict[str, float]) -> None:
        self.t_us = t_us
        self._readings: dict[str, np.ndarray] | None = readings
        self._gains: dict[str, float] | None = gains
        self._sources: list[str] | None = None
        self._block: np.ndarray | None = None
        self._gain_list: list[float] | None = None

    @classmethod
    def of_block(cls, t_us: int, sources: list[str], block: np.ndarray, gains: list[float]) -> BeaconSweep:
        """A sweep of distinct ``sources``, ``block[i]`` (12 readings) read at ``gains[i]``."""
        sweep = cls.__new__(cls)  # without __init__'s maps, made only to be dropped (one sweep a robot, 25 Hz)
        sweep.t_us = t_us
        sweep._readings = sweep._gains = None
        sweep._sources, sweep._block, sweep._gain_list = sources, block, gains
        return sweep

    @property
    def readings(self) -> dict[str, np.ndarray]:
        """Each source's 12 readings."""
        if self._readings is None:
            self._readings = dict(zip(self._sources or [], self._block if self._block is not None else [], strict=True))
        return self._readings

    @property
    def gains(self) -> dict[str, float]:
        """Each source's gain."""
        if self._gains is None:
            self._gains = dict(zip(self._sources or [], self._gain_list or [], strict=True))
        return self._gains

    def arrays(self) -> tuple[list[str], np.ndarray, list[float]]:
        """The sources, their readings (sources, 12) and their gains (1 where none was given), in one order."""
        if self._block is not None and self._sources is not None and self._gain_list is not None:
            return list(self._sources), self._block, list(self._gain_list)
        names = list(self.readings)
        block = np.array([self.readings[n] for n in names], dtype=float).reshape(-1, IR_RECEIVERS)
        return names, block, [self.gains.get(n, 1.0) for n in names]

    def __repr__(self) -> str:
        return f"BeaconSweep(t_us={self.t_us}, sources={list(self.readings)})"


@dataclass(frozen=True)
class BleMessage:
    """A BLE message from ``src`` (a user's wearable or a robot)."""

    src: str
    payload: bytes
    t_us: int


@dataclass(frozen=True)
class LfBurstHeard:
    """What a belt's LF front end heard: which antenna, the wake-up pattern, the 4 data bytes, RSSI."""

    antenna: str
    pattern: int
    data: bytes
    rssi_dbm: float
    t_us: int


@dataclass(frozen=True)
class IrSweep:
    """One sweep of the 12 phototransistors (ADC counts, receiver 0 on the heading) at model time ``t_us``."""

    readings: np.ndarray
    t_us: int
