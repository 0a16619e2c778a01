"""The control channel of robot processes: how the CLI and tests ask a running robot to do things.

Each robot serves a queryable ``petswarm/<world>/robot/<id>/ctl`` taking a msgpack map ``{"cmd": ...}``
and answering a map; it also listens on ``petswarm/<world>/robots/ctl`` for commands to all robots at
once (no answer), which lets a test make several robots act in the same instant.
"""

from __future__ import annotations

import asyncio
import itertools
import time
from collections.abc import Awaitable, Callable, Coroutine
from typing import TYPE_CHECKING, Any

import msgpack

from petswarm.wearables.user_link import robot_node
from radio_hub.interface import Keys
from radio_hub.values import HubUnavailable

if TYPE_CHECKING:
    import zenoh

    from radio_hub.interface import RadioClient
    from radio_hub.values import Faults, Relayed

HUB_NODE = "hub"
"""The name the hub's relay gives the hub itself."""


def robot_key(keys: Keys, robot_id: int) -> str:
    """The control queryable of one robot."""
    return f"{keys.prefix}/robot/{robot_id}/ctl"


def all_robots_key(keys: Keys) -> str:
    """The control topic every robot listens to."""
    return f"{keys.prefix}/robots/ctl"


def command(
    session: zenoh.Session, keys: Keys, robot_id: int, cmd: str, timeout: float = 5.0, **args: Any
) -> dict[str, Any]:
    """Send one command to one robot and return its answer; HubUnavailable if it does not answer."""
    payload = msgpack.packb({"cmd": cmd, **args}, use_bin_type=True)
    started = time.monotonic()
    for reply in session.get(robot_key(keys, robot_id), payload=payload, timeout=timeout):
        if reply.ok is not None:
            return msgpack.unpackb(reply.ok.payload.to_bytes(), raw=False, strict_map_key=False)
    if time.monotonic() - started < timeout * 0.9:  # zenoh ends a query at once when nobody serves the key
        raise HubUnavailable(f"no robot {robot_id} serves world {keys.world!r} (not running, or not attached yet)")
    raise HubUnavailable(f"robot {robot_id} of world {keys.world!r} did not answer {cmd!r} within {timeout} s")


def broadcast(session: zenoh.Session, keys: Keys, cmd: str, **args: Any) -> None:
    """Send one command to every robot of the world at once."""
    session.put(all_robots_key(keys), msgpack.packb({"cmd": cmd, **args}, use_bin_type=True))


class RelayControl:
    """The control channel of model and lockstep runs: commands to robots and questions to the hub, carried
    by the hub's relay on model time (so they happen at the same instants in every exact clock).

    ``radio`` is a ``control`` node's radio; a robot answers relayed commands as its control queryable would.
    """

    def __init__(self, radio: RadioClient) -> None:
        self.radio = radio
        self._ids = itertools.count(1)
        self._pending: dict[int, asyncio.Future[dict[str, Any]]] = {}
        radio.on_relayed = self._answered

    async def command(self, robot_id: int, cmd: str, timeout: float = 5.0, **args: Any) -> dict[str, Any]:
        """One command to one robot; HubUnavailable when there is no such robot or it does not answer."""
        return await self._ask(robot_node(robot_id), {"cmd": cmd, **args}, timeout)

    async def hub(self, op: str, timeout: float = 5.0, **args: Any) -> dict[str, Any]:
        """A question to the hub: ``stats``, ``world``, or ``chaos`` with ``request={...}``."""
        return await self._ask(HUB_NODE, {"op": op, **args}, timeout)

    async def sleep(self, seconds: float) -> None:
        """Model time goes on."""
        await asyncio.sleep(seconds)

    async def _ask(self, to: str, body: dict[str, Any], timeout: float) -> dict[str, Any]:
        ask_id = next(self._ids)
        future: asyncio.Future[dict[str, Any]] = asyncio.get_running_loop().create_future()
        self._pending[ask_id] = future
        try:
            self.radio.relay(to, msgpack.packb({**body, "id": ask_id}, use_bin_type=True))
            async with asyncio.timeout(timeout):
                return await future
        except TimeoutError:
            what = body.get("cmd") or body.get("op")
            raise HubUnavailable(f"{to} did not answer {what!r} within {timeout} s") from None
        finally:
            self._pending.pop(ask_id, None)

    def _answered(self, msg: Relayed) -> None:
        try:
            body = msgpack.unpackb(msg.body, raw=False, strict_map_key=False)
            future = self._pending.get(body["id"])
        except Exception:  # not an answer to us: nothing waits for it
            return
        if future is None or future.done():
            return
        if msg.bounced:
            future.set_exception(HubUnavailable(f"no node {msg.frm} in world {self.radio.world!r}"))
        else:
            future.set_result(body.get("answer") or {})


async def guarded_handle(
    handle: Callable[[dict[str, Any]], Awaitable[dict[str, Any]]], cmd: dict[str, Any], faults: Faults
) -> dict[str, Any]:
    """``handle(cmd)``, or an error answer when it raises something nobody expected (counted in ``faults``)."""
    try:
        return await handle(cmd)
    except Exception as err:
        faults.record("command", err, str(cmd.get("cmd"))[:64])
        return {"error": f"{type(err).__name__}: {err}"}


def answer_relayed(
    handle: Callable[[dict[str, Any]], Awaitable[dict[str, Any]]],
    radio: RadioClient,
    spawn: Callable[[Coroutine[Any, Any, None]], None],
) -> Callable[[Relayed], None]:
    """A robot's handler of relayed commands: carry each out with ``handle`` (as a task made by ``spawn``) and
    relay the answer back."""

    async def serve(msg: Relayed) -> None:
        try:
            cmd = msgpack.unpackb(msg.body, raw=False, strict_map_key=False)
            if not isinstance(cmd, dict):
                raise ValueError("command is not a map")
        except Exception as err:  # garbage on the control channel must not hurt the robot
            answer: dict[str, Any] = {"error": f"malformed command: {type(err).__name__}"}
            cmd = {}
        else:
            answer = await guarded_handle(handle, cmd, radio.faults)
        radio.relay(msg.frm, msgpack.packb({"id": cmd.get("id"), "answer": answer}, use_bin_type=True))

    return lambda msg: spawn(serve(msg))
