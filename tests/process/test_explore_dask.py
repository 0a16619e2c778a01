"""``petswarm explore --scheduler``: a real ``dask scheduler`` and two ``dask worker`` processes on loopback run a
campaign's cases, and every case's digest and verdicts equal those of ``--workers 2`` (local processes)."""

from __future__ import annotations

import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from petswarm.lab.processes import free_tcp_port

pytest.importorskip("distributed")
pytestmark = pytest.mark.long

CASES = range(6)
SEED = 3


@pytest.fixture
def dask_cluster(tmp_path: Path) -> Iterator[str]:
    dask = Path(sys.executable).with_name("dask")
    if not dask.exists():
        dask = Path(shutil.which("dask") or "dask")
    port = free_tcp_port()
    address = f"tcp://127.0.0.1:{port}"
    log = (tmp_path / "dask.log").open("w")
    procs = [
        subprocess.Popen(
            [str(dask), "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
            stdout=log,
            stderr=log,
        )
    ]
    try:
        for _ in range(2):
            procs.append(
                subprocess.Popen(
                    [str(dask), "worker", address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard"],
                    stdout=log,
                    stderr=log,
                    cwd=tmp_path,
                )
            )
        from distributed import Client

        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
        yield address
    finally:
        for proc in reversed(procs):
            proc.terminate()
        for proc in procs:
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        log.close()


@pytest.mark.timeout(300)
def test_a_campaign_on_a_dask_cluster_gives_the_digests_of_two_local_workers(dask_cluster: str) -> None:
    from petswarm.explore.campaign import run_dask, run_local

    started = time.monotonic()
    on_dask = {r["index"]: r for r in run_dask(SEED, CASES, dask_cluster)}
    local = {r["index"]: r for r in run_local(SEED, CASES, 2)}
    assert set(on_dask) == set(local) == set(CASES), time.monotonic() - started
    for i in CASES:
        assert on_dask[i]["digest"] == local[i]["digest"], i
        assert on_dask[i]["failures"] == local[i]["failures"], i
        assert len(on_dask[i]["digest"]) >= 16
