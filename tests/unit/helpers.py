"""Small builders for medium tests: exact settings, hand-placed nodes, run-to-idle."""

from __future__ import annotations

from typing import Any

import numpy as np

from radio_hub.air.mac import BROADCAST, Frame, FrameType
from radio_hub.air.medium import Medium, Output, RadioNode, Reception, TxReport
from radio_hub.config import MediumConfig

PAN = 0x1000
LOSSLESS: dict[str, Any] = {"range": {"success_ratio_rx": 1.0}, "path_loss": {"shadowing_sigma_db": 0.0}}
NO_BACKOFF: dict[str, Any] = {**LOSSLESS, "mac": {"min_be": 0, "max_be": 0}}


def medium(settings: dict[str, Any] | None = None, seed: int = 0) -> Medium:
    """A medium with the given config sections (merged one level deep over lossless defaults)."""
    merged: dict[str, Any] = {k: dict(v) for k, v in LOSSLESS.items()}
    for section, values in (settings or {}).items():
        merged.setdefault(section, {}).update(values)
    return Medium(MediumConfig.from_dict(merged), np.random.default_rng(seed))


def place(m: Medium, short: int, x: float, y: float = 0.0, pan: int = PAN, channel: int = 11) -> str:
    """Attach node ``n<short>`` with short address ``short`` at (x, y)."""
    node_id = f"n{short}"
    m.attach(RadioNode(node_id, 0xAB00 + short, short, pan, channel, (x, y)))
    return node_id


def data(src: int, dst: int = BROADCAST, payload: bytes = b"", pan: int = PAN, seq: int = 1, ack: bool = True) -> bytes:
    """PSDU of a data frame from short address ``src``."""
    return Frame(FrameType.DATA, seq, pan, dst, pan, src, payload, ack and dst != BROADCAST).encode()


def run_to_idle(m: Medium, outputs: list[Output] | None = None) -> list[Output]:
    """Advance event by event until nothing is pending; collect every output."""
    outs = list(outputs or [])
    while (t := m.next_event_us()) is not None:
        outs += m.advance(t)
    return outs


def receptions(outs: list[Output], node_id: str | None = None) -> list[Reception]:
    """The receptions among ``outs`` (at one node if given)."""
    return [o for o in outs if isinstance(o, Reception) and node_id in (None, o.node_id)]


def reports(outs: list[Output]) -> list[TxReport]:
    """The MAC results among ``outs``."""
    return [o for o in outs if isinstance(o, TxReport)]
