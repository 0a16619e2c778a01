"""The vocabulary the robot's sans-IO cores share: the event a received swarm message makes and the actions
that more than one core returns (put a message on the air, switch the IR module, record an event).

A core (``formation_core``, ``token_schedule``, ``driving_core``, ``surround_core``) returns these as plain
values; its runtime carries them out. Each runtime serves one core, so a field one core never sets keeps its
default there. Pure: no clock, no radio, no asyncio.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from petswarm.managers.messages import SwarmMessage
from radio_hub.values import RxFrame


@dataclass(frozen=True)
class Incoming:
    """A decoded swarm message with the frame that carried it."""

    message: SwarmMessage
    rx: RxFrame
    received_at: float
    """Seconds on the robot's clock when it got the message (the runtime reads its clock; a core never does)."""

    @property
    def sender(self) -> int:
        """Short address of the sender."""
        return self.rx.frame.src


@dataclass(frozen=True)
class Send:
    """Put ``message`` on the air to ``dst``.

    ``dst_pan``: the PAN to address (None: the robot's own). ``where``: when set, a failure to send (the hub
    away) is recorded as an ``error`` event under this name and the action counts as done; when None it is
    raised into the core's procedure. ``ref``: when set, the runtime reports ``sent(ref, now)`` (or
    ``failed``) back to the core."""

    dst: int
    message: SwarmMessage
    dst_pan: int | None = None
    ack: bool = True
    where: str | None = None
    ref: int | None = None


@dataclass(frozen=True)
class SetIrMode:
    """Switch the IR module to ``mode`` (``transmit``, ``receive``, ``idle``, ``beacon``); with a ``ref``, the
    runtime reports ``mode_set(ref, now)`` back once the module has it (at once when it already was in it)."""

    mode: str
    ref: int | None = None


@dataclass(frozen=True)
class Log:
    """Record an event of ``kind`` with ``detail`` in the robot's event log."""

    kind: str
    detail: dict[str, Any] = field(default_factory=dict)
