"""One rogue zenoh session fills the hub's cap on up keys with tokens of made-up ids and floods from them; a run's
robots, started afterwards, must still attach and organize.

Zenoh does not say which session declared a liveliness token, so without TLS the hub cannot bound tokens per
session; the hub of a run is given the run's roster instead, and keeps room for those ids whatever other names
come. The hub, the robots and the rogue are real processes and a real session on loopback: what is exercised is
zenoh's liveliness and the hub's inbox, which a mock could not show.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import zenoh

from radio_hub.link import wire
from radio_hub.link.up_keys import UP_KEYS_MAX
from radio_hub.link.zenoh_link import session_config

from ..waiting import wait_for

ROBOTS = (1, 2, 3)
EXTRA_TOKENS = 64
"""Tokens past the cap: the hub remembers them as waiting for room."""
FLOOD_IDS = 32
FLOOD_RATE = 5_000
"""Messages per second the rogue sends on its own open keys while the robots attach: past the strangers' rate
(``STRANGERS_PER_S``), which a robot's first attach shared with them."""


class _Flood:
    """A thread putting small messages on ``keys`` at ``FLOOD_RATE`` until the block ends."""

    def __init__(self, session: zenoh.Session, keys: list[str]) -> None:
        self.pubs = [session.declare_publisher(k) for k in keys]
        self.sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        data, t0 = wire.Drive(vx=0.1, n=1, s=7).encode(), time.monotonic()
        while not self._stop.is_set():
            for pub in self.pubs:
                pub.put(data)
            self.sent += len(self.pubs)
            ahead = self.sent / FLOOD_RATE - (time.monotonic() - t0)
            if ahead > 0:
                time.sleep(ahead)

    def __enter__(self) -> _Flood:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


def test_a_rogue_session_that_fills_the_up_key_cap_cannot_keep_the_runs_robots_from_attaching(make_air: Any) -> None:
    roster = ",".join(f"robot-{rid}" for rid in ROBOTS)
    air = make_air(hub_args=["--roster", roster])
    rogue = zenoh.open(session_config("client", air.endpoint))
    try:
        held = [
            rogue.liveliness().declare_token(air.keys.alive(f"rogue-{i}", "x"))
            for i in range(UP_KEYS_MAX + EXTRA_TOKENS)
        ]
        full = wait_for(
            "the rogue's tokens fill the cap",
            lambda: (s := air.stats()["liveliness"])["up_keys_waiting"] == EXTRA_TOKENS and s,
            90,
            every=0.2,
        )
        assert full["up_keys_open"] == full["up_keys_others_open"] == UP_KEYS_MAX, full
        with _Flood(rogue, [air.keys.up(f"rogue-{i}") for i in range(FLOOD_IDS)]) as flood:
            # the robots start once the flood is past the strangers' rate, where their first attaches used to go
            wait_for("the flood past the strangers' rate", lambda: air.stats()["inbox"]["dropped"].get("stranger"), 20)
            air.robot(1, (0.0, 0.0), 0x1000, 11, "--user", "1")
            for rid in ROBOTS[1:]:
                air.robot(rid, (1.0 * rid, 0.0), 0x1000, 11)
            organized = air.cmd(1, "organize", timeout=30, count=len(ROBOTS) - 1)
        stats = air.stats()
        print(f"\nrogue: {len(held)} tokens, {flood.sent} flood messages; liveliness {stats['liveliness']}")
        print(f"inbox {stats['inbox']}; organized {organized}")
        assert organized.get("members") == list(ROBOTS[1:]), organized
        live = stats["liveliness"]
        # the rogue still holds the whole cap: the robots' keys were opened beside it, not in room it gave up
        assert live["up_keys_others_open"] == UP_KEYS_MAX and live["up_keys_open"] == UP_KEYS_MAX + len(ROBOTS), live

        # an id the run did not start still waits for room, as before
        late = rogue.liveliness().declare_token(air.keys.alive("robot-4", "x"))
        wait_for("robot-4's token waits", lambda: air.stats()["liveliness"]["up_keys_waiting"] == EXTRA_TOKENS + 1, 20)
        late.undeclare()
    finally:
        rogue.close()
    codes = air.close()
    assert codes["hub"] == 0, codes
