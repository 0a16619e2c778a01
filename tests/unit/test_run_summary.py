"""The default run's pass criterion on hearing, from the hub's stats and the robots' statuses."""

from __future__ import annotations

from petswarm.lab.run import ALL_PAIRS_UP_TO, HEARING_PROBLEMS, RunOptions, default_ping_interval, summarise


def _summary(robots: int, heard: dict[int, list[int]], delivered: dict[int, int] | None = None) -> dict:
    """``heard``: whose pongs each robot got; ``delivered``: frames the hub delivered to a robot's radio."""
    nodes = {f"robot-{rid}": {"delivered": n} for rid, n in (delivered or {}).items()}
    stats = {"nodes": nodes, "channels": {}, "hub": {"transport_gaps": 0}, "ir": {}, "config": {}}
    status = {rid: {"heard_from": {h: 1 for h in heard.get(rid, [])}} for rid in range(1, robots + 1)}
    return summarise(stats, status, RunOptions(robots, 1, 1.0, 0.5), "w", "e")


def test_up_to_ten_robots_every_pair_must_be_heard() -> None:
    everyone = {rid: [o for o in range(1, 6) if o != rid] for rid in range(1, 6)}
    assert _summary(5, everyone)["problems"] == []
    assert _summary(5, {**everyone, 3: [1, 2, 4]})["problems"] == [HEARING_PROBLEMS[0]]


def test_beyond_ten_robots_every_robot_must_receive_frames_from_others_and_the_fraction_is_reported() -> None:
    robots = ALL_PAIRS_UP_TO + 2
    ring = {rid: [rid % robots + 1] for rid in range(1, robots + 1)}  # each hears only its successor
    summary = _summary(robots, ring)
    assert summary["problems"] == [] and not summary["all_pairs_heard"]
    assert summary["pairs_heard_fraction"] == round(robots / (robots * (robots - 1)), 3)
    assert _summary(robots, {**ring, 4: []})["problems"] == [HEARING_PROBLEMS[1]]  # nothing at all reached robot 4
    # its own pongs all collided, but other robots' pings reached its radio: the channel is loaded, not broken
    assert _summary(robots, {**ring, 4: []}, delivered={4: 12})["problems"] == []


def test_the_ping_interval_grows_with_the_robots_beyond_ten() -> None:
    assert default_ping_interval(5) == default_ping_interval(10) == 0.5
    assert default_ping_interval(50) == 2.5 and default_ping_interval(100) > default_ping_interval(50)
