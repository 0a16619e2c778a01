"""The command line is parsing only: each bench and explore is a plain function of typed options, whose
defaults are the command line's, so a notebook runs them without argv."""

from __future__ import annotations

import json
from dataclasses import fields
from pathlib import Path
from typing import Any

import pytest

from cli.main import build_parser
from cli.options import options_of


def _options() -> dict[tuple[str, ...], Any]:
    from petswarm.bench.hub import HubBenchOptions
    from petswarm.bench.ir import IrOptions
    from petswarm.bench.organize import OrganizeOptions
    from petswarm.bench.reaction import ReactionOptions
    from petswarm.bench.scale import ScaleOptions
    from petswarm.bench.start import StartOptions
    from petswarm.bench.surround import SurroundOptions
    from petswarm.explore.main import ExploreOptions
    from petswarm.lab.certs import CertsOptions
    from petswarm.lab.experiment import ExperimentOptions
    from petswarm.lab.mcap_export import ExportOptions
    from petswarm.lab.report import ReportOptions
    from petswarm.lab.swarm import SwarmOptions
    from petswarm.lab.watch import WatchOptions

    return {
        ("bench", "hub"): HubBenchOptions,
        ("bench", "organize"): OrganizeOptions,
        ("bench", "ir"): IrOptions,
        ("bench", "reaction"): ReactionOptions,
        ("bench", "scale"): ScaleOptions,
        ("bench", "start"): StartOptions,
        ("bench", "surround"): SurroundOptions,
        ("explore",): ExploreOptions,
        ("experiment", "x.toml"): ExperimentOptions,
        ("report", "runs/x"): ReportOptions,
        ("watch",): WatchOptions,
        ("export", "runs/x", "--mcap", "x.mcap"): ExportOptions,
        ("certs", "--out", "d", "--hub-host", "h"): CertsOptions,
        ("swarm", "status", "--robot", "2"): SwarmOptions,
        ("swarm", "organize", "--master", "1", "--count", "3"): SwarmOptions,
        ("swarm", "disperse", "--master", "1"): SwarmOptions,
    }


REQUIRED = {
    "experiment": {"file": "x.toml"},
    "report": {"run": "runs/x"},
    "export": {"run": "runs/x", "mcap": "x.mcap"},
    "certs": {"out": "d", "hub_host": "h"},
}
"""What each command's argv above gives that has no default."""
TRANSPORT = {"tls_ca", "tls_cert", "tls_key", "zenoh_config"}
"""A client's transport security: the process's zenoh session's (set up before the command runs), not an option
of the command's own."""


@pytest.mark.parametrize("argv", list(_options()), ids=" ".join)
def test_typed_options_default_to_what_the_command_line_does(argv: tuple[str, ...]) -> None:
    cls = _options()[argv]
    args = build_parser().parse_args(list(argv))
    given = REQUIRED.get(argv[0], {})
    if argv[0] == "swarm":  # each action has its own required options
        given = {"action": argv[1], **{argv[i][2:]: int(argv[i + 1]) for i in range(2, len(argv), 2)}}
    assert options_of(cls, args) == cls(**given)
    # every option of the command is a field: nothing the command line takes is lost on the way
    taken = set(vars(args)) - {"command", "bench"} - TRANSPORT
    names = {f.name for f in fields(cls)}
    assert taken <= names and (argv[0] == "swarm" or taken == names), taken ^ names


def test_a_bench_runs_from_its_options_without_argv(tmp_path: Path, capsys: Any) -> None:
    from petswarm.bench.ir import IrOptions, bench_ir

    assert bench_ir(IrOptions(runs=2, wire=False, out=str(tmp_path), json=True)) == 0
    printed = json.loads(capsys.readouterr().out)
    assert json.loads((tmp_path / "bench_ir.json").read_text())["settings"] == printed["settings"]


def test_hub_tables_merge_config_scenario_and_profile_in_one_place(tmp_path: Path) -> None:
    """--config gives the radio and the light, the scenario the world, the profile its values over both."""
    from petswarm.lab.hub_tables import hub_environment
    from petswarm.scenario import load
    from radio_hub.hosting import EnvironmentConfig

    config = tmp_path / "hub.json"
    config.write_text(json.dumps({"mac": {"min_be": 5}, "ir": {"emitter_noise": 0.05}}))
    scenario = load(Path(__file__).resolve().parents[2] / "scenarios" / "surround-cylinder.toml")
    merged = hub_environment(str(config), scenario, "ideal")
    assert merged.medium.mac.min_be == 5 and merged.ir.emitter_noise == 0.05
    assert merged.obstacles == hub_environment(None, scenario, "ideal").obstacles != EnvironmentConfig().obstacles
    assert hub_environment(None, None, "kim2017") != EnvironmentConfig()
    missing = tmp_path / "missing.json"
    with pytest.raises(ValueError) as refused:
        hub_environment(str(missing), None, "ideal")
    assert str(refused.value) == f"bad --config: {missing}: no such file or directory"


def test_a_notebook_runs_a_swarm_from_the_package_alone(tmp_path: Path) -> None:
    """``import petswarm`` and a RunOptions with the command line's defaults: the run's digest is the seed's, as
    the command line gives it (``petswarm run --seed 7 --clock model``)."""
    import subprocess
    import sys

    import petswarm
    from petswarm.lab.run import RunOptions

    code = petswarm.run(RunOptions(seed=7, clock="model", record_dir=str(tmp_path / "nb"), as_json=True))
    assert code == 0
    argv = ["run", "--seed", "7", "--clock", "model", "--json", "--record", str(tmp_path / "cli")]
    done = subprocess.run([sys.executable, "-m", "cli", *argv], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    digest = json.loads((tmp_path / "nb" / "summary.json").read_text())["digest"]
    assert digest == json.loads(done.stdout)["digest"]


def test_run_bench_dispatches_on_the_options_it_is_given(tmp_path: Path, capsys: Any) -> None:
    import petswarm
    from petswarm.bench.ir import IrOptions

    assert petswarm.run_bench(IrOptions(runs=2, wire=False, out=str(tmp_path), json=True)) == 0
    assert (tmp_path / "bench_ir.json").exists()
    with pytest.raises(TypeError, match="no bench takes"):
        petswarm.run_bench(object())
