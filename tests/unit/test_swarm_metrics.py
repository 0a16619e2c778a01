"""The swarm's shape metrics (petswarm/lab/metrics.py): connected within sight, and its extent r."""

from __future__ import annotations

import math

import numpy as np

from petswarm.lab.metrics import is_connected, swarm_extent


def _connected_by_search(positions: np.ndarray, sight_m: float) -> bool:
    """Depth-first search over pairs closer than ``sight_m``: the definition, one robot at a time."""
    n, seen, frontier = len(positions), {0}, [0]
    while frontier:
        i = frontier.pop()
        for j in range(n):
            if j not in seen and math.dist(positions[i], positions[j]) < sight_m:
                seen.add(j)
                frontier.append(j)
    return len(seen) == n


def test_a_chain_is_connected_while_every_link_is_within_sight_and_not_once_one_is_out() -> None:
    chain = np.array([[0.0, 0.0], [0.9, 0.0], [1.8, 0.0], [2.7, 0.0]])
    assert is_connected(chain, 1.0)
    assert not is_connected(chain, 0.9)  # closer than sight, strictly
    broken = chain.copy()
    broken[2:] += 0.2
    assert not is_connected(broken, 1.0)
    assert is_connected(chain[:1], 0.0)  # one robot is a swarm of its own


def test_connected_agrees_with_a_search_on_random_swarms() -> None:
    rng = np.random.default_rng(3)
    verdicts = []
    for _ in range(400):
        n = int(rng.integers(2, 25))
        positions = rng.uniform(0.0, 0.7 * math.sqrt(n), size=(n, 2))  # about as often connected as not
        verdict = is_connected(positions, 1.0)
        assert verdict == _connected_by_search(positions, 1.0)
        verdicts.append(verdict)
    assert 0.1 < np.mean(verdicts) < 0.9  # both answers were really tried


def test_the_extent_is_the_rms_distance_to_the_centroid() -> None:
    ring = np.array([[math.cos(a), math.sin(a)] for a in np.linspace(0, 2 * math.pi, 8, endpoint=False)])
    assert math.isclose(swarm_extent(0.65 * ring + (3.0, -1.0)), 0.65)
