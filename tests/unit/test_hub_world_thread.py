"""The hub's two threads: while the world thread holds the world lock (a tick in progress), a robot's frames
still reach the medium and their outcomes still leave; anything else waits, in arrival order, and nothing of it
is half done."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager

from radio_hub.air.mac import Frame, FrameType
from radio_hub.environment import Environment, EnvironmentConfig
from radio_hub.link import wire
from radio_hub.shell.hub import RadioHub

from .recorder import Recorder

WORLD = "wt"


@contextmanager
def world_busy(env: Environment) -> Iterator[None]:
    """Another thread holds the world lock, as the hub's world thread does during a tick."""
    taken, done = threading.Event(), threading.Event()

    def hold() -> None:
        with env.world_lock:
            taken.set()
            done.wait(10)

    holder = threading.Thread(target=hold)
    holder.start()
    assert taken.wait(10)
    try:
        yield
    finally:
        done.set()
        holder.join(10)


def _attach(node_id: str, short: int, key: int) -> bytes:
    msg = wire.Attach(short_addr=short, pan_id=0x1000, position=[float(short), 0.0], instance=node_id, n=1, s=key)
    return msg.encode()


def _frame(src: int, dst: int, n: int, key: int, token: int) -> bytes:
    frame = Frame(FrameType.DATA, n, 0x1000, dst, 0x1000, src, b"hi")
    return wire.Transmit(token=token, psdu=frame.encode(), n=n, s=key).encode()


def _drive(n: int, key: int) -> bytes:
    return wire.Drive(vx=0.1, vy=0.0, omega=0.0, n=n, s=key).encode()


def test_a_robots_frame_goes_on_the_air_while_a_tick_holds_the_world_and_a_drive_waits_untouched() -> None:
    down = Recorder()
    env = Environment(EnvironmentConfig(), 1, down)
    env.receive("a", _attach("a", 1, 11), 0)
    env.receive("b", _attach("b", 2, 12), 0)
    with world_busy(env):
        assert env.receive("a", _frame(1, 2, 2, 11, token=7), 1000, wait=False)
        assert not env.receive("a", _drive(3, 11), 1000, wait=False)
        assert env.world.bodies["a"].command.tolist() == [0.0, 0.0, 0.0]  # the drive did nothing yet
        assert env.counters.transport_gaps == 0
        env.advance_medium(env.medium.next_event_us() or 0)
        while (due := env.medium.next_event_us()) is not None:
            env.advance_medium(due)
    kinds = [(node, type(msg).__name__) for node, msg in down.sent[2:]]
    assert ("b", "Received") in kinds and ("a", "TxDone") in kinds
    assert env.receive("a", _drive(3, 11), 30_000, wait=False)  # offered again once the tick is done
    assert env.world.bodies["a"].command.tolist() == [0.1, 0.0, 0.0]
    assert env.counters.transport_gaps == 0  # n=3 was taken once, after n=2


def test_the_hub_holds_what_needs_the_world_and_everything_after_it_in_arrival_order() -> None:
    hub = RadioHub("tcp/127.0.0.1:0", WORLD)  # never opened: the job thread's steps, taken by hand
    keys = hub.keys
    for node_id, short, key in (("a", 1, 11), ("b", 2, 12)):
        hub._admit(("up", keys.up(node_id), _attach(node_id, short, key)))
        hub._take(hub._inbox.get_nowait())
    assert set(hub.env.kinds) == {"a", "b"}
    with world_busy(hub.env):
        hub._admit(("up", keys.up("a"), _drive(2, 11)))
        hub._admit(("up", keys.up("a"), _frame(1, 2, 3, 11, token=5)))
        hub._take(hub._inbox.get_nowait())
        assert len(hub._held) == 2  # the frame waits behind the drive: a node's messages keep their order
        assert hub.env.medium.next_event_us() is None  # nothing of it reached the medium
        hub._take_held()
        assert len(hub._held) == 2
    hub._take_held()
    assert not hub._held
    assert hub.env.counters.transport_gaps == 0
    assert hub.env.medium.next_event_us() is not None  # the frame is on its way
    assert hub.stats()["inbox"]["waiting"] == 0
