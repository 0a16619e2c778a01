"""The floor hub's frame path (radio_hub/shell/floor.py) without zenoh: what it carries, and what it leaves to the
hub's own way (refused, counted or modelled there as always)."""

from __future__ import annotations

from radio_hub.air.mac import Frame, FrameType
from radio_hub.link import wire
from radio_hub.shell.floor import FloorHub

KEY = 77


def _hub() -> FloorHub:
    hub = FloorHub("tcp/127.0.0.1:1", "floor-test")  # never opened: its downlink has no session and puts nothing
    for i, (pan, channel) in enumerate(((0x1000, 11), (0x1000, 11), (0x2000, 11), (0x1000, 12)), start=1):
        attach = wire.Attach(n=1, s=KEY, short_addr=i, pan_id=pan, channel=channel, position=[1000.0 * i, 0.0])
        hub.env.receive(f"robot-{i}", attach.encode(), 0)
    return hub


def _transmit(dst: int, n: int = 2, s: int = KEY, frame_type: FrameType = FrameType.DATA) -> bytes:
    frame = Frame(frame_type, 5, 0x1000, dst, 0x1000, 1, b"hello")
    return wire.Transmit(n=n, s=s, token=9, psdu=frame.encode()).encode()


def _count(hub: FloorHub, node: int, name: str) -> int:
    return hub.env.stats()["nodes"][f"robot-{node}"][name]


def test_a_frame_reaches_its_address_on_the_senders_channel_and_pan_whatever_the_distance():
    hub = _hub()
    assert hub._carry("robot-1", _transmit(dst=2))
    assert hub._carry("robot-1", _transmit(dst=0xFFFF, n=3))  # broadcast: robot 2 only (PAN 0x2000, channel 12)
    assert [_count(hub, i, "delivered") for i in (1, 2, 3, 4)] == [0, 2, 0, 0]
    assert _count(hub, 1, "sent") == 2 and hub.stats()["hub"]["carried"] == 2
    assert list(hub.env.medium.air_log) == []  # nothing went on the modelled air


def test_what_is_not_a_robots_well_formed_frame_goes_the_hubs_way():
    hub = _hub()
    assert not hub._carry("robot-1", b"\x00garbage")
    assert not hub._carry("robot-1", _transmit(dst=2, s=KEY + 1))  # another session's key
    assert not hub._carry("robot-1", _transmit(dst=2, frame_type=FrameType.ACK))
    assert not hub._carry("robot-9", _transmit(dst=2))  # not attached
    assert not hub._carry("robot-1", wire.Detach(n=2, s=KEY).encode())
    assert hub.stats()["hub"]["carried"] == 0 and _count(hub, 2, "delivered") == 0
