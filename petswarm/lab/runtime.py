"""Which local processes are petswarm robots: a registry in a private runtime directory.

``petswarm chaos kill|pause|resume`` signals a process, so the pid must never come from the network (a
rogue answering for a robot would have its choice of victim). Each robot process registers itself in
``$XDG_RUNTIME_DIR/petswarm`` (else ``~/.cache/petswarm/run``), a directory of mode 0700 that only its
owner can write: world, robot id, pid, the process's start time and a random token. Before a signal the
registration must be ours, the pid above 1, and ``/proc/<pid>`` must still be that process (same start
time, a ``petswarm robot`` command line for that id and world): anything else is refused with the reason.
"""

from __future__ import annotations

import json
import os
import secrets
import stat
from pathlib import Path
from typing import Any

from radio_hub.interface import DEFAULT_WORLD, check_name


class NotOurRobot(Exception):
    """The target is not a petswarm robot process of that world on this host, run by this user."""


def runtime_dir() -> Path:
    """The private runtime directory, made 0700 if missing; NotOurRobot if it is not private."""
    base = os.environ.get("XDG_RUNTIME_DIR")
    path = Path(base, "petswarm") if base else Path.home() / ".cache" / "petswarm" / "run"
    path.mkdir(mode=0o700, parents=True, exist_ok=True)
    info = path.stat()
    if info.st_uid != os.getuid() or info.st_mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise NotOurRobot(f"{path} must belong to this user with mode 0700 (it is {stat.filemode(info.st_mode)})")
    return path


def _entry(world: str, robot: int) -> Path:
    return runtime_dir() / f"{check_name('world', world)}.robot-{int(robot)}.json"


def stat_fields(pid: int | str = "self") -> list[str]:
    """The fields of /proc/<pid>/stat after the command name (which may hold spaces): index k is field k + 3
    of proc(5). OSError when there is no such process."""
    return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()


def start_time(pid: int) -> int:
    """The process's start time in clock ticks since boot (/proc/<pid>/stat field 22): a pid, once reused,
    has another."""
    return int(stat_fields(pid)[19])


def register(world: str, robot: int) -> Path | None:
    """Register this process as robot ``robot`` of ``world``; None where there is no /proc (not Linux)."""
    try:
        started = start_time(os.getpid())
    except (OSError, ValueError, IndexError):
        return None
    entry = _entry(world, robot)
    body = {"world": world, "robot": robot, "pid": os.getpid(), "start": started, "token": secrets.token_hex(16)}
    part = entry.with_suffix(".part")
    fd = os.open(part, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        json.dump(body, f)
    os.replace(part, entry)
    return entry


def unregister(entry: Path | None) -> None:
    """Remove this process's registration (only if it is still this process's)."""
    if entry is None:
        return
    try:
        if json.loads(entry.read_text()).get("pid") == os.getpid():
            entry.unlink()
    except (OSError, ValueError):
        pass


def robot_pid(world: str, robot: int) -> int:
    """The pid of robot ``robot`` of ``world`` on this host, checked as the module says; NotOurRobot if not."""
    entry = _entry(world, robot)
    try:
        info = entry.stat()
        body: dict[str, Any] = json.loads(entry.read_text())
        pid, started = int(body["pid"]), int(body["start"])
    except FileNotFoundError:
        raise NotOurRobot(f"no robot {robot} of world {world!r} runs on this host (not registered)") from None
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise NotOurRobot(f"robot {robot}'s registration {entry} is unreadable: {err}") from None
    if info.st_uid != os.getuid():
        raise NotOurRobot(f"{entry} does not belong to this user")
    if pid <= 1:
        raise NotOurRobot(f"refusing pid {pid}: never a robot")
    check_process(pid, started, world, robot)
    return pid


def check_process(pid: int, started: int, world: str, robot: int) -> None:
    """NotOurRobot unless ``pid`` is still the registered ``petswarm robot`` of that id and world."""
    try:
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace").split("\0")
        now_started = start_time(pid)
    except (OSError, ValueError, IndexError):
        raise NotOurRobot(f"robot {robot} (pid {pid}) is not running on this host") from None
    if now_started != started:
        raise NotOurRobot(f"pid {pid} is another process now (robot {robot} ended and its pid was reused)")
    if not is_robot_command(argv, world, robot):
        shown = " ".join(argv).strip()[:200]
        raise NotOurRobot(f"pid {pid} is not petswarm robot {robot} of world {world!r}: {shown!r}")


def is_robot_command(argv: list[str], world: str, robot: int) -> bool:
    """Whether a command line is ``petswarm robot`` (or ``python -m cli robot``) for that robot and world."""
    args = [a for a in argv if a]
    try:
        at = args.index("robot")
    except ValueError:
        return False
    launcher = " ".join(args[:at])
    if "petswarm" not in launcher and "cli" not in args[:at]:
        return False
    options = _options(args[at + 1 :])
    return options.get("--world", DEFAULT_WORLD) == world and options.get("--id") in (str(robot), "auto")


def _options(args: list[str]) -> dict[str, str]:
    options: dict[str, str] = {}
    for i, arg in enumerate(args):
        if arg.startswith("--") and "=" in arg:
            name, value = arg.split("=", 1)
            options[name] = value
        elif arg.startswith("--") and i + 1 < len(args):
            options[arg] = args[i + 1]
    return options
