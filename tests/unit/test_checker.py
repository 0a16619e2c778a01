"""The run checker finds planted violations and passes a clean record."""

import itertools
import json

from petswarm.lab.checker import check_counters, check_events, check_ir, check_record

GOOD_NODE = {"heard": 10, "delivered": 6, "collided": 2, "lost": 1, "filtered": 1}


def _events(*states: str, stop: bool = True) -> list[dict]:
    events = [{"t": 1.0, "mono": 1.0, "kind": "start", "state": states[0]}]
    for i, (frm, to) in enumerate(itertools.pairwise(states), start=2):
        events.append({"t": float(i), "mono": float(i), "kind": "state", "frm": frm, "to": to})
    if stop:
        events.append({"t": 99.0, "mono": 99.0, "kind": "stop"})
    return events


def _write(run, nodes, events: dict[str, list], ir=None):
    (run / "events").mkdir(parents=True)
    (run / "summary.json").write_text(json.dumps({"nodes": nodes, "ir": ir or {"overlap_episodes": 0}}))
    for name, evs in events.items():
        (run / "events" / f"{name}.jsonl").write_text("".join(json.dumps(e) + "\n" for e in evs))


def test_a_clean_record_passes(tmp_path):
    _write(tmp_path, {"robot-1": GOOD_NODE}, {"robot-1": _events("waiting", "organizing", "slave-driving", "waiting")})
    assert check_record(tmp_path) == []


def test_counters_that_do_not_add_up_are_caught():
    [problem] = check_counters({"robot-2": {**GOOD_NODE, "lost": 5}})
    assert "robot-2" in problem and "heard 10" in problem


def test_incomplete_unordered_and_broken_event_streams_are_caught():
    assert "not 'stop'" in check_events("r", _events("waiting", "organizing", stop=False), finished=True)[0]
    shuffled = _events("waiting", "organizing", "waiting")
    shuffled[2]["t"] = 0.5
    assert any("out of order" in p for p in check_events("r", shuffled, finished=True))
    # a robot that joins a second swarm without leaving the first: slave -> organizing is no arrow
    two_swarms = _events("waiting", "organizing", "slave-driving")
    two_swarms.insert(-1, {"t": 50.0, "mono": 50.0, "kind": "state", "frm": "waiting", "to": "organizing"})
    assert any("while in slave-driving" in p for p in check_events("r", two_swarms, finished=True))
    stuck = check_events("r", _events("waiting", "organizing", "slave-driving"), finished=True)
    assert any("ends in slave-driving" in p for p in stuck)


def test_a_robot_whose_user_cancelled_ends_validly_in_command_waiting():
    cancelled = _events("waiting", "command-waiting", "remote-control", "command-waiting")
    assert check_events("r", cancelled, finished=True) == []


def test_ir_overlap_is_a_violation(tmp_path):
    assert check_ir({"overlap_episodes": 2})
    _write(tmp_path, {"robot-1": GOOD_NODE}, {"robot-1": _events("waiting")}, ir={"overlap_episodes": 1})
    assert any("IR" in p for p in check_record(tmp_path))
