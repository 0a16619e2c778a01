"""petswarm explore's pure parts: cases drawn from (seed, i) alone and valid scenario files, the TOML writer, the
shrinker's fault units, and every property fed a record that breaks it (and one that keeps it)."""

from __future__ import annotations

import json
import tomllib
from typing import Any

import pytest

from petswarm.explore import properties as P
from petswarm.explore.generate import FAMILIES, FAULT_KINDS, case
from petswarm.explore.main import parse_families
from petswarm.explore.shrink import fault_units, join_units
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


def test_pan_hearing_fails_a_foreign_pan_frame() -> None:
    [violation] = P.pan_hearing(_record(**{"robot-2": [_ev("foreign_pan", 2.5, dst_pan=0x1000, pan=0x2222, src=3)]}))
    assert violation.who == ("robot-2",) and "0x1000" in violation.what


def test_no_contact_fails_two_robots_touching_but_not_the_user_walking_into_one() -> None:
    def tick(t_us: int, collisions: int, x2: float) -> str:
        bodies = [
            {"id": "robot-1", "x": 0.0, "y": 0.0, "radius": 0.15},
            {"id": "robot-2", "x": x2, "y": 0.0, "radius": 0.15},
            {"id": "user", "x": 5.0, "y": 5.0, "radius": 0.25},
        ]
        return json.dumps({"t_us": t_us, "bodies": bodies, "collisions": collisions})

    record = _record()
    record.world_lines = [tick(0, 0, 1.0), tick(20_000, 1, 0.3)]
    [violation] = P.no_contact(record)
    assert violation.who == ("robot-1", "robot-2") and violation.when == 0.02


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
