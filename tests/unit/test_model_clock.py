"""The model clock: a loop whose time moves only when it would wait, and runs that repeat from their seed."""

from __future__ import annotations

import asyncio
import itertools
import json
import math
import signal
from pathlib import Path

import pytest

from cli.main import main
from petswarm import clock
from petswarm.clock import MODEL_EPOCH_S, ModelClockLoop, ModelTimeStalled
from petswarm.grid import next_on_grid
from petswarm.lab.digest import record_digest


def test_sleeping_moves_model_time_by_exactly_the_sleep_and_no_wall_time_passes() -> None:
    seen: list[tuple[str, float]] = []

    async def sleeper(name: str, period: float) -> None:
        for _ in range(3):
            await asyncio.sleep(period)
            seen.append((name, round(clock.now(), 9)))

    async def both() -> None:
        await asyncio.gather(sleeper("a", 0.1), sleeper("b", 0.25))

    loop = ModelClockLoop()
    try:
        loop.run_until_complete(both())
        assert loop.time() == pytest.approx(0.75)
    finally:
        loop.close()
    assert seen == [("a", 0.1), ("a", 0.2), ("b", 0.25), ("a", 0.3), ("b", 0.5), ("b", 0.75)]


def test_callbacks_due_at_one_instant_run_in_the_order_they_were_scheduled() -> None:
    order: list[int] = []
    loop = ModelClockLoop()
    try:
        for n in range(5):
            loop.call_at(1.0, order.append, n)
        loop.call_at(0.5, order.append, -1)
        loop.run_until_complete(asyncio.sleep(2.0))
    finally:
        loop.close()
    assert order == [-1, 0, 1, 2, 3, 4]


def test_a_loop_with_nothing_to_wait_for_says_it_stalled_instead_of_hanging() -> None:
    loop = ModelClockLoop()
    try:
        with pytest.raises(ModelTimeStalled):
            loop.run_until_complete(loop.create_future())  # nobody will ever resolve it
    finally:
        loop.close()


def test_wall_time_in_model_time_is_the_fixed_epoch_plus_model_time() -> None:
    async def stamp() -> tuple[float, bool]:
        await asyncio.sleep(2.5)
        return clock.wall_time(), clock.in_model_time()

    loop = ModelClockLoop()
    try:
        assert loop.run_until_complete(stamp()) == (MODEL_EPOCH_S + 2.5, True)
    finally:
        loop.close()
    assert not asyncio.run(_in_model_time())  # an ordinary loop is the wall clock


async def _in_model_time() -> bool:
    return clock.in_model_time()


def _model_run(tmp: Path, name: str, seed: int, capsys: pytest.CaptureFixture[str]) -> dict:
    argv = ["run", "--robots", "4", "--organize", "2", "--duration", "2", "--seed", str(seed)]
    code = main([*argv, "--clock", "model", "--json", "--record", str(tmp / name)])
    summary = json.loads(capsys.readouterr().out)
    assert code == 0, summary["problems"]
    return summary


def test_a_model_run_repeats_from_its_seed_and_another_seed_is_another_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    first = _model_run(tmp_path, "a", 7, capsys)
    again = _model_run(tmp_path, "b", 7, capsys)
    other = _model_run(tmp_path, "c", 8, capsys)
    assert first["ok"] and first["clock"] == "model"
    assert first["digest"] == again["digest"] == record_digest(tmp_path / "a")
    assert first["organization"]["members"] == again["organization"]["members"]
    assert other["digest"] != first["digest"]
    # the model ran the traffic phase, the organization and the dispersal: more than the 2 s asked for
    assert first["model_time_s"] > 2.0 and first["wall_time_s"] > 0


def test_the_digest_ignores_wall_clock_stamps_and_sees_everything_else(tmp_path: Path) -> None:
    events = tmp_path / "events"
    events.mkdir()
    line = {"t": 1.0, "mono": 0.5, "kind": "start", "robot_id": 1}
    (events / "robot-1.jsonl").write_text(json.dumps(line) + "\n")
    before = record_digest(tmp_path)
    (events / "robot-1.jsonl").write_text(json.dumps({**line, "t": 99.0}) + "\n")
    assert record_digest(tmp_path) == before
    (events / "robot-1.jsonl").write_text(json.dumps({**line, "mono": 0.6}) + "\n")
    assert record_digest(tmp_path) != before


def test_a_run_into_a_folder_that_holds_an_earlier_run_gives_the_same_digest(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A robot appends to its event file (a restarted robot carries on its own stream), so a second run with the
    same ``--record`` once appended to the first run's streams and reported a digest of both."""
    first = _model_run(tmp_path, "same", 7, capsys)
    (tmp_path / "same" / "events" / "robot-9.jsonl").write_text('{"kind": "start"}\n')  # a larger earlier run's
    again = _model_run(tmp_path, "same", 7, capsys)
    assert again["digest"] == first["digest"] == record_digest(tmp_path / "same")
    assert not (tmp_path / "same" / "events" / "robot-9.jsonl").exists()


def test_timers_order_by_deadline_then_by_when_they_were_scheduled_as_tuples_of_both_do() -> None:
    loop = ModelClockLoop()
    try:
        nan = math.nan
        whens = [0.0, 0.02, 0.02, 1e-9, 0.04, math.inf, nan, nan, 0.02, float("nan"), 0.0]
        timers = [loop.call_at(when, lambda: None) for when in whens]
        for a, b in itertools.product(timers, timers):
            assert (a < b) == ((a._when, a._order) < (b._when, b._order))  # type: ignore[attr-defined]
        assert timers[1] < timers[2] and not timers[2] < timers[1]  # equal deadlines: first scheduled first
        assert timers[6] < timers[7]  # one nan object: as a tuple compares it, the same
    finally:
        loop.close()


def test_the_next_instant_on_a_grid_is_the_one_a_periodic_timer_would_have_reached() -> None:
    ticks, at = [], 0.1
    for _ in range(200):  # a timer that went on: each instant its last plus the period
        at = at + 0.05
        ticks.append(at)
    for after in (0.1, 0.12, ticks[40], ticks[40] + 1e-12, 9.0):
        expected = next(t for t in [0.1 + 0.05, *ticks] if t > after)
        assert next_on_grid(0.1, 0.05, after) == expected  # exactly: instants are compared exactly
    assert next_on_grid(0.1, 0.05, 0.0) == 0.1 + 0.05  # never before the grid's next instant


def test_dead_after_is_refused_outside_lockstep_with_the_reason(capsys: pytest.CaptureFixture[str]) -> None:
    """The lockstep hub's patience means nothing to a wall-clock or model-time run: said, not ignored."""
    for run_clock in ("wall", "model"):
        assert main(["run", "--robots", "2", "--clock", run_clock, "--dead-after", "3"]) == 2
        assert "needs --clock lockstep" in capsys.readouterr().err


def test_the_selector_polls_the_self_pipe_only_when_something_can_have_written_it() -> None:
    """Model time skips the system call of a poll that could only come back empty; a thread's wake-up (the
    self-pipe written) or an asyncio signal handler (which writes it from C) makes it poll again."""
    loop = ModelClockLoop()
    try:
        assert loop.nothing_to_read()
        loop.call_soon_threadsafe(lambda: None)  # writes the self-pipe, as any thread's call does
        assert not loop.nothing_to_read()
        assert loop.nothing_to_read()  # once: the caller polls then, which drains what was written
        loop.add_signal_handler(signal.SIGUSR1, lambda: None)
        assert not loop.nothing_to_read() and not loop.nothing_to_read()
        loop.remove_signal_handler(signal.SIGUSR1)
        assert loop.nothing_to_read()
    finally:
        loop.close()
