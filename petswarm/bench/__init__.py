"""The benchmarks behind ``petswarm bench``: the hub's throughput and latency (``hub``, ``nodes``),
network formation (``organize``), IR relative location (``ir``, ``ir_token``), reaction to the user
(``reaction``), scale (``scale``) and the surround formation (``surround``, ``surround_sim``); ``all`` reruns
every bench the docs quote. Each writes its figures and results the same way (``petswarm.lab.output``), and
each is a plain function of typed options: ``run_bench(IrOptions(...))`` runs one without a command line.
"""

from __future__ import annotations

from typing import Any


def run_bench(options: Any) -> int:
    """Run the bench whose typed options ``options`` are (``hub.HubBenchOptions``, ``organize.OrganizeOptions``,
    ``ir.IrOptions``, ``reaction.ReactionOptions``, ``scale.ScaleOptions``, ``start.StartOptions``,
    ``surround.SurroundOptions``, ``all.AllOptions``); its exit
    status. Each bench is imported when run: they bring zenoh, numpy and matplotlib, which parsing does not need."""
    name = type(options).__name__
    if name == "IrOptions":
        from petswarm.bench.ir import bench_ir

        return bench_ir(options)
    if name == "ReactionOptions":
        from petswarm.bench.reaction import bench_reaction

        return bench_reaction(options)
    if name == "ScaleOptions":
        from petswarm.bench.scale import bench_scale

        return bench_scale(options)
    if name == "StartOptions":
        from petswarm.bench.start import bench_start

        return bench_start(options)
    if name == "OrganizeOptions" and options.clock == "model":
        from petswarm.bench.organize_model import bench_organize as bench_organize_model

        return bench_organize_model(options)
    if name == "OrganizeOptions":
        from petswarm.bench.organize import bench_organize

        return bench_organize(options)
    if name == "AllOptions":
        from petswarm.bench.all import bench_all

        return bench_all(options)
    if name == "SurroundOptions":
        from petswarm.bench.surround import bench_surround

        return bench_surround(options)
    if name == "HubBenchOptions":
        from petswarm.bench.hub import bench_hub

        return bench_hub(options)
    raise TypeError(f"no bench takes {name}")
