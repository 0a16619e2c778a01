"""Model-time test harness: real ``Robot`` objects on the hub's own environment, in this process, on model time.

The pieces are ``petswarm.lab.model_run``'s (the ones ``petswarm run --clock model`` uses): a ``ModelClockLoop`` drives
a
``MemoryAir`` (the hub's pure ``radio_hub.environment.Environment``), and every robot is the object a robot process
runs, attached through a ``MemoryLink``. Nothing sleeps in wall time: when every task waits, model time jumps to
the next timer. The same seed and the same test give the same run on any machine, loaded or idle, so a bound
asserted here is not at the mercy of the scheduler.

A test is a plain synchronous pytest function that hands a coroutine to ``run_model_time``, which makes a fresh
loop, runs the coroutine with a ``ModelWorld``, then stops every robot and closes the loop::

    def test_two_robots_form_a_swarm() -> None:
        async def body(w: ModelWorld) -> None:
            await w.robot(1, (0.0, 0.0), user=1)       # robot 1 serves user 1: it may organize
            await w.robot(2, (1.0, 0.0))               # a waiting robot
            organized = await w.command(1, "organize", count=1)
            assert organized["members"] == [2]
            await w.advance(0.5)                       # half a second of model time
            assert w.status(2)["state"] == "slave-driving"

        run_model_time(body, config=LOSSLESS, seed=1)

``ModelWorld`` offers what a test needs: start robots (``robot``) and a user walking a scenario's plan (``user``);
control commands (``command``); chaos faults (``fault``, ``clear``, ``chaos``); model time (``now``, ``advance``,
``until``); a robot's end (``kill``: as SIGKILL, ``stop``: as SIGTERM); and what happened (``events``, ``status``,
``stats``). Whole scenario runs go through ``run_scenario`` (``petswarm.lab.model_run.execute``, the ``petswarm run
SCENARIO --clock model`` path).
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Awaitable, Callable
from dataclasses import replace
from pathlib import Path
from typing import Any, TypeVar

from petswarm.clock import ModelClockLoop
from petswarm.lab.model_run import (
    ENDPOINT,
    MemoryAir,
    RunningRobot,
    cancel_leftovers,
    execute,
    scenario_options,
    start_robot,
    start_user,
)
from petswarm.managers.event_log import EventLog
from petswarm.robot import DEFAULT_PAN, Robot, RobotConfig
from petswarm.scenario import Scenario, load
from petswarm.wearables.plan import UserPlan
from petswarm.wearables.user import UserConfig
from radio_hub.environment import EnvironmentConfig, environment_from_dict

T = TypeVar("T")
ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "scenarios"
LOSSLESS: dict[str, Any] = {"range": {"success_ratio_rx": 1.0}, "path_loss": {"shadowing_sigma_db": 0.0}}
"""The process tests' hub config: every frame in range arrives unless it collides, no shadowing (so signal
strength falls with distance alone and Table 2's "closest" is the geometric one)."""
WORLD = "model-test"


class ModelWorld:
    """Robots and a user on one ``MemoryAir``, driven by a test on model time."""

    def __init__(self, air: MemoryAir, seed: int) -> None:
        self.air = air
        self.seed = seed
        self.running: dict[int, RunningRobot] = {}
        self._users: list[asyncio.Task[int]] = []

    # -- robots ------------------------------------------------------------------------------------------

    async def robot(
        self,
        rid: int,
        position: tuple[float, float] | None = None,
        heading_deg: float = 0.0,
        *,
        user: int = 0,
        pan: int = DEFAULT_PAN,
        **config: Any,
    ) -> Robot:
        """Start robot ``rid`` at ``position`` (None: its default grid place), connected to ``user`` (0: waiting);
        ``config``: more ``RobotConfig`` fields (``formation``, ``token``, ``seed``...; ``seed`` defaults to the
        world's)."""
        config.setdefault("seed", self.seed)
        robot_config = RobotConfig(
            rid, ENDPOINT, WORLD, pan_id=pan, position=position, heading_deg=heading_deg, user=user, **config
        )
        return await self._start(robot_config)

    async def _start(self, config: RobotConfig) -> Robot:
        if config.robot_id in self.running and not self.running[config.robot_id].gone:
            raise ValueError(f"robot {config.robot_id} is already running")
        running = await start_robot(config, self.air)
        self.running[config.robot_id] = running
        return running.robot

    def __getitem__(self, rid: int) -> Robot:
        """The robot object (its managers, its log) of robot ``rid``."""
        return self.running[rid].robot

    async def command(self, rid: int, cmd: str, timeout: float = 60.0, **args: Any) -> dict[str, Any]:
        """A control command, carried out as a robot process carries it out; its answer (``error`` on a refusal).
        ``timeout`` is model time: a command that hangs fails the test instead of hanging it."""
        async with asyncio.timeout(timeout):
            return await self.running[rid].command(cmd, **args)

    async def kill(self, rid: int) -> None:
        """Robot ``rid`` dies at once (SIGKILL): no last event, no detach; the air forgets it as the hub does."""
        await self.running[rid].kill()

    async def stop(self, rid: int) -> None:
        """Robot ``rid`` stops cleanly (SIGTERM): its last event, then it detaches."""
        await self.running[rid].stop()

    # -- the user ----------------------------------------------------------------------------------------

    def user(self, plan: UserPlan, duration_s: float, *, beacon: bool = False) -> EventLog:
        """A user walking ``plan`` (a scenario's ``[user]``) for ``duration_s`` from now, making its watch
        requests; the user's events are in the returned log as they happen."""
        log = EventLog()
        config = UserConfig(plan, ENDPOINT, WORLD, duration_s, self.seed, beacon=beacon)
        self._users.append(start_user(config, self.air, log))
        return log

    # -- faults ------------------------------------------------------------------------------------------

    def chaos(self, request: dict[str, Any]) -> dict[str, Any]:
        """A raw chaos request, as ``petswarm chaos`` sends it to the hub; the hub's answer."""
        return self.air.chaos(request)

    def fault(self, kind: str, **spec: Any) -> int:
        """Add a fault (``radio_hub.air.chaos``: loss, partition, ir_blind...) now; its id. Refused: ValueError."""
        answer = self.chaos({"op": "add", "fault": {"kind": kind, **spec}})
        if "error" in answer:
            raise ValueError(answer["error"])
        return max(f["fault_id"] for f in answer["faults"])

    def clear(self, fault_id: int | None = None) -> None:
        """End one fault, or every fault."""
        answer = self.chaos({"op": "clear", "id": fault_id})
        if "error" in answer:
            raise ValueError(answer["error"])

    # -- time --------------------------------------------------------------------------------------------

    @property
    def now(self) -> float:
        """Model seconds since the loop started (the robots' ``clock.now()`` and their events' ``mono``)."""
        return self.air.loop.time()

    async def advance(self, seconds: float) -> None:
        """Let ``seconds`` of model time pass (everything due meanwhile happens)."""
        await asyncio.sleep(seconds)

    async def until(self, condition: Callable[[], Any], timeout: float, period: float = 0.01) -> float | None:
        """Check ``condition`` every ``period`` of model time; the model time it first held, or None if it did
        not hold within ``timeout``."""
        deadline = self.now + timeout
        while True:
            if condition():
                return self.now
            if self.now >= deadline:
                return None
            await asyncio.sleep(period)

    # -- what happened -----------------------------------------------------------------------------------

    def events(self, rid: int, kind: str | None = None) -> list[dict[str, Any]]:
        """Robot ``rid``'s events so far (all, or those of ``kind``), in order, as its record has them."""
        events = list(self.running[rid].robot.log.events)
        return events if kind is None else [e for e in events if e["kind"] == kind]

    def status(self, rid: int) -> dict[str, Any]:
        """Robot ``rid``'s status answer (what ``petswarm`` reads over the control channel)."""
        return self.running[rid].robot.status()

    def stats(self) -> dict[str, Any]:
        """The hub's stats (per-node radio counters, IR overlaps, world, chaos)."""
        return self.air.env.stats(self.air.now_us())

    async def close(self) -> None:
        """Stop every live robot and user, then close the environment."""
        for task in self._users:
            task.cancel()
        await asyncio.gather(*self._users, return_exceptions=True)
        for running in self.running.values():
            if not running.gone:
                await running.stop()
        self.air.env.close()


def run_model_time(
    body: Callable[[ModelWorld], Awaitable[T]],
    *,
    config: EnvironmentConfig | dict[str, Any] | None = None,
    seed: int = 1,
) -> T:
    """Run ``body`` on a fresh ``ModelClockLoop`` with a ``ModelWorld`` of the given environment (a hub config
    as a map, like ``LOSSLESS``; None: the hub's defaults) and seed; return what ``body`` returns. Every robot is
    stopped and every task cancelled before the loop closes, whatever ``body`` did."""
    environment = config if isinstance(config, EnvironmentConfig) else environment_from_dict(dict(config or {}))

    async def main() -> T:
        world = ModelWorld(MemoryAir(environment, seed), seed)
        try:
            return await body(world)
        finally:
            await world.close()

    loop = ModelClockLoop()
    try:
        return loop.run_until_complete(main())
    finally:
        loop.run_until_complete(cancel_leftovers(loop))
        loop.close()


def scenario_environment(scenario: Scenario) -> EnvironmentConfig:
    """The hub tables of a scenario (world, obstacles), as ``petswarm hub --scenario`` takes them."""
    return environment_from_dict(scenario.hub_tables())


def run_scenario(scenario: str | Path | Scenario, seed: int, record: Path, **changes: Any) -> dict[str, Any]:
    """``petswarm run SCENARIO --clock model --seed SEED --record RECORD``: the summary (``driving`` metrics,
    ``digest``, ``model_time_s``...). ``changes``: fields of the scenario to replace (``duration_s``...)."""
    loaded = scenario if isinstance(scenario, Scenario) else load(Path(scenario))
    if changes:
        loaded = replace(loaded, **changes)
    opts = scenario_options(loaded, seed, record)
    return execute(opts, loaded)


def record_events(record: Path, node: str) -> list[dict[str, Any]]:
    """The events of ``node`` (``robot-2``, ``user``) in a run record."""
    return [json.loads(line) for line in (record / "events" / f"{node}.jsonl").read_text().splitlines()]
