"""A robot's random draws without numpy: numpy's ``default_rng(seed)`` (SeedSequence and PCG64) in plain Python.

A robot process draws a few numbers a second (ping jitter, a session id, a PAN ID, a retry delay), and
``numpy.random`` alone added about 3.4 MB to every robot process's resident memory. ``Draws`` gives the very
numbers ``numpy.random.default_rng(entropy)`` gives for the calls robots make (``uniform`` and ``integers``
below 2**32), so a seed fixes the same run whichever generator makes it; tests/unit/test_draws.py checks
that against numpy draw for draw.
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import cycle

_M32 = 0xFFFF_FFFF
_M64 = 0xFFFF_FFFF_FFFF_FFFF
_M128 = (1 << 128) - 1
_PCG_MULT = 0x2360_ED05_1FC6_5DA4_4385_DF64_9FCC_F645
# SeedSequence's hashing constants (O'Neill's seed_seq_fe, as numpy.random.bit_generator has them)
_INIT_A, _MULT_A = 0x43B0_D7E5, 0x931E_8875
_INIT_B, _MULT_B = 0x8B51_F9DD, 0x58F3_8DED
_MIX_L, _MIX_R = 0xCA01_F9DD, 0x4973_F715
_POOL = 4


class Draws:
    """The draws of ``numpy.random.default_rng(entropy)``: ``uniform`` and ``integers`` (a range below 2**32)."""

    def __init__(self, entropy: int | Sequence[int]) -> None:
        words = _seed_words(entropy)
        state = _generate_state(_mix_pool(words), 8)
        seed = (state[1] << 96) | (state[0] << 64) | (state[3] << 32) | state[2]
        seq = (state[5] << 96) | (state[4] << 64) | (state[7] << 32) | state[6]
        self._inc = ((seq << 1) | 1) & _M128
        self._state = 0
        self._step()
        self._state = (self._state + seed) & _M128
        self._step()
        self._half: int | None = None  # numpy keeps the high half of a 64-bit draw for the next 32-bit one

    def _step(self) -> None:
        self._state = (self._state * _PCG_MULT + self._inc) & _M128

    def _next64(self) -> int:
        self._step()
        xored = ((self._state >> 64) ^ self._state) & _M64
        rot = self._state >> 122
        return ((xored >> rot) | (xored << (-rot & 63))) & _M64

    def _next32(self) -> int:
        if self._half is not None:
            half, self._half = self._half, None
            return half
        value = self._next64()
        self._half = value >> 32
        return value & _M32

    def random(self) -> float:
        """A float in [0, 1)."""
        return (self._next64() >> 11) * (1.0 / 9007199254740992.0)

    def uniform(self, low: float = 0.0, high: float = 1.0) -> float:
        """A float in [low, high), as ``Generator.uniform(low, high)``."""
        return low + (high - low) * self.random()

    def integers(self, low: int, high: int) -> int:
        """An int in [low, high), as ``Generator.integers(low, high)`` (Lemire's method on 32-bit draws)."""
        span = high - 1 - low
        if span < 0:
            raise ValueError(f"integers: low {low} must be below high {high}")
        if span > _M32:
            raise ValueError("integers: ranges of 2**32 and more are not drawn here")
        if span == 0:
            return low
        if span == _M32:
            return low + self._next32()
        excl = span + 1
        m = self._next32() * excl
        if (m & _M32) < excl:
            threshold = (_M32 - span) % excl
            while (m & _M32) < threshold:
                m = self._next32() * excl
        return low + (m >> 32)


def _seed_words(entropy: int | Sequence[int]) -> list[int]:
    """The entropy as 32-bit words, least significant first per number (numpy's coercion)."""
    numbers = [entropy] if isinstance(entropy, int) else list(entropy)
    words: list[int] = []
    for number in numbers:
        if number < 0:
            raise ValueError(f"seed entropy must not be negative, got {number}")
        words.append(number & _M32)
        number >>= 32
        while number:
            words.append(number & _M32)
            number >>= 32
    return words


def _mix_pool(words: list[int]) -> list[int]:
    """SeedSequence's pool of four words, mixed from the entropy."""
    hash_const = _INIT_A

    def hashmix(value: int) -> int:
        nonlocal hash_const
        value ^= hash_const
        hash_const = (hash_const * _MULT_A) & _M32
        value = (value * hash_const) & _M32
        return value ^ (value >> 16)

    def mix(x: int, y: int) -> int:
        result = (_MIX_L * x - _MIX_R * y) & _M32
        return result ^ (result >> 16)

    pool = [hashmix(words[i] if i < len(words) else 0) for i in range(_POOL)]
    for src in range(_POOL):
        for dst in range(_POOL):
            if src != dst:
                pool[dst] = mix(pool[dst], hashmix(pool[src]))
    for word in words[_POOL:]:
        for dst in range(_POOL):
            pool[dst] = mix(pool[dst], hashmix(word))
    return pool


def _generate_state(pool: list[int], n_words: int) -> list[int]:
    """SeedSequence.generate_state: ``n_words`` 32-bit words from the pool."""
    hash_const = _INIT_B
    out = []
    for word in cycle(pool):
        if len(out) == n_words:
            break
        value = word ^ hash_const
        hash_const = (hash_const * _MULT_B) & _M32
        value = (value * hash_const) & _M32
        out.append(value ^ (value >> 16))
    return out
