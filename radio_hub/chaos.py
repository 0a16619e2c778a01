"""Faults injected into the emulated air at run time: where a real radio would suffer them.

A fault is a small rule the medium consults at every reception:

- ``loss``: the frame is lost with probability ``p`` (a fade, a noisy spot);
- ``corrupt``: the frame arrives with a bad FCS with probability ``p`` and the receiving MAC drops it
  (counted as lost, like any frame the MAC could not use);
- ``duplicate``: a delivered frame is handed up twice with probability ``p`` (counted ``duplicated``);
- ``partition``: the nodes of ``group`` and those of ``others`` (everyone else when empty) cannot hear
  each other at all: no reception, no interference, no carrier sense;
- ``ir_blind``: a receiving IR module (``node``, or every one) reads full scale on all 12 receivers, as
  under a lamp; ``ir_noise``: extra Gaussian noise of ``sigma`` counts on its readings.

Loss, corruption and duplication apply to the receptions selected by ``node`` (frames sent or
received by it), ``link`` (from one node to another), ``pan`` (receivers on that PAN) or ``channel``;
without a selector they apply to every reception. Pure: the medium passes its RNG.
"""

from __future__ import annotations

import itertools
from dataclasses import asdict, dataclass, field
from typing import Any

KINDS = ("loss", "corrupt", "duplicate", "partition", "ir_blind", "ir_noise")


@dataclass(frozen=True)
class Fault:
    """One active fault."""

    fault_id: int
    kind: str
    p: float = 1.0
    node: str | None = None
    link: tuple[str, str] | None = None
    pan: int | None = None
    channel: int | None = None
    group: tuple[str, ...] = ()
    others: tuple[str, ...] = ()
    sigma: float = 0.0
    """ir_noise: standard deviation of the extra noise, in ADC counts."""

    def selects(self, sender: str, receiver: str, receiver_pan: int, channel: int) -> bool:
        """True when this (loss, corrupt or duplicate) fault applies to the reception."""
        if self.node is not None and self.node not in (sender, receiver):
            return False
        if self.link is not None and self.link != (sender, receiver):
            return False
        if self.pan is not None and self.pan != receiver_pan:
            return False
        return self.channel is None or self.channel == channel

    def separates(self, a: str, b: str) -> bool:
        """True when this partition puts ``a`` and ``b`` on different sides."""

        def side(n: str) -> int | None:
            if n in self.group:
                return 0
            if not self.others or n in self.others:
                return 1
            return None

        sa, sb = side(a), side(b)
        return sa is not None and sb is not None and sa != sb

    def to_dict(self) -> dict[str, Any]:
        """For the wire and the logs (only the fields that are set)."""
        return {k: v for k, v in asdict(self).items() if v not in (None, ())}


def parse_fault(fault_id: int, spec: dict[str, Any]) -> Fault:
    """A fault from a request map; ValueError with the reason on anything malformed."""
    spec = dict(spec)
    kind = spec.pop("kind", None)
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, not {kind!r}")
    allowed = {
        "partition": {"group", "others"},
        "ir_blind": {"node"},
        "ir_noise": {"node", "sigma"},
    }.get(kind, {"p", "node", "link", "pan", "channel"})
    unknown = set(spec) - allowed
    if unknown:
        raise ValueError(f"a {kind} fault takes {sorted(allowed)}, not {sorted(unknown)}")
    p = float(spec.get("p", 1.0))
    if not 0.0 <= p <= 1.0:
        raise ValueError(f"p must be a probability in [0, 1], got {p}")
    link = spec.get("link")
    if link is not None and (len(link) != 2 or not all(isinstance(n, str) for n in link)):
        raise ValueError("link is a pair of node ids [sender, receiver]")
    fault = Fault(
        fault_id,
        kind,
        p,
        spec.get("node"),
        tuple(link) if link else None,
        spec.get("pan"),
        spec.get("channel"),
        tuple(spec.get("group", ())),
        tuple(spec.get("others", ())),
        float(spec.get("sigma", 0.0)),
    )
    if fault.sigma < 0:
        raise ValueError(f"sigma must be >= 0, got {fault.sigma}")
    if kind == "partition" and not (fault.group and all(fault.group)):
        raise ValueError("a partition needs a group of node ids")

    return fault


@dataclass
class Chaos:
    """The active faults and the log of every change."""

    faults: dict[int, Fault] = field(default_factory=dict)
    log: list[dict[str, Any]] = field(default_factory=list)
    _ids: itertools.count = field(default_factory=lambda: itertools.count(1))

    def add(self, spec: dict[str, Any], now_us: int, wall: float) -> Fault:
        """Activate a fault; ValueError when the spec is malformed."""
        fault = parse_fault(next(self._ids), spec)
        self.faults[fault.fault_id] = fault
        self.log.append({"op": "add", "model_us": now_us, "wall": wall, **fault.to_dict()})
        return fault

    def clear(self, fault_id: int | None, now_us: int, wall: float) -> list[int]:
        """End one fault (or all when None); the ids that ended."""
        ended = list(self.faults) if fault_id is None else [fault_id] if fault_id in self.faults else []
        for fid in ended:
            del self.faults[fid]
        self.log.append({"op": "clear", "model_us": now_us, "wall": wall, "ended": ended})
        return ended

    def separated(self, a: str, b: str) -> bool:
        """True when a partition keeps ``a`` and ``b`` from hearing each other."""
        return any(f.kind == "partition" and f.separates(a, b) for f in self.faults.values())

    def ir_faults(self, receiver: str) -> list[Fault]:
        """IR blinding and noise faults that reach this receiving module (all of them without a node)."""
        return [f for f in self.faults.values() if f.kind in ("ir_blind", "ir_noise") and f.node in (None, receiver)]

    def probabilities(self, kind: str, sender: str, receiver: str, receiver_pan: int, channel: int) -> list[float]:
        """The ``p`` of every active fault of ``kind`` that applies to this reception."""
        return [
            f.p for f in self.faults.values() if f.kind == kind and f.selects(sender, receiver, receiver_pan, channel)
        ]
