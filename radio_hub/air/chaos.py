"""Faults injected into the emulated air at run time: where a real radio would suffer them.

A fault is a small rule the medium consults at every reception:

- ``loss``: the frame is lost with probability ``p`` (a fade, a noisy spot);
- ``corrupt``: the frame arrives with a bad FCS with probability ``p`` and the receiving MAC drops it
  (counted as lost, like any frame the MAC could not use);
- ``duplicate``: a delivered frame is handed up twice with probability ``p`` (counted ``duplicated``);
- ``delay``: a delivered frame is handed up ``ms`` later, plus a jitter of ``jitter_ms`` (uniform in
  [-jitter_ms, +jitter_ms], or Gaussian with that standard deviation), as if the receiver's radio stack
  (SPI, driver, a busy host) were slow. It acts after the air: the frame's airtime, its outcome, the
  counters and the MAC's ACK are what they would have been, only the hand-up comes later. With jitter,
  frames to one receiver can be handed up out of the order they left the air;
- ``burst``: Gilbert-Elliott loss: a two-state chain per (sender, receiver) link, stepped once per
  reception, good -> bad with ``p_gb``, bad -> good with ``p_bg``, losing ``loss_good`` / ``loss_bad``
  of the frames in each state, so losses come in runs (mean run in the bad state 1/p_bg frames);
- ``partition``: the nodes of ``group`` and those of ``others`` (everyone else when empty) cannot hear
  each other at all: no reception, no interference, no carrier sense;
- ``ir_blind``: a receiving IR module (``node``, or every one) reads full scale on all 12 receivers, as
  under a lamp; ``ir_noise``: extra Gaussian noise of ``sigma`` counts on its readings.

Loss, corruption, duplication, delay and bursts apply to the receptions selected by ``node`` (frames
sent or received by it), ``link`` (from one node to another), ``pan`` (receivers on that PAN) or
``channel``; without a selector they apply to every reception. Pure: the medium passes its RNG, and
draws from it only for the receptions an active fault selects.
"""

from __future__ import annotations

import difflib
import itertools
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

from radio_hub.air.propagation import GilbertElliott
from radio_hub.config import GilbertElliottConfig, check_keys
from radio_hub.lazy import lazy_numpy

if TYPE_CHECKING:
    import numpy as np
else:
    np = lazy_numpy(__name__)

KINDS = ("loss", "corrupt", "duplicate", "delay", "burst", "partition", "ir_blind", "ir_noise")
JITTERS = ("uniform", "gaussian")
MAX_DELAY_MS = 10_000.0
"""Longest extra delay (and jitter) a delay fault takes. A frame ten seconds late is, for every timeout in
the middleware, a lost frame: use a loss fault for that. The bound catches a value typed in microseconds."""
_SELECTORS = {"node", "link", "pan", "channel"}
BURST_DEFAULTS = {"p_gb": 0.05, "p_bg": 0.25, "loss_good": 0.0, "loss_bad": 1.0}
"""A burst fault's defaults: one reception in twenty starts a burst, a burst lasts 4 receptions on
average and loses them all (about 17 % of the frames lost in all); chosen to be seen in a few seconds of
pings, not taken from a measurement."""


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
    ms: float | None = None
    """delay: the extra delay of every selected delivery, in milliseconds."""
    jitter_ms: float | None = None
    """delay: uniform half-width, or Gaussian standard deviation, of the delay's variation (ms)."""
    jitter: str | None = None
    """delay: ``uniform`` or ``gaussian``."""
    p_gb: float | None = None
    """burst: probability that a link in the good state turns bad at a reception."""
    p_bg: float | None = None
    """burst: probability that a link in the bad state turns good at a reception."""
    loss_good: float | None = None
    """burst: loss probability in the good state."""
    loss_bad: float | None = None
    """burst: loss probability in the bad state."""

    def selects(self, sender: str, receiver: str, receiver_pan: int, channel: int) -> bool:
        """True when this (loss, corrupt, duplicate, delay or burst) fault applies to the reception."""
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
        """For the wire and the logs: the id, the kind and the fields of that kind that are set (a partition
        has no ``p``, a loss no ``sigma``)."""
        fields = asdict(self)
        taken = {"fault_id", "kind", *fault_keys(self.kind)}
        return {k: v for k, v in fields.items() if k in taken and v not in (None, ())}

    def delay_us(self, rng: np.random.Generator) -> int:
        """One draw of this delay fault's extra delay; never negative (no frame is handed up before it arrived)."""
        ms, jitter = self.ms or 0.0, self.jitter_ms or 0.0
        if jitter > 0:
            ms += rng.normal(0.0, jitter) if self.jitter == "gaussian" else rng.uniform(-jitter, jitter)
        return max(round(ms * 1000), 0)

    def burst_config(self) -> GilbertElliottConfig:
        """This burst fault's chain parameters."""
        return GilbertElliottConfig(
            float(self.p_gb or 0.0), float(self.p_bg or 0.0), float(self.loss_good or 0.0), float(self.loss_bad or 0.0)
        )


def fault_keys(kind: str) -> tuple[str, ...]:
    """The keys a fault of ``kind`` takes besides ``kind`` (every kind's keys for an unknown kind)."""
    if kind not in KINDS:
        return tuple(sorted({k for known in KINDS for k in fault_keys(known)}))
    return {
        "partition": ("group", "others"),
        "ir_blind": ("node",),
        "ir_noise": ("node", "sigma"),
        "delay": ("ms", "jitter_ms", "jitter", *_SELECTORS),
        "burst": (*BURST_DEFAULTS, *_SELECTORS),
    }.get(kind, ("p", *_SELECTORS))


def parse_fault(fault_id: int, spec: dict[str, Any], where: str = "the fault") -> Fault:
    """A fault from a request map (``where`` names it in errors); ValueError with the reason on anything malformed."""
    kind = spec.get("kind") if isinstance(spec, dict) else None
    check_keys(spec, ("kind", *fault_keys(kind)), where)
    if kind not in KINDS:
        nearest = difflib.get_close_matches(str(kind), KINDS, n=1)
        hint = f" (did you mean {nearest[0]!r}?)" if nearest else ""
        raise ValueError(f"{where}: kind must be one of {', '.join(KINDS)}, not {kind!r}{hint}")
    spec = dict(spec)
    del spec["kind"]
    p = _probability("p", spec.get("p", 1.0))
    _check_selectors(spec)
    link = spec.get("link")
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
        **(_delay_fields(spec) if kind == "delay" else _burst_fields(spec) if kind == "burst" else {}),
    )
    if fault.sigma < 0:
        raise ValueError(f"sigma must be >= 0, got {fault.sigma}")
    if kind == "partition" and not (fault.group and all(fault.group)):
        raise ValueError("a partition needs a group of node ids")

    return fault


MAX_GROUP = 256
"""Node ids a partition's ``group`` or ``others`` lists at most (a swarm of the benches' largest size fits)."""
MAX_NODE_ID = 64
"""Characters of a node id in a selector (as in a key: ``radio_hub.link.keys.check_name``)."""


def _node_id(name: str, value: Any) -> str:
    if not isinstance(value, str) or len(value) > MAX_NODE_ID:  # an empty one is judged where it matters
        raise ValueError(f"{name} must be a node id (at most {MAX_NODE_ID} characters), not {_short(value)}")
    return value


def _short(value: Any) -> str:
    """A value for an error message: its type only, past a few characters (a selector may be megabytes deep)."""
    text = repr(value) if isinstance(value, (str, int, float, bool)) or value is None else ""
    return text if 0 < len(text) <= 40 else f"a {type(value).__name__}"


def _check_selectors(spec: dict[str, Any]) -> None:
    """Each selector's type, range and size, before anything is stored: a fault is kept for the run and sent in
    every stats and chaos answer, so a selector nested 600 deep or megabytes long must never get that far."""
    if spec.get("node") is not None:
        _node_id("node", spec["node"])
    link = spec.get("link")
    if link is not None:
        if not isinstance(link, (list, tuple)) or len(link) != 2:
            raise ValueError("link is a pair of node ids [sender, receiver]")
        for end in link:
            _node_id("link", end)
    for name, low, high in (("pan", 0, 0xFFFF), ("channel", 11, 26)):
        value = spec.get(name)
        if value is not None and (not isinstance(value, int) or isinstance(value, bool) or not low <= value <= high):
            raise ValueError(f"{name} must be an integer in [{low}, {high}], not {_short(value)}")
    for name in ("group", "others"):
        ids = spec.get(name, ())
        if not isinstance(ids, (list, tuple)) or len(ids) > MAX_GROUP:
            raise ValueError(f"{name} must be a list of at most {MAX_GROUP} node ids, not {_short(ids)}")
        for node in ids:
            _node_id(name, node)


def describe_fault(fault: dict[str, Any]) -> str:
    """A fault (``Fault.to_dict`` or a request's ``fault``) in words: ``fault 2: loss p=0.3 on robot-2's frames``."""
    kind = fault.get("kind")
    head = f"fault {fault['fault_id']}: " if "fault_id" in fault else ""
    if kind == "partition":
        others = ", ".join(fault.get("others") or ()) or "everyone else"
        return f"{head}partition {', '.join(fault.get('group') or ())} | {others}"
    if kind in ("ir_blind", "ir_noise"):
        what = "ir-blind" if kind == "ir_blind" else f"ir-noise sigma={fault.get('sigma', 0):g} counts"
        return f"{head}{what} on {fault.get('node') or 'every IR receiver'}"
    if kind == "delay":
        jitter = fault.get("jitter_ms") or 0
        what = f"delay {fault.get('ms', 0):g} ms" + (f" +- {jitter:g} ms ({fault.get('jitter')})" if jitter else "")
    elif kind == "burst":
        what = "burst " + " ".join(f"{k}={fault.get(k, v):g}" for k, v in BURST_DEFAULTS.items())
    else:
        what = f"{kind} p={fault.get('p', 1.0):g}"
    if fault.get("node"):
        where = f"frames to or from {fault['node']}"
    elif fault.get("link"):
        where = f"frames from {fault['link'][0]} to {fault['link'][1]}"
    elif fault.get("pan") is not None:
        where = f"receivers on PAN {fault['pan']:#06x}"
    elif fault.get("channel") is not None:
        where = f"channel {fault['channel']}"
    else:
        where = "every reception"
    return f"{head}{what} on {where}"


def describe_change(entry: dict[str, Any]) -> str:
    """One entry of the chaos log (``Chaos.log``) in words, with its model time."""
    when = f"at model {entry.get('model_us', 0) / 1e6:.3f} s"
    if entry.get("op") == "clear":
        ended = entry.get("ended") or []
        return f"{when}: cleared " + (f"fault {', '.join(map(str, ended))}" if ended else "nothing (no such fault)")
    fault = {k: v for k, v in entry.items() if k not in ("op", "model_us", "wall")}
    return f"{when}: added {describe_fault(fault)}"


def check_timed_fault(spec: Any, where: str) -> None:
    """A fault of a timeline (a scenario's or an experiment's ``[[faults]]``): ``at`` (seconds into the
    traffic phase) and either a fault, as ``parse_fault`` takes it, or ``clear = true`` (with an ``id``,
    else every fault). ValueError naming ``where`` and what is wrong, before any run starts."""
    check_keys(spec, ("at", "clear", "id", "kind", *fault_keys("")), where)
    at = spec.get("at")
    if not isinstance(at, int | float) or isinstance(at, bool) or not at >= 0:
        raise ValueError(f"{where} needs at = seconds (a number >= 0) into the traffic phase, not {at!r}")
    if spec.get("clear", False):
        check_keys(spec, ("at", "clear", "id"), f"{where} (clear)")
        return
    parse_fault(0, {k: v for k, v in spec.items() if k not in ("at", "clear")}, where)


def _number(name: str, value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None


def _probability(name: str, value: Any) -> float:
    p = _number(name, value)
    if not 0.0 <= p <= 1.0:
        raise ValueError(f"{name} must be a probability in [0, 1], got {p}")
    return p


def _delay_fields(spec: dict[str, Any]) -> dict[str, Any]:
    if "ms" not in spec:
        raise ValueError("a delay fault needs ms, the extra delay in milliseconds")
    fields = {"ms": _number("ms", spec["ms"]), "jitter_ms": _number("jitter_ms", spec.get("jitter_ms", 0.0))}
    for name, value in fields.items():
        if not 0.0 <= value <= MAX_DELAY_MS:  # also refuses NaN
            raise ValueError(f"{name} must be in [0, {MAX_DELAY_MS:g}] milliseconds, got {value}")
    jitter = spec.get("jitter", "uniform")
    if jitter not in JITTERS:
        raise ValueError(f"jitter must be one of {JITTERS}, not {jitter!r}")
    if fields["ms"] == 0 and fields["jitter_ms"] == 0:
        raise ValueError("a delay fault with ms = 0 and jitter_ms = 0 delays nothing")
    return {**fields, "jitter": jitter}


def _burst_fields(spec: dict[str, Any]) -> dict[str, Any]:
    fields = {name: _probability(name, spec.get(name, default)) for name, default in BURST_DEFAULTS.items()}
    if fields["p_bg"] == 0 and fields["p_gb"] > 0:
        raise ValueError("p_bg must be > 0: with 0 the first burst never ends (use a loss fault for a dead link)")
    if not GilbertElliottConfig(*fields.values()).enabled:
        raise ValueError("this burst fault never loses a frame: give loss_good > 0, or p_gb > 0 and loss_bad > 0")
    return fields


MAX_FAULTS = 256
"""Active faults at once; another add is refused (each fault costs every delivery a check)."""
LOG_KEPT = 1000
"""Changes the chaos log keeps (the oldest go first); ``Chaos.log_dropped`` counts those gone."""


@dataclass
class Chaos:
    """The active faults and the log of the latest ``LOG_KEPT`` changes."""

    faults: dict[int, Fault] = field(default_factory=dict)
    log: list[dict[str, Any]] = field(default_factory=list)
    log_dropped: int = 0
    _ids: itertools.count = field(default_factory=lambda: itertools.count(1))
    _chains: dict[int, GilbertElliott] = field(default_factory=dict)
    """Each burst fault's chains, one per (sender, receiver) link, all starting in the good state."""

    def add(self, spec: dict[str, Any], now_us: int, wall: float) -> Fault:
        """Activate a fault; ValueError when the spec is malformed or ``MAX_FAULTS`` are active."""
        if len(self.faults) >= MAX_FAULTS:
            raise ValueError(f"{MAX_FAULTS} faults are active already: clear some first")
        fault = parse_fault(next(self._ids), spec)
        self.faults[fault.fault_id] = fault
        if fault.kind == "burst":
            self._chains[fault.fault_id] = GilbertElliott(fault.burst_config())
        self._log({"op": "add", "model_us": now_us, "wall": wall, **fault.to_dict()})
        return fault

    def _log(self, entry: dict[str, Any]) -> None:
        self.log.append(entry)
        if len(self.log) > LOG_KEPT:
            self.log_dropped += len(self.log) - LOG_KEPT
            del self.log[: len(self.log) - LOG_KEPT]

    def clear(self, fault_id: int | None, now_us: int, wall: float) -> list[int]:
        """End one fault (or all when None); the ids that ended."""
        ended = list(self.faults) if fault_id is None else [fault_id] if fault_id in self.faults else []
        for fid in ended:
            del self.faults[fid]
            self._chains.pop(fid, None)
        self._log({"op": "clear", "model_us": now_us, "wall": wall, "ended": ended})
        return ended

    def separated(self, a: str, b: str) -> bool:
        """True when a partition keeps ``a`` and ``b`` from hearing each other."""
        return any(f.kind == "partition" and f.separates(a, b) for f in self.faults.values())

    def ir_faults(self, receiver: str) -> list[Fault]:
        """IR blinding and noise faults that reach this receiving module (all of them without a node)."""
        return [f for f in self.faults.values() if f.kind in ("ir_blind", "ir_noise") and f.node in (None, receiver)]

    def probabilities(self, kind: str, sender: str, receiver: str, receiver_pan: int, channel: int) -> list[float]:
        """The ``p`` of every active fault of ``kind`` that applies to this reception."""
        return [f.p for f in self._selecting(kind, sender, receiver, receiver_pan, channel)]

    def _selecting(self, kind: str, sender: str, receiver: str, receiver_pan: int, channel: int) -> list[Fault]:
        return [
            f for f in self.faults.values() if f.kind == kind and f.selects(sender, receiver, receiver_pan, channel)
        ]

    def burst_lost(self, sender: str, receiver: str, receiver_pan: int, channel: int, rng: np.random.Generator) -> bool:
        """Step the link's chain of every burst fault that selects this reception; True when one loses it.

        Every selecting chain steps, even after another has lost the frame, so each chain sees one step
        per reception and its runs keep their length."""
        lost = False
        for fault in self._selecting("burst", sender, receiver, receiver_pan, channel):
            lost |= self._chains[fault.fault_id].lost((sender, receiver), rng)
        return lost

    def delay_us(self, sender: str, receiver: str, receiver_pan: int, channel: int, rng: np.random.Generator) -> int:
        """Extra hand-up delay of this delivery in microseconds: the delay faults that select it add up."""
        return sum(f.delay_us(rng) for f in self._selecting("delay", sender, receiver, receiver_pan, channel))

    def forget(self, node_id: str) -> None:
        """Drop the burst chains of a node that left (it comes back in the good state, like a new link)."""
        for chain in self._chains.values():
            chain.forget(node_id)
