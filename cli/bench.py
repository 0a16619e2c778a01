"""``petswarm bench ...``: the benchmarks' command line. Each bench is a plain function of typed options
(``petswarm.bench.<name>``: ``IrOptions`` and ``bench_ir``, ...); this module parses, then calls."""

from __future__ import annotations

import argparse
from typing import Any

from cli.common import add_link_security, add_profile
from cli.options import options_of
from petswarm.lab.arguments import bounded, seed


def add_bench(sub: Any) -> None:
    """The ``bench`` command and its benches."""
    bench = sub.add_parser("bench", help="benchmarks: figures on stdout, JSON and plots to --out")
    bench_sub = bench.add_subparsers(dest="bench", required=True, metavar="BENCH")
    bhub = bench_sub.add_parser("hub", help="hub round trip vs plain zenoh, frames/s with 50 nodes, delivery lag")
    bhub.add_argument("--rounds", type=bounded(int, 10, 100000), default=500, help="round trips per path (default 500)")
    bhub.add_argument(
        "--nodes", type=bounded(int, 2, 200), default=50, help="attached nodes in the load test (default 50)"
    )
    bhub.add_argument(
        "--load-seconds", type=bounded(float, 1, 600), default=5.0, help="length of the load test (default 5)"
    )
    bhub.add_argument("--seed", type=seed, default=1, help="seed of the hubs and the load (default %(default)s)")
    bhub.add_argument("--out", default="bench-results", help="directory for JSON and plots (default %(default)s)")
    bhub.add_argument("--json", action="store_true", help="print the results as JSON on stdout")
    bhub.add_argument(
        "--floor",
        action="store_true",
        help="also run both phases on a hub that carries frames without modelling the air (petswarm hub "
        "--floor): the floor under any hub's figures on this machine, printed beside the real hub's",
    )
    bhub.add_argument(
        "--check",
        action="store_true",
        help="exit 1 (naming each on stderr) when a target is missed: round trip ratio p50 <= 1.5, "
        "throughput >= min(10000, the air's capacity) frames/s, hub lag p99 <= 2 ms",
    )
    borg = bench_sub.add_parser("organize", help="swarm organizing time vs number of slaves, per protocol")
    borg.add_argument(
        "--slaves", type=_slave_counts, default=[1, 2, 3, 4, 5], help="slave counts: N, A-B or N,M,... (default 1-5)"
    )
    borg.add_argument(
        "--runs", type=bounded(int, 1, 10000), default=50, help="organizations per count and protocol (default 50)"
    )
    borg.add_argument(
        "--protocol", choices=("paper", "slotted", "both"), default="both", help="protocols to measure (default both)"
    )
    borg.add_argument("--mac-ack", choices=("on", "off"), default="on", help="MAC acknowledgements (default on)")
    borg.add_argument(
        "--clock",
        choices=("model", "wall"),
        default="model",
        help="model (default): every slave count in this one process on model time, the same figures for the "
        "same seed on any machine; wall: a hub process and robot processes over zenoh, in real time",
    )
    borg.add_argument(
        "--step-deadline",
        type=bounded(float, 0.005, 10),
        help="seconds each organizing step waits before retrying (default: the robot's, 0.1)",
    )
    borg.add_argument(
        "--step-retries",
        type=bounded(int, 0, 50),
        help="retries of an organizing step (default: the robot's, 5)",
    )
    add_profile(borg, "hub and robots; the paper's figure printed beside the bench's, with the ratio")
    borg.add_argument("--seed", type=seed, default=1, help="seed of the hub and the robots (default %(default)s)")
    add_link_security(borg)
    borg.add_argument("--out", default="bench-results", help="directory for JSON and plots (default %(default)s)")
    borg.add_argument("--json", action="store_true", help="print the results as JSON on stdout")
    _add_ir(bench_sub.add_parser("ir", help="IR relative-location accuracy per estimator"))
    _add_reaction(
        bench_sub.add_parser("reaction", help="reaction time of master and slaves to the user's rotation (CDFs)")
    )
    _add_surround(
        bench_sub.add_parser(
            "surround", help="surround scenarios in model time through each robot's own pipeline (seeds, plot)"
        )
    )
    _add_scale(
        bench_sub.add_parser("scale", help="wall time per model second, memory and digests vs robots, per clock")
    )
    _add_start(bench_sub.add_parser("start", help="CPU, time and memory of starting robot processes, forked vs exec'd"))
    from cli.bench_all import add_arguments as add_bench_all_arguments

    add_bench_all_arguments(
        bench_sub.add_parser("all", help="rerun every bench the docs quote: one header with command, date, machine")
    )


def bench(args: argparse.Namespace) -> int:
    """Run the bench ``args`` names, with its options typed."""
    if args.bench == "all":
        from cli.bench_all import run

        return run(args)
    from petswarm.bench import hub, ir, organize, reaction, run_bench, scale, start, surround

    typed = {
        "hub": hub.HubBenchOptions,
        "organize": organize.OrganizeOptions,
        "ir": ir.IrOptions,
        "reaction": reaction.ReactionOptions,
        "scale": scale.ScaleOptions,
        "start": start.StartOptions,
        "surround": surround.SurroundOptions,
    }
    return run_bench(options_of(typed[args.bench], args))


def _add_ir(parser: argparse.ArgumentParser) -> None:
    from petswarm.bench.ir import heading_arg, members_range

    parser.add_argument("--runs", type=bounded(int, 1, 100000), default=300, help="sweeps per point (default 300)")
    parser.add_argument("--seed", type=seed, default=1, help="seed of the light model's noise (default %(default)s)")
    parser.add_argument(
        "--heading",
        type=heading_arg,
        default=0.0,
        help="receiver heading in degrees, or 'random' per sweep (default 0, as in the paper)",
    )
    parser.add_argument("--out", default="bench-results", help="directory for JSON and plots (default %(default)s)")
    parser.add_argument("--json", action="store_true", help="print the results as JSON on stdout")
    add_profile(parser, "the IR module's noise; the paper's Table 4 printed beside the bench's, with the ratio")
    parser.add_argument(
        "--no-wire",
        dest="wire",
        action="store_false",
        help="skip the runs through real hub and robot processes (over the wire, token cycle)",
    )
    parser.add_argument(
        "--wire-seconds",
        type=bounded(float, 1, 600),
        default=6.0,
        help="seconds each over-the-wire swarm runs (default 6)",
    )
    parser.add_argument(
        "--members",
        type=members_range,
        default=(2, 10),
        help="swarm sizes of the token-cycle run, LOW-HIGH (default 2-10)",
    )


def _add_reaction(parser: argparse.ArgumentParser) -> None:
    from petswarm.bench.reaction import SCENARIO

    parser.add_argument(
        "--runs", type=bounded(int, 1, 10000), default=50, help="trials (user rotations) to measure (default 50)"
    )
    parser.add_argument("--scenario", default=str(SCENARIO), help="scenario with a leading swarm and user rotations")
    parser.add_argument("--seed", type=seed, default=1, help="seed of the first scenario run (default %(default)s)")
    parser.add_argument("--out", default="bench-results", help="directory for JSON and plots (default %(default)s)")
    parser.add_argument("--json", action="store_true", help="print the results as JSON on stdout")
    add_profile(parser, "hub, robots and user; the paper's figures printed beside the bench's, with the ratio")
    parser.add_argument(
        "--clock",
        choices=("wall", "model"),
        default="model",
        help="model (default, as bench organize): each run in model time (petswarm run --clock model), "
        "deterministic per seed and much faster; wall: each run as processes over zenoh",
    )


def _add_surround(parser: argparse.ArgumentParser) -> None:
    from petswarm.bench.surround import DEFAULT_SCENARIOS
    from petswarm.bench.surround_runs import CLOCKS

    parser.add_argument(
        "scenarios", nargs="*", default=DEFAULT_SCENARIOS, help="surround scenario files (default: cylinder, corridor)"
    )
    parser.add_argument("--seeds", type=bounded(int, 1, 1000), default=3, help="runs per scenario (default 3)")
    parser.add_argument("--seed", type=seed, default=1, help="seed of the first run (default %(default)s)")
    parser.add_argument("--out", default="bench-results", help="directory for JSON and plots (default %(default)s)")
    parser.add_argument(
        "--paper",
        action="store_true",
        help="also the pure simulation of the paper's setups (exact sensing, no hub): r* from both lattices, "
        "thin- and solid-walled corridor and cylinder, each also with noisy sensing",
    )
    parser.add_argument(
        "--law",
        choices=("paper", "improved", "safe", "both", "all"),
        default="paper",
        help="the law the robots run, whatever the scenario file says: the paper's, the improved one, the safe one "
        "(docs/SURROUND.md), paper and improved in turn (both), or all three in turn (default %(default)s)",
    )
    parser.add_argument(
        "--train",
        type=bounded(int, 0, 10000),
        default=0,
        help="run this many generated training courses instead of scenario files (model time; default 0)",
    )
    parser.add_argument(
        "--test",
        type=bounded(int, 0, 10000),
        default=0,
        help="run this many generated test courses instead of scenario files (model time; default 0)",
    )
    parser.add_argument(
        "--first-course",
        type=bounded(int, 0, 1000000),
        default=0,
        help="index of the first course of each set (default 0)",
    )
    parser.add_argument(
        "--clock",
        choices=CLOCKS,
        default="model",
        help="model: every robot in this process on a virtual clock (fast); lockstep: each robot and the user as "
        "its own process on the hub's model time, same figures and digest per seed (default %(default)s)",
    )
    parser.add_argument(
        "--jobs",
        type=bounded(int, 1, 64),
        default=1,
        help="model-time runs at once, each in its own worker process (default %(default)s; the machine's cores "
        "is the most that helps). Every run is a function of its seed: the same figures and digests whatever this is",
    )
    parser.add_argument(
        "--snapshots",
        action="store_true",
        help="also the safe law's snapshot plot of the first scenario's first seed, each robot's active safety "
        "constraints drawn (bench_surround_safe_snapshots.png)",
    )
    parser.add_argument("--json", action="store_true", help="print the results as JSON on stdout")


def _add_scale(parser: argparse.ArgumentParser) -> None:
    from petswarm.bench.scale import robot_counts

    parser.add_argument(
        "--robots", type=robot_counts, default=[10, 20, 50, 100], help="robot counts (default 10,20,50,100)"
    )
    parser.add_argument(
        "--model-robots",
        type=robot_counts,
        default=[1000],
        help="more counts run in model time only (default 1000; none: no more)",
    )
    parser.add_argument(
        "--lockstep-max", type=bounded(int, 0, 5000), default=100, help="largest lockstep run (default %(default)s)"
    )
    parser.add_argument(
        "--duration", type=bounded(float, 0.5, 3600), default=5.0, help="model seconds a run (default %(default)s)"
    )
    parser.add_argument("--seed", type=seed, default=3, help="seed of every run (default %(default)s)")
    parser.add_argument("--out", default="bench-results", help="directory for JSON and plots (default %(default)s)")
    parser.add_argument("--json", action="store_true", help="print the results as JSON on stdout")


def _add_start(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--robots", type=bounded(int, 1, 200), default=20, help="robots per start (default 20)")
    parser.add_argument("--rounds", type=bounded(int, 1, 50), default=3, help="rounds of both ways (default 3)")
    parser.add_argument("--out", default="bench-results", help="directory for JSON and plots (default %(default)s)")
    parser.add_argument("--json", action="store_true", help="print the results as JSON on stdout")


def _slave_counts(text: str) -> list[int]:
    from petswarm.bench.organize import slave_counts  # imported here: it brings zenoh, which --help does not need

    return slave_counts(text)
