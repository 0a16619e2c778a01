"""Faults: counting what went wrong must never itself go wrong."""

from __future__ import annotations

import io

from radio_hub.guard import Faults


def test_a_fault_is_counted_even_when_its_log_cannot_be_written() -> None:
    """stderr a closed pipe (the reader left): the handler that counts must not raise, or the thread it runs in
    (the hub's world thread) ends there."""
    stream = io.StringIO()
    stream.close()
    faults = Faults("hub", stream)
    faults.record("advance world", RuntimeError("boom"))
    faults.record("advance world", RuntimeError("again"))
    assert faults.counts["advance world:RuntimeError"] == 2 and faults.total == 2


def test_the_first_fault_of_a_kind_is_logged_once() -> None:
    stream = io.StringIO()
    faults = Faults("hub", stream)
    for _ in range(3):
        faults.record("receive", ValueError("bad"), "12 bytes from 'robot-1'")
    assert stream.getvalue().count("receive:ValueError") == 1 and "counted, going on" in stream.getvalue()
