"""The hub's up-key thread ends at once when the hub closes, whatever tokens it has still to handle.

A hub that got SIGTERM while it opened keys for a rogue's 5,000 tokens (cap 4,096) was ended by its 4 s
deadline (exit 3, "not stopped 4 s after the signal"): ``UpKeys.undeclare`` queued its stop behind every
token not yet handled and waited 5 s for the thread. Here each key takes 50 ms to open, as thousands of
subscriptions made it take, and 100 tokens are waiting.
"""

from __future__ import annotations

import time

import pytest
import zenoh

from petswarm.lab.processes import free_tcp_port
from radio_hub.link import up_keys
from radio_hub.link.keys import Keys
from radio_hub.link.zenoh_link import session_config

TOKENS = 100


def test_undeclare_ends_the_thread_without_handling_the_tokens_still_waiting(monkeypatch: pytest.MonkeyPatch) -> None:
    token_came = up_keys.UpKeys._token_came

    def slow(self: up_keys.UpKeys, node_id: str, instance: str) -> None:
        time.sleep(0.05)
        token_came(self, node_id, instance)

    monkeypatch.setattr(up_keys.UpKeys, "_token_came", slow)
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    hub = zenoh.open(session_config("router", endpoint))
    node = zenoh.open(session_config("client", endpoint))
    keys = Keys("up-keys-close")
    seen: list[object] = []
    keeper = up_keys.UpKeys(hub, keys, lambda s: None, seen.append)
    tokens = [node.liveliness().declare_token(keys.alive(f"fake-{i}", "x")) for i in range(TOKENS)]
    try:
        deadline = time.monotonic() + 5
        while not seen:
            assert time.monotonic() < deadline
            time.sleep(0.01)
        started = time.monotonic()
        keeper.undeclare()
        took = time.monotonic() - started
        assert took < 1.0, took
        assert not keeper._thread.is_alive() and keeper.open_count == 0
        assert len(seen) < TOKENS  # what was still waiting was let go, not handled
    finally:
        for token in tokens:
            token.undeclare()
        node.close()
        hub.close()
