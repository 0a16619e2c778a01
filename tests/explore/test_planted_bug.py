"""A bug planted through a fixture (never in shipped code) is found by a campaign and shrunk.

The plant: a master that never counts the first member to answer its JoinNotice (its Joined is taken and thrown
away, its retries too), so that member is left out of the roster and leaves; a swarm of one asked for ends with
none. A campaign of at most 200 cases must find it (``organize_completes``), the same case must pass without the
plant, and shrinking must bring it down to at most 3 robots and 2 faults, still failing the same property.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from petswarm.explore.campaign import run_local, run_seed
from petswarm.explore.generate import case, pick_family
from petswarm.explore.runner import run_case
from petswarm.explore.shrink import shrink
from petswarm.managers import exchange, messages

pytestmark = pytest.mark.long
WEIGHTS = {"organize": 1, "drive": 1}


@pytest.fixture
def master_ignores_first_joined(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    plain = exchange.Step.offer

    def offer(self: exchange.Step, incoming: Any, now: float) -> bool:
        if messages.Joined in self.kinds and incoming.message.session_id == self.session:
            ignored = self.__dict__.setdefault("_planted_ignored", incoming.sender)
            if incoming.sender == ignored:
                return True  # taken as this step's answer, and thrown away
        return plain(self, incoming, now)

    monkeypatch.setattr(exchange.Step, "offer", offer)
    yield


def _fails(result: dict[str, Any], prop: str) -> bool:
    return any(f["property"] == prop for f in result["failures"])


@pytest.mark.timeout(600)
def test_a_campaign_finds_and_shrinks_a_master_that_ignores_the_first_notice_answer(
    master_ignores_first_joined: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    prop = "organize_completes"
    found = next((r for r in run_local(1, range(200), 1, WEIGHTS) if _fails(r, prop)), None)
    assert found is not None, "200 cases did not find the planted bug"
    family = pick_family(1, found["index"], WEIGHTS)
    data, seed = case(1, found["index"], family), run_seed(1, found["index"])

    small, result, runs = shrink(data, prop, lambda d: run_case(d, seed, family), budget=40)
    assert _fails(result, prop), result["failures"]
    assert small["robots"]["count"] <= 3, (small["robots"], runs)
    assert len(small.get("faults", [])) <= 2, small.get("faults")

    monkeypatch.undo()  # the same shrunk case without the plant: the property holds
    assert not _fails(run_case(small, seed, family), prop)
