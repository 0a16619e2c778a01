"""How a run lives with its children: an unexpected death is recorded and the run goes on, and the summary
on disk is rewritten as the run goes, so even a ``kill -9`` of ``petswarm run`` leaves one.

A robot's death is a fault the swarm is meant to survive, so the run records it (``supervision.jsonl`` in
the record, ``deaths`` in the summary, the checker's view of that robot's events) and carries on without
that robot, unless ``--fail-fast``. The hub's or a user's death ends the run: nothing is left to observe.
"""

from __future__ import annotations

import json
import signal
import time
from collections.abc import Callable
from typing import Any

from petswarm.lab.processes import Supervisor
from petswarm.lab.records import RunRecord

PROGRESS_EVERY_S = 1.0
"""How often the summary on disk is rewritten while the run goes (and at once on every death)."""
UNFINISHED = "the run did not finish (this summary was written while it ran)"
DEATHS_ONLY = 3
"""``petswarm run``'s exit status when every check held but robots died during the run (README)."""


class RunAborted(RuntimeError):
    """A child the run cannot do without died, or a robot died under ``--fail-fast``."""


def describe_code(code: int) -> str:
    """An exit code in words: ``SIGKILL`` for -9, ``exit 1`` for 1."""
    if code < 0:
        try:
            return signal.Signals(-code).name
        except ValueError:
            return f"signal {-code}"
    return f"exit {code}"


def robot_of(name: str) -> int | None:
    """The id of child ``robot-<n>``, None for any other child."""
    prefix, _, number = name.partition("-")
    return int(number) if prefix == "robot" and number.isdigit() else None


class Supervision:
    """Watches a run's children and keeps its summary on disk current.

    ``check`` is called from the run's loops: it records every new death (and raises RunAborted when the
    run cannot go on), and rewrites the summary at most every PROGRESS_EVERY_S."""

    def __init__(self, sup: Supervisor, record: RunRecord, fail_fast: bool, log: Callable[[str], None]) -> None:
        self.sup, self.record, self.fail_fast, self.log = sup, record, fail_fast, log
        self.started = time.monotonic()
        self.deaths: list[dict[str, Any]] = []
        self.progress: dict[str, Any] = {}
        """What the run last learnt (totals, phase): it goes into the summary written as the run goes."""
        self._written = 0.0
        self.checkpoint: Callable[[], None] | None = None
        """Called first by every ``check`` (``Interrupts.check``: a stop signal whose raise was lost)."""
        self.world_over = False
        """Set once the run's world has ended (a lockstep run's model time is over): nodes then leave by
        themselves, and a clean exit is no death."""

    def dead_robots(self) -> set[int]:
        """Ids of the robots that died during the run."""
        return {d["robot"] for d in self.deaths if d.get("robot") is not None}

    def check(self) -> None:
        """Record children that died since the last call; RunAborted when the run cannot carry on."""
        if self.checkpoint is not None:
            self.checkpoint()
        fatal = []
        for name, code in self.sup.unexpected_deaths().items():
            if code == 0 and (self.world_over or (robot_of(name) is None and name != "hub")):
                continue  # a user walked its path and left, or the world ended: its work is done
            # (a hub that exits 0 before then was stopped from outside: the air is gone all the same)
            death = self._record_death(name, code)
            if death["robot"] is None or self.fail_fast:
                fatal.append(f"{name} died ({describe_code(code)}):\n{self.sup.log_tail(name)}")
        if fatal:
            raise RunAborted("; ".join(fatal))
        self.write_progress()

    def _record_death(self, name: str, code: int) -> dict[str, Any]:
        elapsed = round(time.monotonic() - self.started, 2)
        death = {"kind": "died", "process": name, "robot": robot_of(name), "code": code}
        death.update(cause=describe_code(code), elapsed_s=elapsed, t=time.time())
        self.deaths.append(death)
        with open(self.record.path / "supervision.jsonl", "a") as events:
            events.write(json.dumps(death) + "\n")
        self.log(f"{name} died ({death['cause']}) {elapsed:g} s into the run; the run goes on without it")
        self.write_progress(force=True)
        return death

    def write_progress(self, force: bool = False) -> None:
        """Rewrite the summary on disk with what is known so far (at most every PROGRESS_EVERY_S unless
        ``force``); the final summary replaces it when the run ends."""
        now = time.monotonic()
        if not force and now - self._written < PROGRESS_EVERY_S:
            return
        self._written = now
        self.record.write(
            "summary.json",
            {
                "ok": False,
                "running": True,
                "problems": [UNFINISHED],
                "elapsed_s": round(now - self.started, 2),
                "deaths": self.deaths,
                "processes": {n: p.pid for n, p in self.sup.children.items()},
                **self.progress,
            },
        )

    def exit_status(self, ok: bool) -> int:
        """0 when every check held and no robot died, DEATHS_ONLY when every check held but robots died, 1
        otherwise (README, ``petswarm run --help``)."""
        if not ok:
            return 1
        return DEATHS_ONLY if self.deaths else 0


def verdict(summary: dict[str, Any]) -> str:
    """The run's last line, which agrees with its exit status: ``OK`` (0) only when every check held and no
    process died; every check held but processes died (``DEATHS_ONLY``); or the problems (1)."""
    if not summary["ok"]:
        return "PROBLEMS: " + "; ".join(summary["problems"])
    died = [d["process"] for d in summary.get("deaths", [])]
    if died:
        return f"CHECKS HELD, BUT {len(died)} DIED: {', '.join(died)} (exit status {DEATHS_ONLY})"
    return "OK"
