"""World frames as ``petswarm watch`` takes them: checking, replay files, the replay clock."""

import json

import pytest

from petswarm.lab.watch_frames import DEFAULT_RADIUS_M, ReplayClock, check_frame, parse_replay, with_events_since


def _frame(t_us: int = 0, **extra) -> dict:
    robot = {"id": "2", "kind": "robot", "x": 1.0, "y": -0.5, "yaw": 0.3, "pan_id": 0x1000, "ir": "transmit"}
    return {"v": 1, "t_us": t_us, "bodies": [robot], **extra}


def test_a_frame_gets_defaults_and_loses_unknown_fields():
    frame = check_frame({**_frame(5), "future_field": 1})
    assert "future_field" not in frame
    body = frame["bodies"][0]
    assert body["radius"] == DEFAULT_RADIUS_M and body["role"] is None and body["reference"] is None
    assert frame["radio"] == {"delivered": 0, "collided": 0, "lost": 0} and frame["events"] == []
    assert check_frame({**_frame(), "bodies": [{**_frame()["bodies"][0], "id": 7}]})["bodies"][0]["id"] == "7"


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"v": 2}, "v must be 1"),
        ({"t_us": 1.5}, "t_us"),
        ({"bodies": [{"id": "1", "kind": "cat", "x": 0, "y": 0}]}, "bodies[0].kind"),
        ({"bodies": [{"id": "1", "kind": "robot", "x": float("nan"), "y": 0}]}, "bodies[0].x"),
        ({"bodies": [{"id": "1", "kind": "robot", "x": 0, "y": 0, "reference": [1]}]}, "bodies[0].reference"),
        ({"bodies": [{"id": "1", "kind": "robot", "x": 0, "y": 0, "pan_id": 70000}]}, "bodies[0].pan_id"),
        ({"bodies": [{"id": "1", "kind": "robot", "x": 0, "y": 0, "ir": "on"}]}, "bodies[0].ir"),
        ({"obstacles": [{"kind": "circle", "x": 0, "y": 0, "r": -1}]}, "obstacles[0].r"),
        ({"obstacles": [{"kind": "wall", "x0": 0, "y0": 0, "x1": 1}]}, "obstacles[0].y1"),
        ({"radio": {"delivered": "many"}}, "radio.delivered"),
        ({"events": [{"kind": "loss", "node": "", "t_us": 3}]}, "events[0].node"),
    ],
)
def test_a_bad_frame_is_refused_naming_the_field(change, field):
    with pytest.raises(ValueError, match=field.replace("[", r"\[").replace("]", r"\]")):
        check_frame({**_frame(), **change})


def test_a_replay_drops_cut_and_foreign_lines_and_sorts_by_time():
    lines = [json.dumps(_frame(300)), json.dumps(_frame(100)), '{"v": 1, "t_us": 2', "", json.dumps({"v": 9})]
    replay = parse_replay(lines)
    assert replay.times_us == [100, 300] and replay.dropped == 2


def test_frames_passed_over_still_carry_their_events():
    frames = [check_frame(_frame(k, events=[{"kind": "loss", "node": "2", "t_us": k}])) for k in range(5)]
    merged = with_events_since(frames, 0, 3)
    assert [e["t_us"] for e in merged["events"]] == [1, 2, 3] and merged["t_us"] == 3
    assert with_events_since(frames, 2, 3) is frames[3]  # the next frame: nothing was passed over


def test_the_replay_clock_plays_pauses_seeks_and_changes_speed():
    clock = ReplayClock([0, 100_000, 200_000, 300_000, 400_000])
    clock.start(wall=10.0)
    assert clock.index(10.0) == 0 and clock.index(10.15) == 1  # real time: 0.15 s -> frame at 0.1 s
    clock.pause(10.25)
    assert clock.index(99.0) == 2 and clock.t_us(99.0) == pytest.approx(250_000)
    clock.play(100.0)
    clock.set_speed(2.0, 100.0)
    assert clock.t_us(100.05) == pytest.approx(350_000)  # 0.05 s at twice real time
    assert clock.finished(101.0) and clock.index(101.0) == 4  # stops at the last frame
    clock.play(101.0)  # play at the end starts again
    assert clock.index(101.0) == 0
    clock.seek(10**9, 102.0)
    assert clock.t_us(102.0) == 400_000 and clock.seeks == 1  # clamped to the recording
    with pytest.raises(ValueError, match="speed"):
        clock.set_speed(0, 103.0)
    with pytest.raises(ValueError, match="times_us"):
        ReplayClock([])


def test_replaying_a_record_without_a_world_log_says_which_runs_have_one(tmp_path):
    from petswarm.lab.watch import load_replay

    (tmp_path / "manifest.json").write_text("{}")  # the default run's record: robots pinging, no world
    with pytest.raises(ValueError, match=r"without a world log: only scenario runs \(petswarm run SCENARIO\)"):
        load_replay(tmp_path)
    with pytest.raises(FileNotFoundError):  # not a record at all: the plain error names the file
        load_replay(tmp_path / "elsewhere")
