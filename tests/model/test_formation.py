"""Network formation (petswarm/managers/formation.py, paper section 3.4, Fig. 8, Tables 1-2) in model time: real robots
on the hub's air, each answering the master's scan, joining query and notice by its own state.

Table 1, may a waiting robot join? Connection first (a robot connected to any user refuses), then the region
(the query's RSSI against the master's minimum). Table 2, which join? All available robots when the user asks
for as many or more, else the closest ones (by the link's RSSI, both ways). The states of Fig. 4 add the
project's rules: a robot in a swarm (slave or master) is no candidate at all; one organizing for another master
refuses as busy.
"""

from __future__ import annotations

import asyncio
import math
from typing import Any

import pytest

from petswarm.managers.formation import WATCH_PERIOD_S, FormationConfig
from petswarm.robot import DEFAULT_PAN

from .harness import LOSSLESS, ModelWorld, run_model_time

MASTER_SILENCE_S = FormationConfig().master_silence_s


async def _ring(w: ModelWorld, distances: dict[int, float]) -> None:
    """Waiting robots around the origin, each at its distance, in different directions."""
    for k, (rid, dist) in enumerate(distances.items()):
        angle = 2 * math.pi * k / len(distances)
        await w.robot(rid, (dist * math.cos(angle), dist * math.sin(angle)))


def _states(w: ModelWorld, rids: Any) -> dict[int, tuple[str, int]]:
    return {rid: (w.status(rid)["state"], w.status(rid)["radio"]["pan_id"]) for rid in rids}


def test_table_1_every_robot_answers_the_scan_and_the_query_by_its_connection_and_region() -> None:
    async def body(w: ModelWorld) -> None:
        await w.robot(1, (0.0, 0.0), user=1)
        await w.robot(2, (1.0, 0.0))  # not connected, inside the region: can join
        await w.robot(3, (15.0, 0.0))  # not connected, outside (about -75 dBm): cannot
        await w.robot(4, (0.0, 1.0), user=2)  # connected to another user, inside: cannot
        await w.robot(5, (0.0, -15.0), user=3)  # connected and outside: connection is checked first
        await w.robot(6, (-2.0, 0.0))  # not connected, inside
        organized = await w.command(1, "organize", count=3)
        # everyone answers the scan, connected or far; each then judges the query itself
        assert organized["candidates"] == [2, 3, 4, 5, 6]
        assert organized["available"] == [2, 6]
        assert organized["refused"] == {"outside_region": [3], "connected_to_user": [4, 5]}
        # Table 2: three asked for, two available: both join, numbered closest first
        assert organized["members"] == [2, 6] and organized["missing"] == []
        pan = organized["pan_id"]
        assert pan != DEFAULT_PAN
        await w.advance(0.3)
        assert _states(w, range(1, 7)) == {
            1: ("master-driving", pan),
            2: ("slave-driving", pan),
            3: ("waiting", DEFAULT_PAN),
            4: ("following", DEFAULT_PAN),
            5: ("following", DEFAULT_PAN),
            6: ("slave-driving", pan),
        }
        assert [w.status(rid)["swarm"]["number"] for rid in (2, 6)] == [1, 2]
        assert all(w.stats()["nodes"][f"robot-{rid}"]["pan_id"] == pan for rid in (1, 2, 6))  # the hub agrees
        for rid in (3, 4, 5):
            assert w.events(rid, "state") == [], rid  # a refusing robot never left its state

    run_model_time(body, config=LOSSLESS)


@pytest.mark.parametrize(("min_rssi_dbm", "far_joins"), [(-70, False), (-90, True)])
def test_table_1_the_region_is_the_masters_rssi_threshold_as_the_waiting_robot_hears_the_query(
    min_rssi_dbm: int, far_joins: bool
) -> None:
    async def body(w: ModelWorld) -> None:
        await w.robot(1, (0.0, 0.0), user=1, formation=FormationConfig(min_rssi_dbm=min_rssi_dbm))
        await w.robot(2, (1.0, 0.0))
        await w.robot(3, (15.0, 0.0))
        organized = await w.command(1, "organize", count=2)
        heard = {rid: [f["rssi_dbm"] for f in w[rid].recent if f["src"] == 1][-1] for rid in (2, 3)}
        assert heard[2] > -70 > heard[3] > -90, heard  # the far robot hears the master between the two thresholds
        assert organized["members"] == ([2, 3] if far_joins else [2])
        assert organized["refused"] == ({} if far_joins else {"outside_region": [3]})

    run_model_time(body, config=LOSSLESS)


def test_table_2_the_closest_join_the_others_go_back_to_waiting_and_disperse_restores_everyone() -> None:
    async def body(w: ModelWorld) -> None:
        await w.robot(1, (0.0, 0.0), user=1)
        await _ring(w, {2: 4.0, 3: 1.0, 4: 5.0, 5: 2.0, 6: 3.0})
        organized = await w.command(1, "organize", count=3)
        assert organized["available"] == [2, 3, 4, 5, 6]
        assert organized["members"] == [3, 5, 6]  # fewer asked for than available: the closest, closest first
        pan = organized["pan_id"]
        await w.advance(0.3)
        for number, rid in enumerate([3, 5, 6], start=1):
            swarm = w.status(rid)["swarm"]
            assert (swarm["master"], swarm["number"], swarm["pan_id"]) == (1, number, pan), swarm
        assert w.status(5)["swarm"]["neighbours"] == [3, 6]  # a column: the members next in number
        for rid in (2, 4):  # available but not chosen: told so, back to waiting on the waiting PAN
            assert _states(w, [rid])[rid] == ("waiting", DEFAULT_PAN)
            assert [(e["to"], e.get("reason")) for e in w.events(rid, "state")] == [
                ("organizing", None),
                ("waiting", "not selected"),
            ]
        dispersed = await w.command(1, "disperse")
        assert dispersed["unconfirmed"] == [] and dispersed["restored"] == "following"
        await w.advance(0.2)
        assert _states(w, range(1, 7)) == {1: ("following", DEFAULT_PAN)} | {
            rid: ("waiting", DEFAULT_PAN) for rid in range(2, 7)
        }
        transitions = [(e["frm"], e["to"]) for e in w.events(3, "state")]
        assert transitions == [("waiting", "organizing"), ("organizing", "slave-driving"), ("slave-driving", "waiting")]
        # Table 2's other row: eight asked for, five available: all five join
        everyone = await w.command(1, "organize", count=8)
        assert sorted(everyone["members"]) == [2, 3, 4, 5, 6] and everyone["pan_id"] != pan

    run_model_time(body, config=LOSSLESS)


def test_the_master_dies_and_every_member_returns_to_waiting_on_its_master_silence_timeout() -> None:
    """The bound tests/process/test_chaos.py once asserted on the wall clock (within the 2 s timeout plus 3 s of
    margin for the machine), here without the margin: a member leaves once it has heard no roster for
    ``master_silence_s``, at its watch's first look past that, and the last roster came at most a roster interval
    before the kill."""

    async def body(w: ModelWorld) -> None:
        await w.robot(1, (0.0, 0.0), user=1)
        await _ring(w, {2: 1.0, 3: 1.5, 4: 2.0})
        organized = await w.command(1, "organize", count=3)
        assert sorted(organized["members"]) == [2, 3, 4]
        await w.advance(1.0)
        killed = w.now
        await w.kill(1)
        await w.advance(MASTER_SILENCE_S + 0.5)
        interval = FormationConfig().roster_interval_s
        for rid in (2, 3, 4):
            assert _states(w, [rid])[rid] == ("waiting", DEFAULT_PAN)
            assert w.status(rid)["ir"]["ir_mode"] == "idle"  # nobody left shining
            left = w.events(rid, "state")[-1]
            assert (left["to"], left["reason"]) == ("waiting", "master silent"), left
            # its watch looks at the deadline every WATCH_PERIOD_S: it leaves at the first look past it
            assert killed + MASTER_SILENCE_S - interval <= left["mono"] <= killed + MASTER_SILENCE_S + WATCH_PERIOD_S

    run_model_time(body, config=LOSSLESS)


def test_robots_already_in_a_swarm_are_no_candidates_of_another_master() -> None:
    async def body(w: ModelWorld) -> None:
        await w.robot(1, (0.0, 0.0), user=1)
        await w.robot(2, (2.0, 0.0), user=2)
        await _ring(w, {3: 1.0, 4: 1.2, 5: 1.4, 6: 1.6})
        first = await w.command(1, "organize", count=2)
        assert first["members"] == [3, 4]
        await w.advance(0.5)
        second = await w.command(2, "organize", count=4)
        # robot 1 (master-driving) and its slaves answer the scan with their state and are never asked
        assert second["candidates"] == [5, 6] and second["refused"] == {}
        assert second["members"] == [6, 5]  # closest to robot 2 first: 2.6 m and 3.4 m
        assert second["pan_id"] != first["pan_id"]
        await w.advance(0.5)
        for rid in (3, 4):
            assert [e["to"] for e in w.events(rid, "state")] == ["organizing", "slave-driving"], rid
            assert w.status(rid)["swarm"]["master"] == 1
        assert w.status(1)["swarm"]["members"] == [3, 4] and w.status(2)["swarm"]["members"] == [6, 5]

    run_model_time(body, config=LOSSLESS)


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("protocol", ["paper", "slotted"])
def test_two_masters_organizing_at_once_end_with_disjoint_members_on_different_pans(protocol: str, seed: int) -> None:
    async def body(w: ModelWorld) -> None:
        await w.robot(1, (0.0, 0.0), user=1)
        await w.robot(2, (3.0, 0.0), user=2)
        for rid, pos in {3: (1.0, 1.0), 4: (2.0, 1.0), 5: (1.0, -1.0), 6: (2.0, -1.0)}.items():
            await w.robot(rid, pos)
        one, two = await asyncio.gather(
            w.command(1, "organize", count=2, protocol=protocol), w.command(2, "organize", count=2, protocol=protocol)
        )
        results = {1: one, 2: two}
        assert not set(one["members"]) & set(two["members"])
        assert one["pan_id"] != two["pan_id"]
        assert one["members"] or two["members"]
        for master, other in ((1, 2), (2, 1)):
            result = results[master]
            # the other master was organizing too: never available to this one
            assert other not in result["available"]
            # a robot this master found busy was organizing for the other master: the other had it available
            assert set(result["refused"].get("busy", [])) <= set(results[other]["available"]), results
        if protocol == "slotted":
            # answers in address slots do not collide, so each master's query reaches every free robot before
            # the other master's notice takes it: both swarms get their two
            assert len(one["members"]) == len(two["members"]) == 2, results
        await w.advance(MASTER_SILENCE_S + 0.5)  # past the members' silence timeout: every robot has settled
        for master, result in results.items():
            for rid in result["members"]:
                swarm = w.status(rid)["swarm"]
                assert swarm is not None and (swarm["master"], swarm["pan_id"]) == (master, result["pan_id"]), rid
                assert _states(w, [rid])[rid] == ("slave-driving", result["pan_id"])
        for rid in set(range(3, 7)) - set(one["members"]) - set(two["members"]):
            assert _states(w, [rid])[rid] == ("waiting", DEFAULT_PAN), rid

    run_model_time(body, config=LOSSLESS, seed=seed)


LOSSY_RING = {2: 1.0, 3: 1.5, 4: 2.0, 5: 2.5}


async def _organize_under_loss(w: ModelWorld, p: float) -> dict[str, Any]:
    await w.robot(1, (0.0, 0.0), user=1)
    await _ring(w, LOSSY_RING)
    w.fault("loss", p=p)
    return await w.command(1, "organize", count=len(LOSSY_RING))


def test_under_30_percent_loss_every_robot_that_answered_the_scan_joins_through_retried_steps() -> None:
    """The query and the notice are steps with an expected set of answers: what a loss takes is asked again."""
    retries = []
    for seed in range(1, 7):

        async def body(w: ModelWorld) -> None:
            organized = await _organize_under_loss(w, 0.3)
            assert organized["members"] == organized["candidates"] and organized["missing"] == [], organized
            retry_events = [e for e in w.events(1, "retry") if e["session"] == organized["session"]]
            assert organized["retries"] == sum(organized["step_retries"].values()) == len(retry_events)
            retries.append(organized["retries"])
            await w.advance(MASTER_SILENCE_S + 0.5)
            pan = organized["pan_id"]
            for rid in LOSSY_RING:  # every robot's belief agrees with the master's
                want = ("slave-driving", pan) if rid in organized["members"] else ("waiting", DEFAULT_PAN)
                assert _states(w, [rid])[rid] == want, (w.seed, rid)

        run_model_time(body, config=LOSSLESS, seed=seed)
    assert sum(retries) >= 3, retries  # the loss really cost answers (seeds 1-6 measured 0-3 retries each)


def test_under_30_percent_loss_the_swarm_still_reaches_its_count() -> None:
    """The scan is retried while fewer free robots answered than requested (the paper's retry rule): a robot
    that missed a scan broadcast (no ACK, 30 % per robot) answers the next one (issue 19)."""
    for seed in range(1, 7):
        organized = run_model_time(lambda w: _organize_under_loss(w, 0.3), config=LOSSLESS, seed=seed)
        assert len(organized["members"]) == len(LOSSY_RING), (seed, organized)
