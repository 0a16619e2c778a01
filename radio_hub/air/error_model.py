"""Bit and frame error rates of the 2.4 GHz O-QPSK PHY, from the signal-to-interference-plus-noise ratio.

IEEE 802.15.4-2006 Annex E (E.4.1.8, Figure E.2) gives the bit error rate of the 2.4 GHz O-QPSK PHY over an
AWGN channel as

    BER(SINR) = (8/15) (1/16) sum_{k=2}^{16} (-1)^k C(16, k) exp(20 SINR (1/k - 1))

with SINR as a power ratio; interference is treated as further Gaussian noise. A frame piece of ``n`` bits at
one SINR survives with (1 - BER)^n. The noise floor is derived from the receiver's sensitivity as the standard
defines it (2006 6.5.3.3, 2011 10.3.4): the input power at which the packet error rate of a 20-octet PSDU is 1 %. Pure.
"""

from __future__ import annotations

import math
from functools import cache

BITS_PER_US = 0.25
"""250 kbit/s: a PPDU's bits over a stretch of its airtime."""
SENSITIVITY_PSDU_OCTETS = 20
SENSITIVITY_PER = 0.01
_TERMS = tuple(((-1) ** k * math.comb(16, k), 20.0 * (1.0 / k - 1.0)) for k in range(2, 17))


def bit_error_rate(sinr: float) -> float:
    """Annex E's O-QPSK bit error rate at the linear ratio ``sinr``, clamped to [0, 0.5] (the alternating sum
    loses a few ulps to cancellation near SINR 0)."""
    # fsum is exactly rounded, so the result does not depend on how the terms are handed to it
    total = math.fsum([c * math.exp(a * sinr) for c, a in _TERMS])
    return min(max(total * (8.0 / 15.0) / 16.0, 0.0), 0.5)


def piece_success(sinr: float, bits: float) -> float:
    """The probability that ``bits`` bits received at ``sinr`` all arrive intact: (1 - BER)^bits."""
    return (1.0 - bit_error_rate(sinr)) ** bits


@cache
def clean_sinr() -> float:
    """The lowest SINR (linear) at which 1 - BER rounds to exactly 1.0 in double precision.

    Above it a piece of a frame cannot fail in floating point, so the medium skips the arithmetic and the
    random draw there without changing any outcome (found by bisection; BER falls monotonically with SINR)."""
    low, high = 0.0, 100.0
    for _ in range(200):
        mid = (low + high) / 2
        if 1.0 - bit_error_rate(mid) == 1.0:
            high = mid
        else:
            low = mid
    return high


@cache
def sensitivity_snr_db() -> float:
    """The SNR (dB) at which a 20-octet PSDU (with its 6-octet PHY header) fails 1 % of the time."""
    bits = (SENSITIVITY_PSDU_OCTETS + 6) * 8
    low, high = -10.0, 20.0
    for _ in range(200):
        mid = (low + high) / 2
        if 1.0 - piece_success(10 ** (mid / 10), bits) > SENSITIVITY_PER:
            low = mid
        else:
            high = mid
    return high


def noise_floor_dbm(sensitivity_dbm: float) -> float:
    """The receiver's noise power that makes ``sensitivity_dbm`` its sensitivity in the standard's sense."""
    return sensitivity_dbm - sensitivity_snr_db()


def dbm_to_mw(dbm: float) -> float:
    """Power in milliwatts."""
    return 10.0 ** (dbm / 10.0)
