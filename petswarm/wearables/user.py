"""The user process: a person walking a scripted path, wearing a smart belt and a smart watch.

- The person: every world tick the process tells the hub where the person is (``place``); the hub
  records it as ground truth. The walk follows the scenario's legs (walk, turn, stop).
- The belt: its LF front end hears bursts (from the hub's LF field); a burst with the pattern in its
  register wakes it. A wake-up burst within 1 m makes it answer the robot over BLE (``owner``); tracking
  bursts (left, then right antenna) become a pair of distances, reported over BLE (``lf``). Its IMU,
  emulated from the walk, feeds the activity recognizer; the activity goes to the owner every gyro
  sample (70 ms).
- The watch: the scenario's requests, sent over BLE to the owner at their times.
- Re-pairing: when the owner hands the master's role to another robot it says so over BLE (``pair``); the
  belt then wakes on the new robot's pattern and reports to it (the project's protocol; the paper has none).

Everything is recorded as structured events (``EventLog``), flushed per event.
"""

from __future__ import annotations

import asyncio
import math
import sys
from dataclasses import dataclass

import numpy as np

from petswarm.managers.event_log import EventLog
from petswarm.profiles import wearable_profile
from petswarm.wearables import user_link
from petswarm.wearables.activity import ActivityRecognizer
from petswarm.wearables.imu import ACCEL_PERIOD_S, GYRO_PERIOD_S, BeltImu
from petswarm.wearables.lf_location import rssi_to_distance
from petswarm.wearables.plan import UserPlan
from radio_hub.datasheet import LfConfig, wake_pattern, wakes
from radio_hub.interface import HubLink, RadioClient
from radio_hub.values import BleMessage, HubUnavailable, LfBurstHeard, RadioError, RadioIdentity

PLACE_PERIOD_S = 0.02
"""The person's pose goes to the hub at the world's tick rate."""


@dataclass
class UserConfig:
    """One user process."""

    plan: UserPlan
    endpoint: str
    world: str
    duration_s: float
    seed: int = 0
    beacon: bool = False
    """The person wears an IR beacon (surround scenarios): the surround robots see him by it."""
    profile: str = "ideal"
    """The testbed profile (``petswarm.profiles``): the belt's recognition delay."""


class User:
    """The person, the belt and the watch."""

    def __init__(self, config: UserConfig, client: RadioClient, log: EventLog) -> None:
        self.config = config
        self.plan = config.plan
        self.client = client
        self.log = log
        self.owner = user_link.robot_node(self.plan.owner)
        self.register = wake_pattern(self.plan.owner)
        self.lf_config = LfConfig()
        """The belt's calibration: the module's datasheet curve, whatever the hub's noise settings."""
        rng = np.random.default_rng([config.seed, 7])
        self.imu = BeltImu(rng)
        self.recognizer = ActivityRecognizer()
        self.recognition_delay_s = wearable_profile(config.profile).recognition_delay_s
        self.owned = False
        self.counters = {"bursts": 0, "ignored": 0, "lf_reports": 0, "activity": 0, "requests": 0, "bad_ble": 0}
        self._pairs: dict[int, dict[str, float]] = {}
        self._t0 = 0.0
        self._rotation_reported: float | None = None
        self._beacon_task: asyncio.Task[None] | None = None

    async def wear_beacon(self) -> None:
        """Switch the IR module to beacon mode, and again after a restarted hub (it forgets IR modes)."""
        await self.client.set_ir_mode("beacon")
        self.client.on_reattach.append(self._beacon_again)

    def _beacon_again(self) -> None:
        self._beacon_task = asyncio.get_running_loop().create_task(self.client.set_ir_mode("beacon"))

    def now(self) -> float:
        """Seconds since the user process started its scenario."""
        return asyncio.get_running_loop().time() - self._t0

    async def run(self) -> None:
        """Walk, listen and request until the scenario's duration is over."""
        self._t0 = asyncio.get_running_loop().time()
        self.log.record(
            "start", role="user", owner=self.owner, turns_at=self.plan.turn_starts(), beacon=self.config.beacon
        )
        tasks = [
            asyncio.create_task(self._walk()),
            asyncio.create_task(self._belt_lf()),
            asyncio.create_task(self._belt_ble()),
            asyncio.create_task(self._watch()),
        ]
        try:
            await asyncio.sleep(self.config.duration_s)
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            self.log.record("stop", role="user", **self.counters)

    async def _walk(self) -> None:
        next_accel = next_gyro = 0.0
        while True:
            t = self.now()
            x, y, yaw, vx, vy, omega = self.plan.pose_at(t)
            self.client.place(x, y, yaw, vx, vy, omega)
            speed = math.hypot(vx, vy)
            while next_accel <= t:
                self.recognizer.add_accel(next_accel, self.imu.accel_z(next_accel, speed))
                next_accel += ACCEL_PERIOD_S
            while next_gyro <= t:
                self.recognizer.add_gyro(next_gyro, self.imu.gyro_z(next_gyro, omega))
                self._report_activity(next_gyro)  # the activity as of this gyro sample
                next_gyro += GYRO_PERIOD_S
            await asyncio.sleep(PLACE_PERIOD_S)

    def _report_activity(self, t: float) -> None:
        activity = self.recognizer.activity(t)
        started = self.recognizer.rotation_started_at
        if activity.rotating and started is not None and started != self._rotation_reported:
            self._rotation_reported = started
            self.log.record("rotation_detected", at=round(started, 3), user_t=round(t, 3))
        if self.owned:
            self.counters["activity"] += 1
            report = user_link.encode("activity", t=round(t, 3), **activity.to_dict())
            if self.recognition_delay_s:  # the belt's MCU takes this long to recognise and report
                loop = asyncio.get_running_loop()
                loop.call_later(self.recognition_delay_s, self.client.ble_send, self.owner, report)
            else:
                self.client.ble_send(self.owner, report)

    async def _belt_lf(self) -> None:
        while True:
            burst = await self.client.lf_heard()
            try:
                self._on_burst(burst)
            except Exception as err:  # one odd burst must not deafen the belt
                self.client.faults.record("lf", err)

    def _on_burst(self, burst: LfBurstHeard) -> None:
        self.counters["bursts"] += 1
        if not wakes(self.register, burst.pattern):
            self.counters["ignored"] += 1  # another robot's pattern: the wake-up receiver stays asleep
            return
        try:
            robot_id, seq, purpose = user_link.parse_lf_data(burst.data)
        except ValueError:
            self.counters["ignored"] += 1
            return
        distance = rssi_to_distance(burst.rssi_dbm, self.lf_config)
        if purpose == user_link.LF_WAKE:
            if distance <= self.lf_config.wake_range_m:
                # the burst's sequence byte is the robot's challenge: echoing it proves the belt heard the LF
                owner = user_link.encode("owner", d=round(distance, 3), seq=seq)
                self.client.ble_send(user_link.robot_node(robot_id), owner)
                self.log.record("owner_reply", robot=robot_id, d=round(distance, 3))
            return
        pair = self._pairs.setdefault(seq, {})
        pair[burst.antenna] = distance
        if len(pair) == 2:
            del self._pairs[seq]
            self.counters["lf_reports"] += 1
            self.client.ble_send(
                user_link.robot_node(robot_id), user_link.encode("lf", seq=seq, dl=pair["left"], dr=pair["right"])
            )
        for old in [s for s in self._pairs if (seq - s) % 256 > 4]:
            del self._pairs[old]  # a pair whose other burst never came

    async def _belt_ble(self) -> None:
        while True:
            message = await self.client.ble_receive()
            try:
                self._on_ble(message)
            except Exception as err:  # one odd message must not deafen the wearable
                self.counters["bad_ble"] += 1
                self.client.faults.record("ble", err)

    def _on_ble(self, message: BleMessage) -> None:
        """One BLE message from a robot: owner state, a re-pairing, or something to record."""
        try:
            body = user_link.decode(message.payload)
        except ValueError:
            self.counters["bad_ble"] += 1
            return
        if body["k"] == "state" and message.src == self.owner:
            self.owned = body.get("state") not in ("waiting", None)
        if body["k"] == "pair" and message.src == self.owner and not self._repair(body.get("robot")):
            return
        self.log.record(f"ble_{body['k']}", src=message.src, **{k: v for k, v in body.items() if k != "k"})

    def _repair(self, robot: object) -> bool:
        """The owner handed the master's role to ``robot``: wake on its pattern and report to it from now.
        False (counted as bad BLE) when ``robot`` is not a robot id."""
        if not isinstance(robot, int) or isinstance(robot, bool) or not 0 < robot <= 0xFFFF:
            self.counters["bad_ble"] += 1
            return False
        self.log.record("repaired", frm=self.owner, to=user_link.robot_node(robot))
        self.owner, self.register = user_link.robot_node(robot), wake_pattern(robot)
        self._pairs.clear()
        return True

    async def _watch(self) -> None:
        for request in self.plan.watch:
            await asyncio.sleep(max(0.0, request.at - self.now()))
            self.counters["requests"] += 1
            self.client.ble_send(self.owner, user_link.encode("request", request=request.request, **request.args))
            self.log.record("request", request=request.request, **request.args)


async def run_user(config: UserConfig, log: EventLog, attach_timeout: float = 15.0, link: HubLink | None = None) -> int:
    """The user process's main coroutine; returns the exit code. ``link``: the port to the hub (default zenoh
    to ``config.endpoint``)."""
    plan = config.plan
    x, y, yaw = plan.start
    identity = RadioIdentity(plan.node_id, 0, 0, 0, position=(x, y), heading_deg=math.degrees(yaw), kind="user")
    deadline = asyncio.get_running_loop().time() + attach_timeout
    while True:
        try:
            client = await RadioClient.connect(identity, config.endpoint, config.world, link=link, timeout=1.0)
            break
        except HubUnavailable as err:
            if asyncio.get_running_loop().time() >= deadline:
                print(f"user: {err}", file=sys.stderr)
                return 2
            await asyncio.sleep(0.5)
        except RadioError as err:
            print(f"user: {err}", file=sys.stderr)
            return 2
    user = User(config, client, log)
    if config.beacon:
        try:
            await user.wear_beacon()
        except (HubUnavailable, RadioError) as err:
            print(f"user: cannot switch on the IR beacon: {err}", file=sys.stderr)
            await client.close()
            return 2
    print(f"{user_name(plan.node_id)}: walking (owner robot {plan.owner})", file=sys.stderr, flush=True)
    try:
        await user.run()
    finally:
        await client.close()
    return 0


def user_name(node_id: str) -> str:
    """How logs name the user: its node id when that already says "user" (the default id is "user")."""
    return node_id if node_id.startswith("user") else f"user {node_id}"
