"""A stop signal ends a model-time run wherever in the run it lands (petswarm/lab/model_run.py ``execute``,
``Interrupts(at_safe_points=True)``).

The run is the real one (``petswarm run --clock model`` in this process); only the moment of the signal is
chosen: inside a weakref callback, where a KeyboardInterrupt raised by a signal handler is printed as
"Exception ignored" and lost. A model run drops a weakref with every timer it fires, so in CI an experiment's
SIGINT landed there once and the run went on for its whole hour of model time.
"""

from __future__ import annotations

import json
import signal
import weakref
from pathlib import Path

import pytest

from petswarm.clock import ModelClockLoop
from petswarm.lab import model_run
from petswarm.lab.run import RunOptions

SIGNAL_AT_S = 2.0


class _Dropped:
    """An object whose only strong reference goes away: its weakref's callback runs at once."""


class _SignalInAWeakrefCallback(ModelClockLoop):
    """The run's loop, which at model time ``SIGNAL_AT_S`` takes the signal inside a weakref callback."""

    signum = signal.SIGINT

    def __init__(self) -> None:
        super().__init__()
        self.call_at(SIGNAL_AT_S, self._drop)

    def _drop(self) -> None:
        dropped = _Dropped()
        ref = weakref.ref(dropped, lambda _: signal.raise_signal(self.signum))  # the handler runs in there
        del dropped
        assert ref() is None


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_landing_in_a_weakref_callback_still_stops_the_model_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, signum: int
) -> None:
    monkeypatch.setattr(_SignalInAWeakrefCallback, "signum", signum)
    monkeypatch.setattr(model_run, "ModelClockLoop", _SignalInAWeakrefCallback)
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    opts = RunOptions(
        robots=3,
        seed=1,
        duration=120.0,
        ping_interval=0.5,
        record_dir=str(tmp_path / "run"),
        as_json=True,
        clock="model",
    )
    assert model_run.run_model(opts, None) == 130
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["problems"] == ["interrupted"] and summary["clock"] == "model"
    assert summary["model_time_s"] == SIGNAL_AT_S  # raised at the next pass, before time moves on
    for rid in (1, 2, 3):  # each robot's record ends as a process's does when its run is stopped
        last = json.loads((tmp_path / "run" / "events" / f"robot-{rid}.jsonl").read_text().splitlines()[-1])
        assert last["kind"] == "stop" and last["interrupted"] and last["mono"] == SIGNAL_AT_S, last
    try:  # on its way out (130), the process takes a later signal as noted only, not as a KeyboardInterrupt
        signal.raise_signal(signal.SIGINT)
    finally:
        for signum, handler in before.items():
            signal.signal(signum, handler)


def test_a_signal_landing_in_a_weakref_callback_stops_the_model_time_organize_bench(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the bench's loop drops weakrefs as the run's does: a Ctrl-C there was lost and the bench went on
    from cli.main import main
    from petswarm.bench import organize_model

    monkeypatch.setattr(organize_model, "ModelClockLoop", _SignalInAWeakrefCallback)
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        code = main(["bench", "organize", "--slaves", "2", "--runs", "500", "--out", str(tmp_path)])
    finally:
        for signum, handler in before.items():
            signal.signal(signum, handler)
    assert code == 130  # 500 organizations take far longer than the 2 s of model time the signal waits
    assert not (tmp_path / "bench_organize.json").exists()


class _SignalAfterTheLastPass(ModelClockLoop):
    """The run's loop, which takes a SIGINT just after the run's last pass."""

    def run_until_complete(self, future: object) -> object:  # type: ignore[override]
        result = super().run_until_complete(future)  # type: ignore[arg-type]
        signal.raise_signal(signal.SIGINT)
        return result


def test_a_signal_after_the_runs_last_pass_still_leaves_an_interrupted_summary_and_prints_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(model_run, "ModelClockLoop", _SignalAfterTheLastPass)
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    opts = RunOptions(
        robots=2, seed=1, duration=2.0, ping_interval=0.5, record_dir=str(tmp_path / "run"), as_json=True, clock="model"
    )
    try:
        assert model_run.run_model(opts, None) == 130
    finally:
        for signum, handler in before.items():
            signal.signal(signum, handler)
    printed = json.loads(capsys.readouterr().out)  # --json promises a summary, interrupted too
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    for told in (printed, summary):
        assert told["interrupted"] and not told["ok"] and "interrupted" in told["problems"]
        assert told["model_time_s"] == 2.0  # the run itself was whole
