"""``RadioClient.on_built`` takes the environment's own messages in memory without ``wire.check``: whatever the
environment builds, the node must end as the checked way (``_on_down``) leaves it, a refused message counted
as malformed and dropped."""

from __future__ import annotations

import asyncio
import math
import warnings

from radio_hub.coordinator import Coordinator
from radio_hub.environment import EnvironmentConfig
from radio_hub.link import wire
from radio_hub.link.port import RadioClient, RadioIdentity
from tests.unit.test_port_transmit import RecordingLink


def _checked_and_built(messages: list[wire.Message]) -> tuple[RadioClient, RadioClient]:
    """Two nodes, one taking ``messages`` the checked way, the other on_built."""

    async def take() -> tuple[RadioClient, RadioClient]:
        checked, built = _radio(), _radio()
        for msg in messages:
            checked._on_down(msg)
            built.on_built(msg)
        return checked, built

    return asyncio.run(take())


def _radio() -> RadioClient:
    radio = RadioClient(RecordingLink(), "w", RadioIdentity("r", 0x1234, 1, 0x1000, 11, (0.0, 0.0)))
    radio._ultrasonic_deg = (0.0,) * 8  # as an Attached would have said (the default config: eight sensors)
    return radio


def _sensors_after_a_hostile_drive() -> list[wire.Sensors]:
    """A robot's sensors after a Drive of finite, huge speeds. The world's rotation of such a command into the
    world frame overflowed (inf), clipping made it nan, and the body's odometry was nan for good; the world now
    refuses a command beyond ``MAX_RATE``."""
    coordinator = Coordinator(EnvironmentConfig(), 1, wall_epoch_us=0, in_memory=True)
    env = coordinator.env
    env.receive("r", wire.Attach(ext_addr=1, position=[0.0, 0.0], heading_deg=45.0, kind="robot", n=1), 0)
    env.receive("r", wire.Drive(vx=1.5e308, vy=-1.5e308, omega=0.0, n=2), 0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for tick in range(1, 5):
            env.advance(tick * 20_000)
    return [m for m in coordinator.take_downs()["r"] if type(m) is wire.Sensors]


def test_sensors_after_a_hostile_drive_stay_finite_and_are_taken_alike_both_ways() -> None:
    sensors = _sensors_after_a_hostile_drive()
    assert sensors and all(map(math.isfinite, sensors[-1].odometry))  # the drive was refused, the body kept
    checked, built = _checked_and_built(sensors)
    assert (checked.malformed, built.malformed) == (0, 0)
    assert checked.sensors is not None and built.sensors is not None
    assert built.sensors.odometry == checked.sensors.odometry


def test_beacons_and_sensors_with_odd_floats_are_refused_on_built_as_by_the_check() -> None:
    odd = [
        wire.Sensors(t_us=1, ranges=bytes(32), yaw=math.nan, odometry=[0.0, 0.0, 0.0], n=1),
        wire.Sensors(t_us=1, ranges=bytes(32), yaw=0.0, odometry=[0.0, math.inf, 0.0], n=2),
        wire.IrBeacons(sources=["u"], readings=bytes(48), t_us=1, gains=[math.nan], n=3),
        wire.Sensors(t_us=1, ranges=bytes(32), yaw=1e308, odometry=[1e308, 1e308, 0.0], n=4),  # finite: taken
    ]
    checked, built = _checked_and_built(odd)
    assert checked.malformed == 3 and checked.sensors is not None
    assert (built.malformed, built.faults.total) == (3, checked.faults.total)
    assert built.sensors is not None and (built.sensors.yaw_rad, built.sensors.odometry) == (1e308, (1e308, 1e308, 0.0))
