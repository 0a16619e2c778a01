"""compose.yaml for real: the image built and the stack run under a Docker engine, driven as the README says.

One stack for the module, in order: build (cold, then after a source change), `up --wait --scale robot=5`,
a swarm of 3 organized through `docker compose exec`, a fault in the air, docker's process faults on one
replica (pause, crash), a hub restart, a member's container stopped, and `down`. The tests run in file order
and share the stack; anything the module added to the engine (containers, network, images) is removed at the
end, and an engine it started is stopped. Without an engine the module skips, except where one is expected
(CI: .ci/run installs and starts it), where it fails. Figures (build, up, memory) are printed at the end."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from typing import Any

import pytest

from petswarm import control
from petswarm.lab.processes import free_tcp_port
from radio_hub.interface import Keys, open_session, query_hub
from radio_hub.values import HubUnavailable

from ..waiting import wait_for
from .engine import (
    BASE_IMAGE,
    ROOT,
    Stack,
    copy_build_context,
    docker,
    engine_is_ours,
    ensure_base_image,
    ensure_engine,
    stop_engine,
)

pytestmark = [pytest.mark.compose, pytest.mark.long, pytest.mark.timeout(900)]

ROBOTS = 5
SEED, WORLD = "7", "compose-test"  # not compose.yaml's defaults: the test sees that both settings are read
FIGURES: dict[str, Any] = {}
SWARM: dict[str, Any] = {}


@pytest.fixture(scope="module")
def stack(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Stack]:
    started_engine = ensure_engine()
    work = tmp_path_factory.mktemp("compose")
    built: Stack | None = None
    base_added = None
    images: list[str] = []  # the first build's image: the rebuild after the source change takes its tag
    try:
        t = time.monotonic()
        base_added = ensure_base_image(work)
        FIGURES["base_image"] = (base_added or "present", time.monotonic() - t)
        copy_build_context(ROOT, work / "repo")
        env = {"PETSWARM_SEED": SEED, "PETSWARM_WORLD": WORLD}
        built = Stack(work / "repo", f"petswarm-test-{uuid.uuid4().hex[:8]}", env, free_tcp_port(), free_tcp_port())
        t = time.monotonic()
        built.compose("--progress", "plain", "build", timeout=900)
        FIGURES["build_first_s"] = time.monotonic() - t
        images.append(docker("image", "inspect", "--format", "{{.Id}}", built.image).stdout.strip())
        source = built.dir / "petswarm/lab/arguments.py"  # a source change, in the copy
        source.write_text(source.read_text() + "\n# a source change\n")
        t = time.monotonic()
        warm = built.compose("--progress", "plain", "build", timeout=300)
        FIGURES["build_warm_s"] = time.monotonic() - t
        FIGURES["warm_output"] = warm.stdout + warm.stderr
        t = time.monotonic()
        built.compose("up", "-d", "--wait", "--no-build", "--scale", f"robot={ROBOTS}", timeout=180)
        FIGURES["up_healthy_s"] = time.monotonic() - t
        yield built
    finally:
        if built is not None:
            built.compose("down", "--volumes", "--remove-orphans", "--timeout", "10", timeout=120, check=False)
            docker("image", "rm", "--force", built.image, *images, check=False)
        if base_added and os.environ.get("PETSWARM_KEEP_BASE_IMAGE") != "1":
            docker("image", "rm", BASE_IMAGE, check=False)
        if engine_is_ours():  # an engine of ours (.ci/run's or this test's): leave no build cache in it either
            docker("builder", "prune", "--all", "--force", timeout=120, check=False)
        if started_engine:
            stop_engine()


def _hub(stack: Stack, key: str = "stats", timeout: float = 2.0) -> dict[str, Any]:
    """Ask the hub from the host, through its published port."""
    session = open_session("client", stack.hub_endpoint)
    try:
        return query_hub(session, getattr(Keys(stack.world), key), timeout=timeout)
    finally:
        session.close()


def _robot(stack: Stack, rid: int, cmd: str = "status", timeout: float = 2.0) -> dict[str, Any]:
    """A control command to one robot, from the host."""
    session = open_session("client", stack.hub_endpoint)
    try:
        return control.command(session, Keys(stack.world), rid, cmd, timeout)
    finally:
        session.close()


def _attached(stack: Stack) -> set[int]:
    nodes = _hub(stack)["nodes"]
    return {int(name.split("-")[1]) for name, n in nodes.items() if name.startswith("robot-") and n["attached"]}


def _health(container: str) -> str:
    return docker(
        "inspect", "--format", "{{if .State.Health}}{{.State.Health.Status}}{{end}}", container
    ).stdout.strip()


def _container_of(stack: Stack, rid: int) -> str:
    owners = {c: stack.robot_of(c) for c in stack.containers("robot")}
    found = [c for c, r in owners.items() if r == rid]
    assert len(found) == 1, f"robot {rid} in containers {owners}"
    return found[0]


def test_up_gives_a_healthy_hub_and_five_attached_robots_that_run_as_configured(stack: Stack):
    hub = stack.containers("hub")
    robots = stack.containers("robot")
    assert len(hub) == 1 and len(robots) == ROBOTS
    assert _health(hub[0]) == "healthy"
    assert [_health(c) for c in robots] == ["healthy"] * ROBOTS
    # --id auto: the replicas took ids 1..5, and each is attached to the hub
    assert sorted(stack.robot_of(c) or 0 for c in robots) == list(range(1, ROBOTS + 1))
    wait_for("5 robots attached", lambda: _attached(stack) == set(range(1, ROBOTS + 1)), 20)
    stats = _hub(stack)
    assert (stats["seed"], stats["world"]) == (int(SEED), WORLD)  # PETSWARM_SEED and PETSWARM_WORLD were read
    # the host's own `petswarm stats` reaches the hub through the published port
    argv = [sys.executable, "-m", "cli", "stats", "--hub", stack.hub_endpoint, "--world", WORLD]
    host = subprocess.run(argv, capture_output=True, text=True, timeout=60)
    assert host.returncode == 0 and f"seed {SEED}" in host.stdout, host.stderr
    # nothing runs as root, and the root filesystem is read-only
    assert stack.compose("exec", "-T", "hub", "id", "-u").stdout.strip() != "0"
    assert stack.compose("exec", "-T", "--index", "1", "robot", "id", "-u").stdout.strip() != "0"
    denied = stack.compose("exec", "-T", "hub", "touch", "/app/x", check=False)
    assert denied.returncode != 0
    memory = stack.memory_mib(robots)
    FIGURES["robot_mib"] = (min(memory), sum(memory) / len(memory), max(memory))
    FIGURES["hub_mib"] = stack.memory_mib(hub)[0]


def test_a_source_change_rebuilds_the_sources_only(stack: Stack):
    assert "Collecting" not in FIGURES["warm_output"], "the dependencies were installed again"
    assert FIGURES["build_warm_s"] < 30, FIGURES["build_warm_s"]


def test_a_swarm_of_three_organized_through_compose_exec_and_a_fault_in_the_air(stack: Stack):
    organized = stack.petswarm("swarm", "organize", "--master", "1", "--count", "3", "--user", "1", "--json")
    answer = json.loads(organized.stdout)
    assert len(answer["members"]) == 3 and 1 not in answer["members"], answer
    SWARM["members"] = sorted(answer["members"])
    FIGURES["organize_ms"] = answer["organize_time_s"] * 1000
    assert _robot(stack, 1)["state"] == "master-driving"
    status = json.loads(stack.petswarm("swarm", "status", "--robot", str(SWARM["members"][0]), "--json").stdout)
    assert status["state"] == "slave-driving", status["state"]
    stack.petswarm("chaos", "loss", "--p", "0.3")
    faults = json.loads(stack.petswarm("chaos", "list", "--json").stdout)["faults"]
    assert [f["kind"] for f in faults] == ["loss"], faults

    def lost_to_chaos() -> int:
        return sum(n.get("chaos_lost", 0) for n in _hub(stack)["nodes"].values())

    wait_for("frames lost to the injected loss", lost_to_chaos, 15)
    stack.petswarm("chaos", "clear")
    assert _hub(stack)["chaos"] == []


def test_docker_process_faults_pause_and_crash_one_replica(stack: Stack):
    rid = max(set(range(2, ROBOTS + 1)) - set(SWARM["members"]))  # a robot outside the swarm
    container = _container_of(stack, rid)
    docker("pause", container)
    try:
        with pytest.raises(HubUnavailable):
            _robot(stack, rid, timeout=1.5)  # a frozen process answers nothing
    finally:
        docker("unpause", container)
    wait_for(f"robot {rid} answering after unpause", lambda: _robot(stack, rid)["robot_id"] == rid, 10)
    # a crash: everything in the container but its init killed, as the README's recipe does; the restart policy
    # (on-failure) brings the robot back, and it claims its id again (the lowest free one)
    assert stack.restart_count(container) == 0
    index = docker("inspect", "--format", '{{index .Config.Labels "com.docker.compose.container-number"}}', container)
    stack.compose("exec", "-T", "--index", index.stdout.strip(), "robot", "sh", "-c", "kill -KILL -1", check=False)
    wait_for("the crashed robot's container restarted", lambda: stack.restart_count(container) == 1, 20)
    wait_for(f"robot {rid} attached again", lambda: rid in _attached(stack) and _robot(stack, rid), 30)
    assert stack.robot_of(container) == rid
    wait_for("the restarted container healthy", lambda: _health(container) == "healthy", 30)


def test_the_hub_restarts_every_robot_reattaches_and_a_swarm_forms_again(stack: Stack):
    hub = stack.containers("hub")[0]
    stack.compose("restart", "hub", timeout=60)
    wait_for("the hub healthy again", lambda: _health(hub) == "healthy", 60)
    wait_for("every robot attached to the new hub", lambda: _attached(stack) == set(range(1, ROBOTS + 1)), 30)
    settled = ("master-driving", "following", "waiting")  # the swarm went on, or it is over for robot 1
    master = wait_for("robot 1 settled after the outage", lambda: (m := _robot(stack, 1))["state"] in settled and m, 20)
    if master["state"] == "master-driving":  # the swarm outlived the outage: end it, as the user would
        ended = stack.petswarm("swarm", "disperse", "--master", "1", check=False)
        # unless it ended on its own in between: members lost in the outage make the master give it up
        assert ended.returncode == 0 or "not the master of a swarm" in ended.stdout + ended.stderr, ended
    user = ["--user", "1"] if _robot(stack, 1)["state"] == "waiting" else []  # robot 1 still follows user 1
    again = json.loads(stack.petswarm("swarm", "organize", "--master", "1", "--count", "3", *user, "--json").stdout)
    assert len(again["members"]) == 3 and 1 not in again["members"], again
    SWARM["members"] = sorted(again["members"])


def test_a_member_whose_container_stops_is_dropped_by_the_master(stack: Stack):
    gone = SWARM["members"][-1]
    container = _container_of(stack, gone)
    restarts = stack.restart_count(container)  # 1 if it is the replica the crash test restarted
    docker("stop", "--time", "10", container, timeout=60)
    rest = [m for m in SWARM["members"] if m != gone]

    def members() -> bool:
        return (_robot(stack, 1).get("swarm") or {}).get("members") == rest

    wait_for(f"the master dropping robot {gone}", members, 20)
    assert gone not in _attached(stack)
    state = stack.state(container)
    assert state["Status"] == "exited" and state["ExitCode"] == 0  # a clean exit: on-failure leaves it down
    assert stack.restart_count(container) == restarts


def test_down_leaves_no_container_network_or_volume(stack: Stack, capsys: pytest.CaptureFixture[str]):
    stack.compose("down", "--volumes", "--remove-orphans", "--timeout", "10")
    assert stack.leftovers() == {"containers": [], "networks": [], "volumes": []}
    base, base_s = FIGURES["base_image"]
    low, mean, high = FIGURES["robot_mib"]
    with capsys.disabled():
        print(
            f"\ncompose figures: base image {base} ({base_s:.0f} s); image build {FIGURES['build_first_s']:.1f} s "
            f"first, {FIGURES['build_warm_s']:.1f} s after a source change; up --wait to {ROBOTS} healthy robots "
            f"{FIGURES['up_healthy_s']:.1f} s; memory per robot container {mean:.1f} MiB ({low:.1f}-{high:.1f}), "
            f"hub {FIGURES['hub_mib']:.1f} MiB; swarm of 3 organized in {FIGURES['organize_ms']:.0f} ms"
        )
