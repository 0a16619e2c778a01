"""What a rogue that declares liveliness tokens of made-up ids can cost a real hub: its up keys are capped
(``UP_KEYS_MAX``), and the cap itself must stay cheap.

A zenoh router's declare_subscriber costs time in proportion to the subscriptions it has already (0.27 ms of
CPU at 512, 4.4 ms at 4,096 on the machine this was written on) and about 19 kB each: at a cap of 4,096 a
rogue's 5,000 tokens added 93 MB to the hub's resident memory and 14 s of its CPU, against 11 MB and under
3 s when the hub still listened on ``up/*``.
"""

from __future__ import annotations

import os
import time
from typing import Any

from radio_hub.link.up_keys import UP_KEYS_MAX

from .procfs import cpu_seconds, rss_mb

TOKENS_RSS_BOUND_MB = 48
"""What ``UP_KEYS_MAX`` open keys and a few more refused tokens may add to the hub's resident memory (32 MB at
a cap of 1,024; 93 MB at 4,096)."""


def test_a_rogue_holding_more_tokens_than_the_cap_costs_the_hub_a_bounded_amount(make_air: Any) -> None:
    air = make_air()
    hub_pid = air.sup.children["hub"].pid
    tokens = UP_KEYS_MAX + 64
    rss0, cpu0, threads0 = rss_mb(hub_pid), cpu_seconds(hub_pid), _threads(hub_pid)
    rogue = [air.session.liveliness().declare_token(air.keys.alive(f"fake-{i}", "x")) for i in range(tokens)]
    try:
        deadline = time.monotonic() + 90
        while (seen := air.stats()["liveliness"])["up_keys_open"] + seen["up_keys_refused"] < tokens:
            assert time.monotonic() < deadline, seen
            time.sleep(0.2)
        grown, cpu = rss_mb(hub_pid) - rss0, cpu_seconds(hub_pid) - cpu0
        print(f"\n{tokens} rogue tokens: hub RSS +{grown:.1f} MB, {cpu:.2f} s of its CPU")
        assert seen["up_keys_open"] == UP_KEYS_MAX and seen["up_keys_refused"] == 64, seen
        assert seen["up_keys_waiting"] == 64, seen  # remembered, to be opened as keys close
        assert grown < TOKENS_RSS_BOUND_MB, grown
        # zenoh-python gave each subscription with a Python callback a thread of its own: 1,040 hub threads
        assert _threads(hub_pid) - threads0 <= THREADS_GROWN_MAX, _threads(hub_pid)
    finally:
        for token in rogue:
            token.undeclare()
    deadline = time.monotonic() + 30
    while air.stats()["liveliness"]["up_keys_open"] > 0:
        assert time.monotonic() < deadline, air.stats()["liveliness"]
        time.sleep(0.2)
    after = rss_mb(hub_pid)
    print(f"after the tokens went: hub RSS {rss0:.1f} -> {after:.1f} MB, threads {threads0} -> {_threads(hub_pid)}")
    assert after <= rss0 * 1.10, (rss0, after)  # back within 10 % of where it started


THREADS_GROWN_MAX = 8
"""Threads the hub may gain while a rogue holds ``UP_KEYS_MAX`` keys (the hand-off runs in zenoh's own threads)."""


def _threads(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/task"))
