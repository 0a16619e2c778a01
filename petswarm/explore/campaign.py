"""A campaign: cases ``0..N-1`` of a seed, each run in model time, mapped over local worker processes or a Dask
distributed cluster and gathered as they finish. Cases are independent and pure, so a case's result and digest do
not depend on where, or beside what, it ran."""

from __future__ import annotations

import multiprocessing
import os
import shutil
import signal
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Any

from petswarm.explore.generate import DEFAULT_WEIGHTS, case, pick_family
from petswarm.lab.processes import arm_parent_death


def explore_case(seed: int, i: int, weights: dict[str, float] | None = None) -> dict[str, Any]:
    """Case ``i`` of ``seed``, generated and run: its result with ``seed``, ``index`` and wall time."""
    from petswarm.explore.runner import run_case

    started = time.perf_counter()
    family = pick_family(seed, i, weights or DEFAULT_WEIGHTS)
    data = case(seed, i, family)
    result = run_case(data, seed=run_seed(seed, i), family=family)
    return {"seed": seed, "index": i, **result, "wall_s": round(time.perf_counter() - started, 3)}


def run_seed(seed: int, i: int) -> int:
    """The run's own seed (the medium's and the robots' draws) for case ``i``: from ``(seed, i)`` alone."""
    return (int(seed) * 1_000_003 + int(i)) % (2**31 - 1)


STOP_GRACE_S = 5.0
"""Wall seconds a worker told to stop (SIGTERM: its case unwinds and removes its scratch directory) has before
SIGKILL."""


def run_local(
    seed: int, indices: Iterable[int], workers: int, weights: dict[str, float] | None = None
) -> Iterator[dict[str, Any]]:
    """Results as cases finish, over ``workers`` local processes (1: in this process). Closed before the end (the
    campaign interrupted), it cancels the cases not begun and stops the workers, whatever case they are in."""
    indices = list(indices)
    if workers <= 1:
        for i in indices:
            yield explore_case(seed, i, weights)
        return
    ours_before = set(multiprocessing.active_children())
    # the workers' cases keep their records here meanwhile: a worker stopped in a case leaves its own behind
    scratch = tempfile.mkdtemp(prefix="petswarm-explore-")
    # spawn, not fork: a worker starts clean of this process's loop and threads; cases are seconds each
    pool = ProcessPoolExecutor(
        workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_worker_start,
        initargs=(os.getpid(), scratch),
    )
    finished = False
    try:
        yield from _as_they_finish([pool.submit(explore_case, seed, i, weights) for i in indices])
        finished = True
    finally:
        if finished:
            pool.shutdown()
        else:
            _stop_workers(pool, [p for p in multiprocessing.active_children() if p not in ours_before])
        shutil.rmtree(scratch, ignore_errors=True)


def _worker_start(parent: int, scratch: str) -> None:
    """A local worker's first act: Ctrl-C at a terminal reaches the whole process group, and the campaign stops
    its workers itself (so SIGINT is ignored here); the worker dies with the campaign even when that is killed
    outright (SIGKILL, the kernel's parent-death signal); its cases' records go under the campaign's ``scratch``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    arm_parent_death(signal.SIGKILL, parent)
    tempfile.tempdir = scratch


def _stop_workers(pool: ProcessPoolExecutor, workers: list[multiprocessing.process.BaseProcess]) -> None:
    """Cancel the cases not begun, SIGTERM the workers (a case in progress unwinds as an interrupted run does),
    SIGKILL any still alive after ``STOP_GRACE_S``, and wait for every one."""
    pool.shutdown(wait=False, cancel_futures=True)
    for worker in workers:
        worker.terminate()
    deadline = time.monotonic() + STOP_GRACE_S
    for worker in workers:
        worker.join(max(0.0, deadline - time.monotonic()))
        if worker.is_alive():
            worker.kill()
            worker.join()
    pool.shutdown(wait=True)


def run_dask(
    seed: int, indices: Iterable[int], address: str, weights: dict[str, float] | None = None
) -> Iterator[dict[str, Any]]:
    """Results as cases finish, on the Dask distributed cluster whose scheduler is at ``address``. Closed before
    the end (the campaign interrupted), it cancels its futures: the cluster drops the cases not yet run."""
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise SystemExit("petswarm explore --scheduler needs Dask: pip install 'petswarm[explore]'") from None
    with Client(address, timeout="20s") as client:
        indices = list(indices)
        futures = client.map(explore_case, [seed] * len(indices), indices, [weights] * len(indices), pure=False)
        finished = False
        try:
            for future in as_completed(futures):
                yield future.result()
            finished = True
        finally:
            if not finished:
                client.cancel(futures)


def _as_they_finish(futures: list[Future[dict[str, Any]]]) -> Iterator[dict[str, Any]]:
    pending = set(futures)
    while pending:
        done, pending = wait(pending, return_when=FIRST_COMPLETED)
        for future in done:
            yield future.result()


class Progress:
    """A one-line progress bar with the rate and an ETA, on stderr (a terminal's line rewritten in place)."""

    def __init__(self, total: int, out: Any = None, clock: Callable[[], float] = time.perf_counter) -> None:
        self.total, self.done, self.failed = total, 0, 0
        self.out = out or sys.stderr
        self.clock = clock
        self.started = clock()

    def line(self) -> str:
        """The bar as it stands."""
        elapsed = self.clock() - self.started
        rate = self.done / elapsed if elapsed > 0 else 0.0
        eta = (self.total - self.done) / rate if rate > 0 else float("nan")
        width = 30
        filled = int(width * self.done / max(self.total, 1))
        eta_text = "--" if eta != eta else _duration(eta)
        return (
            f"[{'#' * filled}{'.' * (width - filled)}] {self.done}/{self.total} cases, {self.failed} failed, "
            f"{rate * 3600:.0f}/h, elapsed {_duration(elapsed)}, ETA {eta_text}"
        )

    def step(self, ok: bool) -> None:
        """One case finished."""
        self.done += 1
        self.failed += 0 if ok else 1
        end = "\n" if self.done == self.total else ""
        if self.out.isatty():
            print(f"\r{self.line()}", end=end, file=self.out, flush=True)
        elif self.done == self.total or self.done % max(1, self.total // 20) == 0:
            print(self.line(), file=self.out, flush=True)


def _duration(seconds: float) -> str:
    seconds = int(seconds)
    return f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}"
