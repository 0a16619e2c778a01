"""``petswarm.draws.Draws`` draws what ``numpy.random.default_rng`` draws, number for number."""

from __future__ import annotations

import numpy as np
import pytest

from petswarm.draws import Draws

ENTROPIES = [0, 1, 7, [7, 3], [0, 0], [3, 1], [1, 200], [2**32 + 5, 9], [2**64 - 1, 2**40], [1, 2, 3, 4, 5, 6]]


@pytest.mark.parametrize("entropy", ENTROPIES)
def test_uniform_draws_are_numpys(entropy: int | list[int]) -> None:
    ours, numpys = Draws(entropy), np.random.default_rng(entropy)
    for low, high in [(0.0, 1.0), (0.5, 1.5), (0.002, 0.02), (0.0, 2.5), (-3.0, 3.0)] * 20:
        assert ours.uniform(low, high) == float(numpys.uniform(low, high))


@pytest.mark.parametrize("entropy", ENTROPIES)
def test_interleaved_integers_and_uniforms_are_numpys(entropy: int | list[int]) -> None:
    """The 32-bit draws share numpy's buffered half of a 64-bit draw, across uniform calls in between."""
    ours, numpys = Draws(entropy), np.random.default_rng(entropy)
    ranges = [(1, 0xFFFF), (0x1000, 0xFF00), (0, 2), (5, 6), (0, 3), (0, 2**32), (-10, 10), (0, 2**31 + 7)]
    for step in range(300):
        low, high = ranges[step % len(ranges)]
        assert ours.integers(low, high) == int(numpys.integers(low, high))
        if step % 3 == 0:
            assert ours.uniform(0.0, 1.0) == float(numpys.uniform(0.0, 1.0))


def test_rejection_sampling_is_numpys() -> None:
    """A range just over 2**31 rejects about half the raw draws: the redraws must be numpy's too."""
    ours, numpys = Draws([4, 2]), np.random.default_rng([4, 2])
    assert [ours.integers(0, 2**31 + 1) for _ in range(500)] == numpys.integers(0, 2**31 + 1, size=500).tolist()


def test_bad_ranges_are_refused() -> None:
    draws = Draws(1)
    with pytest.raises(ValueError):
        draws.integers(5, 5)
    with pytest.raises(ValueError):
        draws.integers(0, 2**32 + 1)
    with pytest.raises(ValueError):
        Draws([-1])
