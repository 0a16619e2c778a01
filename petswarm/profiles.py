"""Named testbed profiles, the robots' and wearables' half (the hub's half is ``radio_hub.profiles``).

``ideal`` (the default) is today's robot: a frame reaches the air the moment the middleware sends it, a
received one reaches the middleware the moment it ends, the belt reports a rotation with the gyro sample
that shows it. ``kim2017`` is the swarm paper's testbed: an MCU and a UART between the middleware and the
802.15.4 module (``petswarm.managers.serial_link``), the organizing steps' deadline that such a link needs,
and the belt's recognition delay. Every value's source is in docs/PROFILES.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from petswarm.managers.serial_link import LinkTiming

PROFILES = ("ideal", "kim2017")
"""The profiles ``--profile`` takes (the hub's ``radio_hub.profiles.PROFILES`` names the same)."""
DEFAULT_PROFILE = "ideal"


@dataclass(frozen=True)
class RobotProfile:
    """A robot's own hardware and its middleware's timing under a profile."""

    link: LinkTiming = field(default_factory=LinkTiming)
    step_deadline_s: float | None = None
    """The organizing steps' deadline (None: the robot's default, ``--step-deadline``)."""


@dataclass(frozen=True)
class WearableProfile:
    """The belt's timing under a profile."""

    recognition_delay_s: float = 0.0
    """From the gyro sample that shows a rotation to the belt's report of it (its MCU's recognition)."""


_ROBOTS = {
    "ideal": RobotProfile(),
    "kim2017": RobotProfile(
        link=LinkTiming(uart_bps=38400.0, frame_overhead_bytes=9, mcu_min_s=0.001, mcu_max_s=0.005),
        step_deadline_s=0.53,
    ),
}
_WEARABLES = {"ideal": WearableProfile(), "kim2017": WearableProfile(recognition_delay_s=0.84)}


def check_profile(name: str) -> str:
    """``name`` when it is a known profile; ValueError naming the known ones otherwise."""
    if name not in PROFILES:
        raise ValueError(f"unknown profile {name!r}: one of {', '.join(PROFILES)}")
    return name


def robot_profile(name: str) -> RobotProfile:
    """The robot's half of profile ``name``."""
    return _ROBOTS[check_profile(name)]


def wearable_profile(name: str) -> WearableProfile:
    """The wearables' half of profile ``name``."""
    return _WEARABLES[check_profile(name)]
