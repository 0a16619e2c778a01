"""The robot and wearable side of petswarm: swarm middleware managers, controllers, the robot process, and the
lab around a swarm.

From a notebook, without a command line (each takes the dataclass its command parses into, with the same
defaults, and returns the command's exit status; ``petswarm.explore`` and ``petswarm.bench`` are the
subpackages, so their functions are ``run_explore`` and ``run_bench``)::

    import petswarm
    from petswarm.lab.run import RunOptions
    petswarm.run(RunOptions(robots=5, organize=3, seed=7, clock="model"))

    from petswarm.explore.main import ExploreOptions
    petswarm.run_explore(ExploreOptions(seed=1, cases=20))

    from petswarm.bench.ir import IrOptions
    petswarm.run_bench(IrOptions(runs=50, wire=False))
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import radio_hub.determinism  # noqa: F401  (numpy's float paths pinned before numpy loads)

if TYPE_CHECKING:
    from petswarm.explore.main import ExploreOptions
    from petswarm.lab.run import RunOptions


def run(options: RunOptions) -> int:
    """``petswarm run``: a hub and robots (and a scenario's user) on the options' clock; the exit status."""
    from petswarm.lab.launch import run as launch  # here: a robot process imports this package, not the lab

    return launch(options)


def run_explore(options: ExploreOptions) -> int:
    """``petswarm explore``: a seed's cases in model time, checked and shrunk; the exit status."""
    from petswarm.explore.main import explore as campaign

    return campaign(options)


def run_bench(options: Any) -> int:
    """``petswarm bench``: the bench whose options these are (``petswarm.bench.ir.IrOptions``...); its exit status."""
    from petswarm.bench import run_bench as bench

    return bench(options)
