"""The link between a robot's MCU and its 802.15.4 module, sans-IO: when a frame reaches the air, and when
a received frame reaches the middleware.

On the paper's robots the middleware runs on an MCU that talks to the radio module over a UART, so every
frame costs the MCU's processing and its bytes' time on the serial line, one frame at a time. ``SerialLink``
is that timing and nothing else: ``tx_ready(now, size)`` and ``rx_ready(now, size)`` say when; the RF
manager (``petswarm.managers.rf``) waits until then on the loop's clock, so the same delays happen in wall,
model and lockstep time. Random processing times come from the robot's seed.
"""

from __future__ import annotations

from dataclasses import dataclass

from petswarm.draws import Draws

UART_BITS_PER_BYTE = 10
"""Start bit, 8 data bits, stop bit (8N1)."""


@dataclass(frozen=True)
class LinkTiming:
    """A robot's MCU and UART per frame. All zero: no link at all (the ideal robot)."""

    uart_bps: float = 0.0
    """The UART's rate in bits/s; 0: frames pass at once."""
    frame_overhead_bytes: int = 0
    """Bytes the module's serial protocol adds to each payload (API frame header, addresses, checksum)."""
    mcu_min_s: float = 0.0
    mcu_max_s: float = 0.0
    """The MCU's processing of one frame, uniform between the two."""

    def __post_init__(self) -> None:
        if self.uart_bps < 0 or self.frame_overhead_bytes < 0 or not 0 <= self.mcu_min_s <= self.mcu_max_s:
            raise ValueError("a serial link needs uart_bps >= 0, overhead >= 0 and 0 <= mcu_min_s <= mcu_max_s")

    @property
    def ideal(self) -> bool:
        """True when a frame costs nothing on this link."""
        return self.uart_bps == 0 and self.mcu_max_s == 0

    def uart_s(self, payload_bytes: int) -> float:
        """Seconds one frame of ``payload_bytes`` takes on the serial line."""
        if not self.uart_bps:
            return 0.0
        return (payload_bytes + self.frame_overhead_bytes) * UART_BITS_PER_BYTE / self.uart_bps


class SerialLink:
    """When frames pass the MCU and the UART, each direction one frame at a time (sans-IO: times in, times out).

    Times are kept in whole microseconds, as the hub keeps model time: a delay's end then falls on the same
    instant whichever clock runs it (a lockstep node's loop stands on the granted microsecond, a model-time
    loop on the float deadline; their sub-microsecond difference must not decide the order of events).
    """

    def __init__(self, timing: LinkTiming, draws: Draws) -> None:
        self.timing = timing
        self.draws = draws
        self._tx_free_us = 0
        """When the UART's transmit line is free again."""
        self._rx_free_us = 0
        """When the MCU has done with the last received frame (line and processing in series)."""

    def _mcu_us(self) -> int:
        low, high = self.timing.mcu_min_s, self.timing.mcu_max_s
        return _us(float(self.draws.uniform(low, high)) if high > low else low)

    def tx_ready(self, now: float, payload_bytes: int) -> float:
        """A frame the middleware hands over at ``now`` reaches the radio then: the MCU builds it, then it
        waits for the transmit line and crosses it."""
        start = max(_us(now) + self._mcu_us(), self._tx_free_us)
        self._tx_free_us = start + _us(self.timing.uart_s(payload_bytes))
        return self._tx_free_us / 1e6

    def rx_ready(self, now: float, payload_bytes: int) -> float:
        """A frame the radio has since ``now`` (or since the previous one was done, whichever is later)
        reaches the middleware then: it crosses the receive line, then the MCU processes it."""
        start = max(_us(now), self._rx_free_us)
        self._rx_free_us = start + _us(self.timing.uart_s(payload_bytes)) + self._mcu_us()
        return self._rx_free_us / 1e6


def _us(seconds: float) -> int:
    return round(seconds * 1e6)
