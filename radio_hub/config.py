"""Settings of the emulated air. Defaults follow IEEE 802.15.4-2006 (2.4 GHz O-QPSK PHY).

A hub reads them from a TOML or JSON file (``petswarm hub --config FILE``) whose tables mirror these
dataclasses; an unknown key is an error, not a silent default. ``check_keys`` is that check for every
table of every file petswarm reads (hub configs, scenarios, experiments).
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import tomllib
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

SYMBOL_US = 16
"""One O-QPSK symbol at 62.5 ksymbol/s; two symbols per byte, so 32 us per byte (250 kbit/s)."""
BYTE_US = 2 * SYMBOL_US
PHY_OVERHEAD_BYTES = 6
"""Preamble (4), SFD (1) and PHR (1) precede every PSDU."""
CHANNELS = range(11, 27)
"""The sixteen 2.4 GHz channels."""


def airtime_us(psdu_len: int) -> int:
    """Time on air of a PPDU carrying ``psdu_len`` bytes: (6 + PSDU) x 32 us."""
    return (PHY_OVERHEAD_BYTES + psdu_len) * BYTE_US


@dataclass
class MacConfig:
    """MAC timing and retry settings (unslotted CSMA-CA, acknowledged unicast)."""

    csma_enabled: bool = True
    min_be: int = 3
    max_be: int = 5
    max_csma_backoffs: int = 4
    unit_backoff_us: int = 20 * SYMBOL_US
    cca_us: int = 8 * SYMBOL_US
    turnaround_us: int = 12 * SYMBOL_US
    ack_enabled: bool = True
    ack_wait_us: int = 54 * SYMBOL_US
    max_frame_retries: int = 3
    queue_limit: int = 32
    """Frames a node may have waiting in its MAC; more are refused (a real MAC has a small queue)."""
    sifs_us: int = 12 * SYMBOL_US
    """macSIFSPeriod (IEEE 802.15.4-2011 5.1.1.3, Table 52): 12 symbols after an MPDU of at most
    ``max_sifs_frame_size`` octets, before the same device starts its next frame."""
    lifs_us: int = 40 * SYMBOL_US
    """macLIFSPeriod: 40 symbols after a longer MPDU."""
    max_sifs_frame_size: int = 18
    """aMaxSIFSFrameSize (Table 51): the largest MPDU followed by a short interframe spacing."""

    def ifs_us(self, mpdu_len: int) -> int:
        """The interframe spacing after an MPDU of ``mpdu_len`` octets (5.1.1.3)."""
        return self.sifs_us if mpdu_len <= self.max_sifs_frame_size else self.lifs_us

    def validate(self) -> None:
        """Raise ValueError on settings outside the standard's ranges."""
        if not 0 <= self.min_be <= self.max_be <= 8:
            raise ValueError("need 0 <= min_be <= max_be <= 8")
        if not 0 <= self.max_csma_backoffs <= 5:
            raise ValueError("max_csma_backoffs must be 0..5")
        if not 0 <= self.max_frame_retries <= 7:
            raise ValueError("max_frame_retries must be 0..7")
        if min(self.unit_backoff_us, self.cca_us, self.turnaround_us, self.ack_wait_us) <= 0:
            raise ValueError("MAC durations must be positive")
        if self.queue_limit < 1:
            raise ValueError("queue_limit must be at least 1")
        if not 0 <= self.sifs_us <= self.lifs_us:
            raise ValueError("need 0 <= sifs_us <= lifs_us")
        if not 0 < self.max_sifs_frame_size <= 127:
            raise ValueError("max_sifs_frame_size must be 1..127 octets")


@dataclass
class RangeConfig:
    """Who can decode whom: a unit disk, as in Cooja, with a success ratio falling towards its edge."""

    tx_range_m: float = 30.0
    interference_range_m: float = 50.0
    """The ``overlap`` reception model's interference and carrier-sense disk; the ``sinr`` model sums every
    transmission's power instead and senses energy against ``ReceptionConfig``'s threshold."""
    success_ratio_tx: float = 1.0
    """Probability that a transmission leaves the sender at all."""
    success_ratio_rx: float = 0.9
    """Reception probability at the edge of tx range; it falls with the square of distance from 1 at 0 m."""

    def validate(self) -> None:
        """Raise ValueError on an inconsistent range model."""
        if not 0 < self.tx_range_m <= self.interference_range_m:
            raise ValueError("need 0 < tx_range_m <= interference_range_m")
        for name in ("success_ratio_tx", "success_ratio_rx"):
            _check_probability(name, getattr(self, name))


@dataclass
class GilbertElliottConfig:
    """Two-state burst loss per directed link, stepped once per frame."""

    p_good_to_bad: float = 0.0
    p_bad_to_good: float = 1.0
    loss_good: float = 0.0
    loss_bad: float = 1.0

    @property
    def enabled(self) -> bool:
        """True when the chain can ever lose a frame."""
        return self.loss_good > 0 or (self.p_good_to_bad > 0 and self.loss_bad > 0)

    def validate(self) -> None:
        """Raise ValueError on a probability outside [0, 1]."""
        for f in dataclasses.fields(self):
            _check_probability(f.name, getattr(self, f.name))


@dataclass
class LossConfig:
    """Loss on top of the range model."""

    base: float = 0.0
    """Independent loss probability of every reception."""
    gilbert_elliott: GilbertElliottConfig = field(default_factory=GilbertElliottConfig)

    def validate(self) -> None:
        """Raise ValueError on a probability outside [0, 1]."""
        _check_probability("base", self.base)
        self.gilbert_elliott.validate()


@dataclass
class PathLossConfig:
    """Log-distance path loss that gives each reception its RSSI and LQI."""

    tx_power_dbm: float = 0.0
    loss_at_1m_db: float = 40.0
    """Free-space loss at 1 m for 2.45 GHz is about 40 dB."""
    exponent: float = 3.0
    shadowing_sigma_db: float = 2.0
    sensitivity_dbm: float = -95.0
    """RSSI that maps to LQI 0 (CC2420 sensitivity); LQI 255 at -20 dBm."""

    def validate(self) -> None:
        """Raise ValueError on a non-physical setting."""
        if self.exponent <= 0 or self.shadowing_sigma_db < 0:
            raise ValueError("path-loss exponent must be > 0 and shadowing sigma >= 0")
        if self.sensitivity_dbm >= -20:
            raise ValueError("sensitivity_dbm must be below -20 dBm")


@dataclass
class CaptureConfig:
    """The ``overlap`` model's capture effect: a frame survives overlap when it is stronger than every
    interferer by a margin. The ``sinr`` model needs no margin: the error rate decides."""

    enabled: bool = False
    margin_db: float = 6.0


RECEPTION_MODELS = ("sinr", "overlap")


@dataclass
class ReceptionConfig:
    """How a receiver decides a frame that other transmissions overlap, and how CCA senses the channel.

    ``sinr`` (the default): the frame's signal against the noise floor plus the summed power of everything else
    on the air at the receiver, piece by piece over its airtime, through the O-QPSK bit error rate of
    IEEE 802.15.4-2006 Annex E (E.4.1.8); CCA mode 1 reports busy above the energy-detection threshold (2006
    6.9.9, 2011 8.2.7). A
    receiver stays synchronised to the first frame it hears unless a stronger one starts (capture).
    ``overlap``: the unit-disk rule (Cooja's UDGM), any overlap inside ``interference_range_m`` collides unless
    ``[capture]`` saves the stronger frame; carrier sense inside the same disk.
    """

    model: str = "sinr"
    ed_threshold_above_sensitivity_db: float = 10.0
    """CCA mode 1's energy-detection threshold over the receiver sensitivity: the standard allows at most
    10 dB (IEEE 802.15.4-2006 6.9.9, 2011 8.2.7)."""

    def validate(self) -> None:
        """Raise ValueError on an unknown model or a threshold outside the standard's range."""
        if self.model not in RECEPTION_MODELS:
            raise ValueError(f"reception model {self.model!r}: one of {', '.join(RECEPTION_MODELS)}")
        if not 0.0 <= self.ed_threshold_above_sensitivity_db <= 10.0:
            raise ValueError("ed_threshold_above_sensitivity_db must be 0..10 dB (IEEE 802.15.4-2006 6.9.9)")


@dataclass
class MediumConfig:
    """Everything that decides a radio outcome."""

    mac: MacConfig = field(default_factory=MacConfig)
    range: RangeConfig = field(default_factory=RangeConfig)
    loss: LossConfig = field(default_factory=LossConfig)
    path_loss: PathLossConfig = field(default_factory=PathLossConfig)
    capture: CaptureConfig = field(default_factory=CaptureConfig)
    reception: ReceptionConfig = field(default_factory=ReceptionConfig)

    def validate(self) -> MediumConfig:
        """Check every section; returns self so it can be chained."""
        self.mac.validate()
        self.range.validate()
        self.loss.validate()
        self.path_loss.validate()
        self.reception.validate()
        return self

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict, as written in run summaries and accepted by ``from_dict``."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> MediumConfig:
        """Build from nested tables; unknown keys raise ValueError naming them."""
        return build_config(cls, data, "").validate()

    @classmethod
    def from_file(cls, path: str | Path) -> MediumConfig:
        """Read a TOML (``.toml``) or JSON file."""
        path = Path(path)
        text = path.read_text()
        data = tomllib.loads(text) if path.suffix == ".toml" else json.loads(text)
        try:
            return cls.from_dict(data.get("medium", data))
        except ValueError as err:
            raise ValueError(f"{path}: {err}") from None


def check_keys(table: Any, known: Iterable[str], where: str) -> None:
    """Refuse a table (``where`` names it, e.g. ``[robots]``) that is not a table or holds a key outside
    ``known``: ValueError naming the table, each unknown key and the nearest known name, then every known one.

    A misspelt key must never fall back silently to a default, so every file petswarm reads goes through here.
    """
    if not isinstance(table, dict):
        raise ValueError(f"{where}: expected a table, got {type(table).__name__}")
    names = sorted(known)
    unknown = [str(key) for key in table if key not in names]
    if not unknown:
        return
    parts = []
    for key in unknown:
        nearest = difflib.get_close_matches(key, names, n=1)
        parts.append(f"unknown key {key!r}" + (f" (did you mean {nearest[0]!r}?)" if nearest else ""))
    raise ValueError(f"{where}: {'; '.join(parts)}; known: {', '.join(names) or 'none'}")


def build_config(cls: type, data: dict[str, Any], where: str) -> Any:
    """A ``cls`` settings dataclass from ``data``, a TOML/JSON table that ``where`` names in errors (e.g.
    ``ir.``): refuses unknown keys and values of the wrong type; nested tables are built the same way.
    """
    table = f"[{where.rstrip('.')}]" if where else "the top level"
    fields = {f.name: f for f in dataclasses.fields(cls)}
    check_keys(data, fields, table)
    kwargs = {}
    for name, value in data.items():
        default = getattr(cls(), name)
        if dataclasses.is_dataclass(default):
            kwargs[name] = build_config(type(default), value, f"{where}{name}.")
        elif isinstance(default, bool) and not isinstance(value, bool):
            raise ValueError(f"{where}{name}: expected true or false")
        else:
            try:
                kwargs[name] = type(default)(value)
            except (TypeError, ValueError):
                raise ValueError(f"{where}{name}: expected {type(default).__name__}, got {value!r}") from None

    return cls(**kwargs)


def _check_probability(name: str, value: float) -> None:
    if not 0.0 <= value <= 1.0:
        raise ValueError(f"{name} must be a probability in [0, 1], got {value}")
