"""The world log's line is ``world_state`` encoded by ``json.dumps``, character for character."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from radio_hub.environment import Environment, EnvironmentConfig
from radio_hub.link import wire
from radio_hub.physics.world import Obstacle, round_places


class Quiet:
    """A downlink that drops everything."""

    def send(self, node_id: str, data: bytes) -> None:
        pass

    def forget(self, node_id: str) -> None:
        pass

    def publish_world(self, state: dict[str, Any]) -> None:
        pass


def _as_json(env: Environment) -> str:
    return json.dumps(env.world_state(), separators=(",", ":"))


def test_the_world_line_is_the_world_state_as_json_through_motion_telemetry_and_odd_values() -> None:
    rng = np.random.default_rng(3)
    env = Environment(EnvironmentConfig(), 1, Quiet())
    assert env.world_line() == _as_json(env)  # nobody yet
    for k in range(6):
        kind = "user" if k == 5 else "robot"
        env.receive(f"n-{k}", wire.Attach(ext_addr=k + 1, position=[0.4 * k, 0.1], kind=kind, n=1), 0)
    env.world.set_obstacles([Obstacle("circle", x=5.0, y=1.6, r=1.0), Obstacle("wall", x0=0, y0=-3, x1=4, y1=-3)])
    now, referenced = 0, 0
    for step in range(60):
        now += 20_000
        for k in range(5):
            vx, vy = rng.normal(0.0, 0.7, 2).tolist()
            env.receive(f"n-{k}", wire.Drive(vx=vx, vy=vy, omega=float(rng.normal()), n=step + 2), now)
        if step % 7 == 3:  # a slave with a slot under master n-0, then one whose master is gone, then none
            slave = wire.Telemetry(state="slave_driving", role="slave", master="n-0", slot=[-0.6, 0.4])
            env.receive("n-2", slave, now)
            odd = wire.Telemetry(state='odd "quoted" \u00e9', role="", master="nobody", slot=[1.0, 0.0])
            env.receive("n-3", odd, now)
        if step == 40:
            env.receive("n-2", wire.Telemetry(state="", role="", master="", slot=None), now)
            env.world.set_obstacles([])
        env.advance(now)
        line = env.world_line(now)
        assert line == _as_json(env)
        referenced += '"reference":[' in line
    assert 0 < referenced < 60
    env.receive("n-1", wire.Configure(token=1, pan_id=0x99, n=1000), now)  # a PAN changed in place
    assert '"pan_id":153' in env.world_line() and env.world_line() == _as_json(env)
    body = env.world.bodies["n-1"]
    body.pose[0], body.velocity[1] = -0.0, 1e-300  # a signed zero and a value that rounds to zero
    assert env.world_line() == _as_json(env)
    body.pose[0], body.velocity[1] = 0.0, -1e-300  # and back
    assert env.world_line() == _as_json(env) and '"vy":-0.0' in env.world_line()
    body.velocity[0] = math.inf  # JSON's Infinity: the encoder's own path
    assert "Infinity" in env.world_line() and env.world_line() == _as_json(env)


def test_round_places_is_round_bit_for_bit_near_halves_signed_zeros_and_beyond() -> None:
    rng = np.random.default_rng(8)
    values = []
    for exponent in range(-9, 13):
        values += (rng.normal(size=400) * 10.0**exponent).tolist()
    halves = np.round(rng.normal(size=400) * 1e4) / 1e4 + 0.00005  # within an ulp or two of a decimal half
    values += halves.tolist() + np.nextafter(halves, 0.0).tolist() + np.nextafter(halves, 1.0).tolist()
    values += [0.0, -0.0, -1e-5, 0.03125, 2.5e-4, -2.5e-4, 1e-300, 5e-324, 1e12 + 0.5, 1e300, math.inf, -math.inf]
    table = np.array(values + [math.nan] * (-len(values) % 6)).reshape(-1, 6)
    got = round_places(table, 4)
    want = [[round(v, 4) for v in row] for row in table.tolist()]
    assert [[repr(v) for v in row] for row in got] == [[repr(v) for v in row] for row in want]
    assert [repr(v) for v in round_places(np.array([[0.123456, -0.5]]), 2)[0]] == ["0.12", "-0.5"]


def test_world_states_are_made_only_for_a_downlink_that_publishes_them() -> None:
    """A model run's coordinator without a viewer says so: the environment makes no state for it every fifth
    tick; with a viewer (lockstep's), or a downlink that does not say (the hub's), every fifth tick's goes out."""
    from radio_hub.coordinator import Coordinator

    def states_made(coordinator: Coordinator | None) -> tuple[int, list[int]]:
        env = coordinator.env if coordinator is not None else Environment(EnvironmentConfig(), 1, Quiet())
        made: list[int] = []
        world_state = env.world_state
        env.world_state = lambda now=None: made.append(now) or world_state(now)  # type: ignore[method-assign]
        env.receive("n-1", wire.Attach(ext_addr=1, position=[0.0, 0.0], kind="robot", n=1), 0)
        for tick in range(1, 11):
            env.advance(tick * 20_000)
        return len(made), made

    quiet = Coordinator(EnvironmentConfig(), 1, wall_epoch_us=0, in_memory=True)
    assert states_made(quiet) == (0, [])
    watched = Coordinator(EnvironmentConfig(), 1, wall_epoch_us=0, in_memory=True)
    seen: list[dict[str, Any]] = []
    watched.on_world = seen.append
    count, _ = states_made(watched)
    assert count == 2 and len(seen) == 2
    assert states_made(None)[0] == 2


def test_round_places_of_whole_tables_is_round_too_with_or_without_a_value_at_a_half() -> None:
    rng = np.random.default_rng(9)
    for exponent in range(-6, 13):  # past 2**50 units too
        table = rng.normal(size=(21, 6)) * 10.0**exponent
        if exponent % 2:  # one value at a decimal half: the whole table takes the slow way
            table[3, 2] = (np.round(table[3, 2] * 1e4) + 0.5) / 1e4
        got = round_places(table, 4)
        assert [[repr(v) for v in row] for row in got] == [[repr(round(v, 4)) for v in row] for row in table.tolist()]


def test_the_world_line_takes_the_radio_counts_from_a_snapshot_as_world_state_does() -> None:
    """The hub's medium thread may add or drop a node's counters (``_forget_gone``) while the world thread writes
    a line: the line sums a snapshot of them, as ``world_state`` does, not the live map three times over."""
    from radio_hub.air.medium import Counters

    env = Environment(EnvironmentConfig(), 1, Quiet())
    env.receive("n-1", wire.Attach(ext_addr=1, position=[0.0, 0.0], kind="robot", n=1), 0)
    live = env.medium.node_counters

    class Meanwhile(Counters):  # reading it stands for the other thread's change at that moment
        @property
        def lost(self) -> int:  # type: ignore[override]
            live.pop("n-gone", None) if "n-gone" in live else live.setdefault("n-gone", Counters(delivered=5))
            return 0

        @lost.setter
        def lost(self, value: int) -> None:
            pass

    live["n-1"] = Meanwhile(delivered=2, collided=1)
    line = env.world_line()
    assert '"radio":{"delivered":2,"collided":1,"lost":0}' in line


def test_the_world_line_names_the_pairs_in_contact_while_they_touch() -> None:
    """The collision counter says that something touched, not what: the line carries the pairs touching now (a
    body and a body, or a body and ``obstacle-K``), in world_state's JSON too, and nothing once they part."""
    env = Environment(EnvironmentConfig(), 1, Quiet())
    env.receive("n-1", wire.Attach(ext_addr=1, position=[0.0, 0.0], kind="robot", n=1), 0)
    env.receive("n-2", wire.Attach(ext_addr=2, position=[3.0, 0.0], kind="robot", n=1), 0)
    env.receive("u", wire.Attach(ext_addr=3, position=[0.0, 3.0], kind="user", n=1), 0)
    env.world.set_obstacles([Obstacle("wall", x0=0.1, y0=-1, x1=0.1, y1=1), Obstacle("circle", x=0, y=3.3, r=0.1)])
    env.advance(20_000)
    line = env.world_line()
    assert line == _as_json(env)
    assert json.loads(line)["contacts"] == [["n-1", "obstacle-0"], ["u", "obstacle-1"]]
    assert env.world.collisions == 2
    env.world.place("u", 0.0, 6.0, 0.0)
    env.world.bodies["n-1"].pose[0] = -1.0
    env.advance(40_000)
    assert '"contacts"' not in env.world_line() and env.world_line() == _as_json(env)
