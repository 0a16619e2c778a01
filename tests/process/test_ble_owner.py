"""An outsider's wearable (``user-9``) tries to become a waiting robot's owner over BLE and have it organize a
swarm, against a real hub and real robot processes: the rogue is a real node attached from its own process's
session, 3 m away (within BLE's reach, beyond the LF wake-up's 1 m). It guesses every challenge byte in a row,
then asks for a swarm. The robot must refuse and count it all (``driving.unpaired``) and stay waiting.

Without the pairing (before the wearable link checked the LF challenge), the first claim made ``user-9`` the
owner and the request made robot 2 organize robot 3.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

from petswarm.wearables import user_link
from radio_hub.link.port import RadioClient, RadioIdentity

ROGUE = "user-9"
GUESSES = 256
"""Every value of the challenge byte, one after the other."""


async def _rogue_wearable(endpoint: str, world: str, robot: str) -> None:
    identity = RadioIdentity(ROGUE, 0, 0, 0, position=(3.0, 0.0), kind="user")
    radio = await RadioClient.connect(identity, endpoint, world)
    try:
        for seq in range(GUESSES):
            radio.ble_send(robot, user_link.encode("owner", d=0.3, seq=seq))
            await asyncio.sleep(0.002)
        radio.ble_send(robot, user_link.encode("request", request="organize", robots=1))
        await asyncio.sleep(1.0)  # the BLE link's latency, and the robot's turn to act on what came
    finally:
        await radio.close()


def test_an_unpaired_wearable_cannot_claim_a_robot_or_command_it_over_ble(make_air: Any) -> None:
    air = make_air()
    air.robot(2, (0.0, 0.0), 0x1000, 11)
    air.robot(3, (1.0, 0.0), 0x1000, 11)
    asyncio.run(_rogue_wearable(air.endpoint, air.world, "robot-2"))
    deadline = time.monotonic() + 20  # a robot the machine's load starves takes its messages late
    while (driving := air.cmd(2, "status")["driving"])["unpaired"] < GUESSES + 1:
        assert time.monotonic() < deadline, driving
        time.sleep(0.2)
    status = air.cmd(2, "status")
    print(f"\nrobot 2 after {GUESSES} owner claims and a request from {ROGUE}: driving {status['driving']}")
    assert status["driving"]["owner"] is None, status["driving"]
    assert status["driving"]["unpaired"] == GUESSES + 1  # every claim and the request, counted
    assert status["state"] == "waiting", status["state"]
    assert air.cmd(3, "status")["state"] == "waiting"  # no swarm was organized
    codes = air.close()
    assert codes["hub"] == 0, codes
