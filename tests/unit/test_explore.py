"""petswarm explore's pure parts: cases drawn from (seed, i) alone and valid scenario files, the TOML writer, the
shrinker's fault units, and every property fed a record that breaks it (and one that keeps it)."""

from __future__ import annotations

import json
import math
import tomllib
from typing import Any

import pytest

from petswarm.explore import properties as P
from petswarm.explore.generate import FAMILIES, FAULT_KINDS, TURN_ABOUT_S, case, turns_about
from petswarm.explore.main import parse_families
from petswarm.explore.shrink import candidates, fault_units, join_units
from petswarm.explore.toml_out import dumps
from petswarm.scenario import parse


def test_a_case_is_a_pure_function_of_seed_and_index_and_a_valid_scenario_file() -> None:
    assert case(3, 17) == case(3, 17)
    assert case(3, 17) != case(3, 18) and case(3, 17) != case(4, 17)
    seen_families, seen_kinds = set(), set()
    for i in range(200):
        data = case(1, i)
        assert tomllib.loads(dumps(data)) == data  # written back as a file, read back the same
        scenario = parse(data)
        assert 1 <= scenario.robot_count <= 30
        seen_families.add(data["name"].rsplit("-", 1)[1])
        seen_kinds |= {f.get("kind") for f in data.get("faults", [])}
    assert seen_families == set(FAMILIES)
    assert set(FAULT_KINDS) <= seen_kinds


def _angle(a: float, b: float) -> float:
    """``a - b`` wrapped to [-pi, pi)."""
    return (a - b + math.pi) % (2 * math.pi) - math.pi


def test_the_user_turns_to_put_the_robots_on_their_new_side_before_every_change_and_stands() -> None:
    """Following, the robots are behind the way the user last walked; leading, ahead of the way he faces. Each
    request that changes the side comes right after the user turned so that they are on the new side (to
    leading: he faces them; to following: a half turn), and he stands ``TURN_ABOUT_S`` while they turn round."""
    switches = 0
    for i in range(120):
        data = case(1, i, "drive" if i % 2 else "mixed")
        plan = parse(data).user
        assert all(r.at < data["duration_s"] - 2.0 for r in plan.watch)  # the last request (disperse) still comes
        side, since = None, 0.0
        for req in plan.watch:
            want = {"follow": "following", "lead": "leading"}.get(req.request, req.args.get("mode"))
            if want is None or want == side:
                continue
            if side is None:
                assert want == "following"  # the robots stand behind the user
            else:
                switches += 1
                turn_start = max(t for t in plan.turn_starts() if t <= req.at)
                assert req.at - turn_start <= 3.1  # the turn (at most 180 degrees at 60 deg/s or more) just ended
                if want == "leading":  # faces the robots: behind the way he last walked (or faced, at the start)
                    samples = [since + 0.01 * k for k in range(int((turn_start - since) / 0.01) + 1)]
                    walked = [plan.pose_at(t)[2] for t in samples if plan.pose_at(t)[3:5] != (0.0, 0.0)]
                    reference = walked[-1] if walked else plan.pose_at(since)[2]
                else:  # turns his back on the robots ahead of him
                    reference = plan.pose_at(turn_start)[2]
                assert abs(_angle(plan.pose_at(req.at)[2], reference + math.pi)) < math.radians(1.5)
                for dt in (0.0, 1.0, 2.0, TURN_ABOUT_S - 0.1):  # standing while the robots turn round
                    assert plan.pose_at(req.at + dt)[3:] == (0.0, 0.0, 0.0)
            side, since = want, req.at
    assert switches > 20


def test_shrinking_keeps_a_path_with_turn_abouts_whole() -> None:
    turned = case(1, 8, "mixed")
    assert turns_about(turned["user"]["path"])
    assert not {"a straight path", "the user standing"} & {what for what, _ in candidates(turned)}
    plain = case(1, 0, "follow")
    assert not turns_about(plain["user"]["path"]) and "the user standing" in {what for what, _ in candidates(plain)}


def test_the_users_own_robot_never_starts_with_its_back_to_him() -> None:
    for i in range(200):
        data = case(2, i)
        if "owner" not in data.get("user", {}):
            continue
        x, y, heading = data["robots"]["positions"][0]
        off = _angle(math.radians(heading), math.atan2(-y, -x))
        assert abs(off) <= math.pi / 2, (i, data["robots"]["positions"][0])


def test_families_and_weights_are_checked() -> None:
    assert parse_families("organize,drive:2") == {"organize": 3.0, "drive": 2.0}
    with pytest.raises(ValueError, match="no family 'organise'"):
        parse_families("organise")
    with pytest.raises(ValueError, match="weight 0"):
        parse_families("drive:0")


def test_fault_units_keep_each_clear_with_its_fault_and_renumber_after_a_drop() -> None:
    faults = [
        {"at": 1.0, "kind": "loss", "p": 0.3},
        {"at": 1.5, "kind": "kill", "robot": 2},
        {"at": 2.0, "kind": "delay", "ms": 5.0},
        {"at": 3.0, "clear": True, "id": 2},
        {"at": 3.5, "kind": "restart", "robot": 2},
        {"at": 4.0, "clear": True, "id": 1},
    ]
    units = fault_units(faults)
    assert [len(u) for u in units] == [2, 2, 2]
    without_loss = join_units([units[1], units[2]])
    clear = next(f for f in without_loss if f.get("clear"))
    assert clear["id"] == 1  # the delay is the hub's fault 1 now


def _record(family: str = "organize", **events: list[dict[str, Any]]) -> P.Record:
    scenario = parse({"duration_s": 30, "robots": {"count": 3}, "user": {"owner": 1}})
    return P.Record(scenario, family, events=events, summary={"model_time_s": 30.0, "problems": []})


def _state(t: float, frm: str, to: str, **detail: Any) -> dict[str, Any]:
    return {"kind": "state", "mono": t, "t": t, "frm": frm, "to": to, **detail}


def _ev(kind: str, t: float, **detail: Any) -> dict[str, Any]:
    return {"kind": kind, "mono": t, "t": t, **detail}


def test_no_exception_fails_a_crash_and_a_caught_programming_error() -> None:
    crashed = _record()
    crashed.crash = "Traceback ...\nIndexError: list index out of range"
    assert "IndexError" in P.no_exception(crashed)[0].what
    caught = _record(**{"robot-2": [_ev("error", 4.0, where="_slave", error="KeyError: 3")]})
    [violation] = P.no_exception(caught)
    assert violation.who == ("robot-2",) and violation.when == 4.0
    air_fault = _record(**{"robot-2": [_ev("error", 4.0, where="drive_state", error="no ack")]})
    assert P.no_exception(air_fault) == []


def test_one_master_per_robot_fails_two_masters_claiming_one_robot() -> None:
    both = _record(
        **{
            "robot-1": [_ev("organized", 3.0, session=7, members=[3])],
            "robot-2": [_ev("organized", 5.0, session=9, members=[3])],
        }
    )
    [violation] = P.one_master_per_robot(both)
    assert set(violation.who) == {"robot-3", "robot-1", "robot-2"} and violation.when == 5.0
    lost_first = _record(
        **{
            "robot-1": [_ev("organized", 3.0, session=7, members=[3]), _ev("member_lost", 4.0, session=7, member=3)],
            "robot-2": [_ev("organized", 5.0, session=9, members=[3])],
        }
    )
    assert P.one_master_per_robot(lost_first) == []


def test_roster_agreement_fails_a_settled_member_the_roster_does_not_match() -> None:
    broken = _record(
        **{
            "robot-1": [
                _state(3.0, "following", "master-driving", session=7),
                _ev("organized", 3.0, session=7, members=[2]),
            ],
            "robot-2": [_state(3.0, "waiting", "slave-driving", session=7), _state(4.0, "slave-driving", "waiting")],
        }
    )
    violations = P.roster_agreement(broken)
    assert violations and violations[0].who == ("robot-2", "robot-1")
    agreed = _record(
        **{
            "robot-1": [
                _state(3.0, "following", "master-driving", session=7),
                _ev("organized", 3.0, session=7, members=[2]),
            ],
            "robot-2": [_state(3.0, "waiting", "slave-driving", session=7)],
        }
    )
    assert P.roster_agreement(agreed) == []


def test_roster_agreement_gives_a_master_its_rounds_to_drop_a_member_that_left_unheard() -> None:
    def killed_member(dropped_at: float | None) -> P.Record:
        master = [_state(3.0, "following", "master-driving", session=7), _ev("organized", 3.0, session=7, members=[2])]
        if dropped_at is not None:
            master += [
                _ev("member_lost", dropped_at, session=7, member=2),
                _state(dropped_at, "master-driving", "following", session=7),
            ]
        member = [_state(3.0, "waiting", "slave-driving", session=7), _ev("start", 7.1, state="waiting")]
        record = _record(**{"robot-1": master, "robot-2": member})
        record.supervision = [
            {"kind": "died", "process": "robot-2", "mono": 6.5},
            {"kind": "restarted", "process": "robot-2", "mono": 7.1},
        ]
        return record

    # killed at 6.5 s, back in waiting at 7.1 s, dropped after three silent rounds (5.5 s): not a disagreement
    assert P.roster_agreement(killed_member(12.0)) == []
    # never dropped: counted in waiting from 6.5 s to the end of the run
    [violation, *_] = P.roster_agreement(killed_member(None))
    assert violation.who == ("robot-2", "robot-1") and violation.when > 6.5 + P.MEMBER_DROP_S
    # dropped, but later than a master's rounds allow
    assert P.roster_agreement(killed_member(6.5 + P.MEMBER_DROP_S + 3.5))


def _ticks(*at: tuple[float, float, float]) -> list[str]:
    """World ticks every 0.1 s: (from s, to s, the user's distance north of robot-1 at the origin)."""
    lines = []
    for start, end, user_m in at:
        for k in range(round((end - start) / 0.1)):
            t = start + k * 0.1
            bodies = [{"id": "robot-1", "x": 0.0, "y": 0.0}, {"id": "user", "x": 0.0, "y": user_m}]
            lines.append(json.dumps({"t_us": round(t * 1e6), "bodies": bodies}))
    return lines


def test_checker_invariants_pass_an_emergency_only_for_a_user_truly_out_of_reach() -> None:
    ends = "robot-1: ends in emergency, not waiting or driving with its user"

    def lost(user_m: float, then_m: float | None = None, faults: list[dict[str, Any]] | None = None) -> P.Record:
        robot = [
            _state(1.0, "command-waiting", "following", cause="watch"),
            _state(5.85, "following", "emergency", cause="user lost"),
            _ev("watch_request", 11.4, request="organize"),
            _state(11.4, "emergency", "organizing", session=3),
            _state(11.5, "organizing", "master-driving", session=3),
            _state(14.4, "master-driving", "emergency", session=3),  # the dispersal restores it
        ]
        record = _record(**{"robot-1": robot})
        if faults:
            record = P.Record(
                parse({"duration_s": 30, "robots": {"count": 3}, "user": {"owner": 1}, "faults": faults}),
                "follow",
                events=record.events,
                summary=record.summary,
            )
        record.__dict__["invariants"] = [ends]
        record.world_lines = _ticks((0.0, 16.0, user_m), (16.0, 30.0, then_m if then_m is not None else user_m))
        return record

    # lost at 2.6 m (beyond the LF's valid range) and never back within it: what the spec asks for
    assert P.checker_invariants(lost(2.6)) == []
    # a false alarm: lost at 1.5 m
    [violation] = P.checker_invariants(lost(1.5))
    assert "ends in emergency" in violation.what
    # back within reach after the swarm ended (1.2 m for 14 s) and never found
    assert P.checker_invariants(lost(2.6, then_m=1.2))
    # within reach only while it drove the swarm, not in emergency since: not a failure
    record = lost(2.6, then_m=2.6)
    record.world_lines = _ticks((0.0, 12.0, 2.6), (12.0, 14.0, 1.2), (14.0, 30.0, 2.6))
    assert P.checker_invariants(record) == []
    # at 1.5 m, but the wearable link was down (a fault): lost by the spec, found never needed
    wearable = [{"at": 3.0, "kind": "wearable_lost"}]
    assert P.checker_invariants(lost(1.5, faults=wearable)) == []
    # the link back at 16 s with the user at 1.2 m: he should be found
    back = [*wearable, {"at": 16.0, "kind": "wearable_back"}]
    assert P.checker_invariants(lost(1.5, then_m=1.2, faults=back))


def test_no_runaway_fails_a_robot_that_drives_away_from_its_standing_user() -> None:
    robot = [_state(1.0, "command-waiting", "following", cause="watch")]
    record = _record("follow", **{"robot-1": robot})
    # the user stands at 1.0 m until 8 s, then the robot opens the gap at 1 m/s (its user taken for one ahead)
    away = [
        json.dumps(
            {
                "t_us": round(t * 1e5),
                "bodies": [
                    {"id": "robot-1", "x": 0.0, "y": -max(0.0, t / 10 - 8.0)},
                    {"id": "user", "x": 0.0, "y": 1.0},
                ],
            }
        )
        for t in range(0, 120)
    ]
    record.world_lines = away
    [violation, *_] = P.no_runaway(record)
    assert violation.who == ("robot-1",) and violation.when == pytest.approx(8.6)  # 1.60 m, 0.60 m in two seconds
    # the same gap opened while the user walks away (he moves, not the robot): not judged
    walking = [
        json.dumps(
            {
                "t_us": round(t * 1e5),
                "bodies": [
                    {"id": "robot-1", "x": 0.0, "y": 0.0},
                    {"id": "user", "x": 0.0, "y": 1.0 + max(0.0, t / 10 - 8.0)},
                ],
            }
        )
        for t in range(0, 120)
    ]
    record = _record("follow", **{"robot-1": robot})
    record.world_lines = walking
    assert P.no_runaway(record) == []
    # the user turns on the spot as the robot opens the gap (a leading robot's arc): not judged
    record = _record("follow", **{"robot-1": robot})
    record.world_lines = [
        json.dumps(
            {
                **json.loads(line),
                "bodies": [{**b, "yaw": 0.5 * k / 10} if b["id"] == "user" else b for b in json.loads(line)["bodies"]],
            }
        )
        for k, line in enumerate(away)
    ]
    assert P.no_runaway(record) == []
    # waiting for a command, the robot may be carried off (not following or leading): not judged
    record = _record("follow", **{"robot-1": [_state(0.5, "waiting", "command-waiting")]})
    record.world_lines = away
    assert P.no_runaway(record) == []
    # leading at both ends of the window, but driving a swarm (a column's master makes room) in between: not judged
    swarm = [
        _state(1.0, "command-waiting", "leading", cause="watch"),
        _state(7.9, "leading", "organizing"),
        _state(8.0, "organizing", "master-driving"),
        _state(9.5, "master-driving", "leading"),
    ]
    record = _record("follow", **{"robot-1": swarm})
    record.world_lines = away
    [violation, *_] = P.no_runaway(record)
    assert violation.when > 10.5  # judged again only once it has led alone for a whole window


def test_a_master_killed_and_restarted_claims_the_members_of_its_new_swarm() -> None:
    master = [
        _state(3.0, "following", "master-driving", session=7),
        _ev("organized", 3.0, session=7, members=[2]),
        _ev("start", 8.3, state="waiting"),
        _state(8.31, "waiting", "command-waiting"),
        _state(9.4, "command-waiting", "organizing", session=9),
        _state(9.5, "organizing", "master-driving", session=9),
        _ev("organized", 9.5, session=9, members=[2]),
    ]
    member = [
        _state(3.0, "waiting", "slave-driving", session=7),
        _state(8.0, "slave-driving", "waiting"),  # its master went silent
        _state(9.5, "waiting", "slave-driving", session=9),
    ]
    record = _record(**{"robot-1": master, "robot-2": member})
    record.supervision = [
        {"kind": "died", "process": "robot-1", "mono": 6.0},
        {"kind": "restarted", "process": "robot-1", "mono": 8.3},
    ]
    assert (9.5, 30.0, "robot-1", "robot-2", 9) in P.claims(record)  # the new swarm's claim lasts
    assert (3.0, 6.0, "robot-1", "robot-2", 7) in P.claims(record)  # the old one ended with the death
    assert P.roster_agreement(record) == []


def _pan_life(*frames: dict[str, Any]) -> list[dict[str, Any]]:
    """robot-2 starts on PAN 0x1000; the hub applies its swarm's PAN 0x2222 at 3.000000 s (it asked at 2.99 s)."""
    start = _ev("start", 0.0, pan=0x1000, pan_at_us=5_000)
    return [start, _ev("pan", 3.01, pan=0x2222, at_us=3_000_000), *frames]


def test_pan_hearing_keeps_a_frame_received_on_the_old_pan_and_handed_up_late() -> None:
    """Case 130 of seed 1: a delay fault hands a frame the MAC took on the old PAN up 0.18 s after the change."""
    late = _ev("foreign_pan", 3.18, dst_pan=0x1000, pan=0x2222, src=3, seq=9, air_end_us=2_999_000)
    asked = _ev("foreign_pan", 2.995, dst_pan=0x1000, pan=0x2222, src=3, seq=8, air_end_us=2_994_000)
    assert P.pan_hearing(_record(**{"robot-2": _pan_life(asked, late)})) == []


def test_pan_hearing_fails_a_frame_for_a_pan_the_robot_was_not_on_when_it_was_on_the_air() -> None:
    # sent to the old PAN after the hub had applied the new one, handed up at once: the filter let it through
    wrong = _ev("foreign_pan", 3.02, dst_pan=0x1000, pan=0x2222, src=3, seq=9, air_end_us=3_015_000)
    [violation] = P.pan_hearing(_record(**{"robot-2": _pan_life(wrong)}))
    assert violation.who == ("robot-2",) and violation.when == 3.02
    assert violation.what == "heard a frame for PAN 0x1000 (on the air until 3.015000 s) while on 0x2222"
    other = _ev("foreign_pan", 1.0, dst_pan=0x3333, pan=0x1000, src=3, seq=1, air_end_us=990_000)  # never ours
    assert len(P.pan_hearing(_record(**{"robot-2": _pan_life(other)}))) == 1
    restarted = [*_pan_life(), _ev("start", 5.0, pan=0x1000, pan_at_us=5_000_000)]  # a new life: the old PAN gone
    late = _ev("foreign_pan", 5.2, dst_pan=0x2222, pan=0x1000, src=3, seq=2, air_end_us=5_100_000)
    assert len(P.pan_hearing(_record(**{"robot-2": [*restarted, late]}))) == 1
    unknown = _ev("foreign_pan", 2.5, dst_pan=0x1000, pan=0x2222, src=3)  # no air time: cannot be excused
    assert "unknown PAN" in P.pan_hearing(_record(**{"robot-2": [unknown]}))[0].what


def _tick(t_us: int, collisions: int, contacts: list[list[str]], robot_1: tuple[float, float] = (0.0, 0.0)) -> str:
    """A world log line: robot-1 (where given), robot-2 beside it, the user at (0, 3) near a wall at x = -0.2."""
    bodies = [
        {"id": "robot-1", "x": robot_1[0], "y": robot_1[1], "radius": 0.15},
        {"id": "robot-2", "x": 0.3, "y": 0.0, "radius": 0.15},
        {"id": "user", "x": 0.0, "y": 3.0, "radius": 0.25},
    ]
    obstacles = [{"kind": "wall", "x0": -0.2, "y0": 1.0, "x1": -0.2, "y1": 9.0}]
    line: dict[str, Any] = {"t_us": t_us, "bodies": bodies, "obstacles": obstacles, "collisions": collisions}
    if contacts:
        line["contacts"] = contacts
    return json.dumps(line)


def test_no_contact_fails_two_robots_touching_once_per_contact() -> None:
    record = _record()
    pair = [["robot-1", "robot-2"]]
    record.world_lines = [_tick(0, 0, []), _tick(20_000, 1, pair), _tick(40_000, 1, pair), _tick(60_000, 1, [])]
    [violation] = P.no_contact(record)
    assert violation.who == ("robot-1", "robot-2") and violation.when == 0.02


def test_no_contact_names_the_robot_that_touched_an_obstacle_not_the_closest_pair_of_bodies() -> None:
    record = _record()
    record.world_lines = [_tick(0, 0, []), _tick(20_000, 1, [["robot-2", "obstacle-0"]])]
    [violation] = P.no_contact(record)
    assert violation.who == ("robot-2", "obstacle-0")
    assert violation.what == "contact robot-2 / obstacle-0 (wall (-0.2, 1)-(-0.2, 9))"


def test_no_contact_keeps_the_user_walking_into_a_wall_or_a_robot() -> None:
    """The scripted user walks blind: his own contacts are not the robots' (the counter counted them, and the
    judge once blamed the first robot of the closest pair of bodies for the user's wall)."""
    record = _record()
    record.world_lines = [
        _tick(0, 0, []),
        _tick(20_000, 1, [["user", "obstacle-0"]]),
        _tick(40_000, 2, [["robot-1", "user"], ["user", "obstacle-0"]]),
    ]
    assert P.no_contact(record) == []


def test_no_contact_excuses_a_robot_the_user_pushes_into_another_but_not_long_after() -> None:
    pushed = [["robot-1", "robot-2"], ["robot-1", "user"]]
    record = _record()
    record.world_lines = [_tick(0, 0, []), _tick(20_000, 1, [["robot-1", "user"]]), _tick(40_000, 2, pushed)]
    assert P.no_contact(record) == []
    record = _record()
    record.world_lines = [
        _tick(0, 0, []),
        _tick(20_000, 1, [["robot-1", "user"]]),
        _tick(20_000 + 200_000, 2, pushed[:1]),
    ]
    [violation] = P.no_contact(record)
    assert violation.who == ("robot-1", "robot-2")


def test_no_contact_excuses_robots_the_user_presses_through_another() -> None:
    """Seed 1 case 396: the user walks into robot-1, which presses robot-2 against a third (here: the wall does not
    pass a push on)."""
    chain = [["robot-1", "robot-2"], ["robot-1", "user"], ["robot-2", "obstacle-0"]]
    record = _record()
    record.world_lines = [_tick(0, 0, []), _tick(20_000, 3, chain)]
    assert P.no_contact(record) == []
    walled = [["user", "obstacle-0"], ["robot-2", "obstacle-0"]]  # the user at the wall pushes nobody through it
    record = _record()
    record.world_lines = [_tick(0, 0, []), _tick(20_000, 2, walled)]
    [violation] = P.no_contact(record)
    assert violation.who == ("robot-2", "obstacle-0")


def test_no_contact_takes_a_pair_that_parts_for_a_tick_as_one_contact_going_on() -> None:
    """Seed 1 case 193: a robot the user pressed against another slides along it after the push; the pair parts for
    one tick as the world pushes them apart and touches again: the contact that began under the push, going on."""
    pair, pushed = [["robot-1", "robot-2"]], [["robot-1", "robot-2"], ["robot-1", "user"]]
    record = _record()
    record.world_lines = [
        _tick(0, 0, []),
        _tick(20_000, 2, pushed),
        *(_tick(20_000 * k, 2, pair) for k in range(2, 20)),
        _tick(400_000, 2, []),
        _tick(420_000, 3, pair),
        _tick(440_000, 3, [], robot_1=(-0.02, 0.0)),
        _tick(700_000, 4, pair),  # parted (2 cm) for a quarter second: a new contact
    ]
    [violation] = P.no_contact(record)
    assert violation.who == ("robot-1", "robot-2") and violation.when == 0.7


def test_no_contact_takes_a_pair_left_pressed_together_as_one_contact_however_long_it_flickers() -> None:
    """Seed 1 case 193: after the push the two robots stay side by side, exactly touching (the world pushed them
    apart to that), and drop out of the contact list and back as one slides along the other: never parted."""
    pair, pushed = [["robot-1", "robot-2"]], [["robot-1", "robot-2"], ["robot-1", "user"]]
    flicker = [_tick(20_000 * k, 2, [] if 15 <= k < 30 else pair, robot_1=(0.001 * (k % 2), 0.0)) for k in range(2, 60)]
    record = _record()
    record.world_lines = [_tick(0, 0, []), _tick(20_000, 2, pushed), *flicker]
    assert P.no_contact(record) == []


def test_no_contact_fails_a_contact_a_world_log_does_not_name() -> None:
    record = _record()
    record.world_lines = [_tick(0, 0, []), _tick(20_000, 1, [])]
    [violation] = P.no_contact(record)
    assert "names no pair" in violation.what and violation.when == 0.02


def test_no_contact_counts_a_pair_touching_on_as_one_contact_though_the_world_counts_it_again() -> None:
    """A robot killed while touching another keeps its body, taken out of the world and put back: the world counts
    the pair again; the log shows one contact going on (seed 3 case 100, with the user)."""
    record = _record()
    pair = [["robot-1", "robot-2"]]
    record.world_lines = [_tick(0, 0, []), _tick(20_000, 1, pair), _tick(40_000, 2, pair)]
    [violation] = P.no_contact(record)
    assert violation.when == 0.02


def test_organize_completes_fails_an_organize_with_no_member_after_the_faults() -> None:
    events = {
        "robot-1": [
            _state(1.0, "command-waiting", "following"),
            _ev("watch_request", 10.0, request="organize", robots=1),
            _state(10.0, "following", "organizing", session=5),
            _ev("watch_organized", 10.7, members=[]),
        ],
        "robot-2": [],
    }
    [violation] = P.organize_completes(_record(**events))
    assert violation.when == 10.0 and "did not complete" in violation.what
    events["robot-1"][-1] = _ev("watch_organized", 10.2, members=[2])
    assert P.organize_completes(_record(**events)) == []


def test_disperse_returns_waiting_fails_a_member_left_driving() -> None:
    events = {
        "robot-1": [
            _state(3.0, "following", "master-driving", session=5),
            _ev("watch_request", 10.0, request="disperse"),
            _state(10.1, "master-driving", "following", session=5),
        ],
        "robot-2": [_state(3.0, "organizing", "slave-driving", session=5)],
    }
    [violation] = P.disperse_returns_waiting(_record(**events))
    assert violation.who == ("robot-2",)
    events["robot-2"].append(_state(10.1, "slave-driving", "waiting", session=5))
    assert P.disperse_returns_waiting(_record(**events)) == []


def test_token_regenerates_fails_members_without_ir_fixes_after_a_member_died() -> None:
    members = {f"robot-{k}": [_state(3.0, "organizing", "slave-driving", session=5)] for k in (2, 3)}
    record = _record(**members)
    record.supervision = [{"kind": "died", "process": "robot-3", "mono": 10.0}]
    [violation] = P.token_regenerates(record)
    assert violation.who == ("robot-2", "robot-3")
    members["robot-2"].append(_ev("ir_fix", 15.0, holder=1))
    assert P.token_regenerates(_with(record, members)) == []


def _with(record: P.Record, events: dict[str, list[dict[str, Any]]]) -> P.Record:
    record.events = events
    return record


def test_checker_invariants_fail_a_robot_left_in_a_swarm(tmp_path: Any) -> None:
    run = tmp_path / "run"
    (run / "events").mkdir(parents=True)
    (run / "events" / "robot-1.jsonl").write_text(
        '{"kind": "start", "t": 0, "mono": 0}\n'
        '{"kind": "state", "t": 1, "mono": 1, "frm": "waiting", "to": "slave-driving"}\n'
        '{"kind": "stop", "t": 2, "mono": 2}\n'
    )
    (run / "summary.json").write_text('{"nodes": {}, "problems": []}')
    record = P.Record.read(run, parse({"robots": {"count": 1}}), "organize")
    [violation] = P.checker_invariants(record)
    assert "ends in slave-driving" in violation.what


def test_every_property_names_its_families_and_kind() -> None:
    for prop in P.PROPERTIES.values():
        assert prop.kind in ("safety", "liveness") and set(prop.families) <= set(FAMILIES) and prop.doc
