"""``petswarm bench organize``'s count of organizations that ended short while enough robots waited."""

from typing import Any

from petswarm.bench.organize import waiting_after
from petswarm.bench.organize_report import ended_short, summary_row


def _record(members: list[int], waiting: int, ok: bool = True, run: int = 0) -> dict[str, Any]:
    figures = {"ok": ok, "complete": len(members) == 3, "members": members, "candidates": members, "retries": 0}
    figures |= {"organize_time_s": 0.2, "step_retries": {}, "dispersal": None, "settle": {"ok": True}}
    return {"slaves": 3, "protocol": "paper", "run": run, "waiting_before": waiting, **figures}


def test_an_organization_is_short_only_when_as_many_robots_waited_as_it_asked_for():
    complete = _record([2, 3, 4], 3)
    short = _record([2, 3], 3, run=1)
    too_few_waiting = _record([2, 3], 2, run=2)  # a robot of the last run was stuck elsewhere
    failed = {**_record([], 3, ok=False, run=3), "error": "timeout"}  # a failed command is counted as failed
    assert ended_short([complete, short, too_few_waiting, failed]) == [short]
    row = summary_row([complete, short, too_few_waiting, failed], "paper", 3)
    assert row["short"] == 1 and row["incomplete"] == 2 and row["failed"] == 1


def test_robots_stuck_after_the_last_organization_do_not_count_as_waiting():
    assert waiting_after(None, 4) == 4
    assert waiting_after({"settle": {"ok": True}}, 4) == 4
    # the master (1) stuck does not take a slave away; keys come back from JSON as strings too
    assert waiting_after({"settle": {"ok": False, "stuck": {1: "organizing", "3": "slave-driving"}}}, 4) == 3
