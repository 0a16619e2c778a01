"""``free_tcp_port``: a port for a hub to listen on that no outgoing connection can take meanwhile."""

from __future__ import annotations

import socket

import pytest

from petswarm.lab import processes
from petswarm.lab.processes import free_tcp_port


def test_ports_come_from_below_the_ephemeral_range_and_can_be_listened_on() -> None:
    low = processes._ephemeral_low()
    ports = {free_tcp_port() for _ in range(200)}
    assert all(max(1024, low - processes.LISTEN_PORTS_SPAN) <= p < low for p in ports), sorted(ports)[-5:]
    assert len(ports) > 150  # drawn at random: runs started at once do not line up on one port
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", ports.pop()))
        sock.listen()


def test_a_port_someone_listens_on_is_not_given(monkeypatch: pytest.MonkeyPatch) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        monkeypatch.setattr(processes, "LISTEN_PORTS_SPAN", 1)  # the span is that one port: it must be refused
        monkeypatch.setattr(processes, "_ephemeral_low", lambda: port + 1)
        assert free_tcp_port() != port


def test_an_unreadable_range_falls_back_to_linuxs_default(monkeypatch: pytest.MonkeyPatch, tmp_path) -> None:
    monkeypatch.setattr(processes, "EPHEMERAL_RANGE_FILE", tmp_path / "missing")
    assert processes._ephemeral_low() == 32768
    (tmp_path / "range").write_text("garbage\n")
    monkeypatch.setattr(processes, "EPHEMERAL_RANGE_FILE", tmp_path / "range")
    assert processes._ephemeral_low() == 32768
