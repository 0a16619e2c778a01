"""The environment sweeps IR beacons with the body sensors: 25 Hz, at the very instants the sensors go out."""

from __future__ import annotations

from collections import defaultdict
from typing import Any

from radio_hub.environment import Environment, EnvironmentConfig
from radio_hub.link import wire


class Recorder:
    """A downlink that keeps every message it is given, decoded."""

    def __init__(self) -> None:
        self.messages: dict[str, list[wire.Message]] = defaultdict(list)

    def send(self, node_id: str, data: bytes) -> None:
        self.messages[node_id].append(wire.decode(data))

    def forget(self, node_id: str) -> None:
        pass

    def publish_world(self, state: dict[str, Any]) -> None:
        pass


def _attach(env: Environment, node_id: str, x: float, kind: str, mode: str) -> None:
    env.receive(node_id, wire.Attach(ext_addr=len(node_id), position=[x, 0.0], kind=kind, n=1).encode(), 0)
    env.receive(node_id, wire.SetIrMode(token=1, mode=mode, n=2).encode(), 0)


def test_beacons_are_swept_with_the_body_sensors_and_only_then() -> None:
    downlink = Recorder()
    env = Environment(EnvironmentConfig(), 1, downlink)
    for k in range(3):
        _attach(env, f"robot-{k}", 0.5 * k, "robot", "beacon")
    _attach(env, "user", -0.5, "user", "beacon")
    now, instants = 0, 0
    while now <= 1_000_000:
        env.advance(now)
        instants += 1
        now = env.next_event_us()
    for k in range(3):
        got = downlink.messages[f"robot-{k}"]
        sensors = [m.t_us for m in got if isinstance(m, wire.Sensors)]
        beacons = [m for m in got if isinstance(m, wire.IrBeacons)]
        assert len(sensors) == 25
        assert [m.t_us for m in beacons] == sensors  # one sweep per sample, at its instant
        assert sorted(beacons[-1].sources) == sorted({"robot-0", "robot-1", "robot-2", "user"} - {f"robot-{k}"})
    assert env.stats()["ir"]["beacon_sweeps"] == 25
    assert env.stats()["ir"]["sweeps"] == 0  # nothing transmits: no receive sweeps,
    assert instants <= 52  # and no IR instants besides the world's 50 Hz ticks
