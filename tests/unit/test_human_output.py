"""What people read is in words and tables, not raw JSON or Python reprs; ``--json`` gives machines the JSON."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import pytest

from cli.main import build_parser

STATUS: dict[str, Any] = {
    "robot_id": 2,
    "pid": 5037,
    "radio": {
        "node_id": "robot-2",
        "ext_addr": 5149012952875010,
        "short_addr": 2,
        "pan_id": 59211,
        "channel": 11,
        "position": [1.5, 0.0],
        "heading_deg": 0.0,
        "kind": "robot",
    },
    "uptime_s": 4.882,
    "pings_sent": 0,
    "pings_answered": 0,
    "heard_from": {},
    "messages_received": 94,
    "malformed_payloads": 0,
    "tx_results": {"success": 62},
    "radio_malformed": 0,
    "transport_gaps": 0,
    "state": "slave-driving",
    "user": 0,
    "swarm": {"session": 34220, "pan_id": 59211, "master": 1, "number": 1, "members": [2, 3], "neighbours": [1, 3]},
    "organizations": [],
    "retries": 0,
    "duplicates": 2,
    "late_responses": 0,
    "ir": {"round": 20, "rounds_held": 6, "fixes": 13, "regenerations": 0, "ir_mode": "receive", "chain": [1, 2, 3]},
    "driving": {"owner": None, "mode": "following", "command": [0.0, 0.0, 0.0], "wake_bursts": 1},
    "relative_location": {
        "1": {"bearing_deg": 179.2884, "distance_m": 1.49448, "heading_deg": 359.8, "age_s": 0.033, "fixes": 7},
        "3": {"bearing_deg": 359.7307, "distance_m": 1.50944, "heading_deg": 359.29, "age_s": 0.196, "fixes": 6},
    },
    "surround": None,
}


@pytest.mark.parametrize(
    "argv",
    [
        ["swarm", "status", "--robot", "2", "--json"],
        ["chaos", "list", "--json"],
        ["chaos", "loss", "--p", "0.3", "--json"],
        ["chaos", "kill", "--robot", "2", "--json"],
        ["experiment", "x.toml", "--json"],
        ["report", "runs/x", "--json"],
        ["stats", "--json"],
    ],
)
def test_every_command_that_prints_figures_has_json(argv: list[str]) -> None:
    assert build_parser().parse_args(argv).json is True


def test_swarm_status_prints_in_words() -> None:
    from petswarm.lab.swarm import describe

    text = describe("status", STATUS)
    assert "{" not in text and "[" not in text and len(text.splitlines()) <= 12, text
    assert text.splitlines()[0] == "robot 2 (pid 5037, up 4.9 s): slave-driving"
    assert "swarm: PAN 0xe74b, master 1, members 2, 3; this robot is member 1, neighbours 1, 3" in text
    assert any(line.split()[:4] == ["robot", "1", "179.3°", "1.49"] for line in text.splitlines()), text


def test_a_fault_holds_only_its_own_fields_and_reads_in_words() -> None:
    from radio_hub.air.chaos import describe_change, describe_fault, parse_fault

    partition = parse_fault(1, {"kind": "partition", "group": ["robot-3"]}).to_dict()
    assert partition == {"fault_id": 1, "kind": "partition", "group": ("robot-3",)}  # no p = 1.0, no sigma = 0.0
    loss = parse_fault(2, {"kind": "loss", "p": 0.3, "node": "robot-2"}).to_dict()
    assert loss == {"fault_id": 2, "kind": "loss", "p": 0.3, "node": "robot-2"}
    assert describe_fault(partition) == "fault 1: partition robot-3 | everyone else"
    assert describe_fault(loss) == "fault 2: loss p=0.3 on frames to or from robot-2"
    assert describe_fault({"kind": "delay", "ms": 20.0, "jitter_ms": 5.0, "jitter": "uniform", "pan": 0x1000}) == (
        "delay 20 ms +- 5 ms (uniform) on receivers on PAN 0x1000"
    )
    assert describe_fault({"kind": "ir_noise", "sigma": 40.0}) == "ir-noise sigma=40 counts on every IR receiver"
    assert describe_change({"op": "add", "model_us": 9_872_524, "wall": 1.0, **partition}) == (
        "at model 9.873 s: added fault 1: partition robot-3 | everyone else"
    )
    assert describe_change({"op": "clear", "model_us": 14_370_544, "wall": 2.0, "ended": [1, 2]}) == (
        "at model 14.371 s: cleared fault 1, 2"
    )


def test_the_hub_line_of_stats_rounds_the_lags() -> None:
    from cli.main import hub_line

    hub = {"malformed": 0, "transport_gaps": 0, "lag_p50_us": 219.0, "lag_p99_us": 4120.329999999974}
    assert hub_line(hub) == "hub: malformed 0, transport gaps 0, lag p50 219 us, lag p99 4120 us"


def test_the_user_is_not_named_twice() -> None:
    from petswarm.wearables.user import user_name

    assert user_name("user") == "user" and user_name("user-2") == "user-2" and user_name("7") == "user 7"


def _summary(**extra: Any) -> dict[str, Any]:
    node = {"sent": 5, "delivered": 7, "collided": 1, "lost": 0, "mac_retries": 2, "channel_access_failures": 0}
    nodes = {"robot-1": {**node, "heard_from": [2, 3]}, "robot-2": {**node, "heard_from": []}}
    hub = {"lag_p50_us": 94.2, "lag_p99_us": 508.7, "malformed": 0, "transport_gaps": 0}
    return {"seed": 1, "world": "w", "robots": 2, "duration_s": 5, "nodes": nodes, "hub": hub, "ok": True, **extra}


def test_a_scenario_summary_has_no_empty_heard_from_column(capsys: Any) -> None:
    from petswarm.lab.run import _print

    _print(_summary(scenario="reaction", problems=[]), as_json=False)
    out = capsys.readouterr().out
    assert "heard from" not in out and "[]" not in out, out
    _print(_summary(problems=[]), as_json=False)
    out = capsys.readouterr().out
    assert "heard from" in out and "  2, 3" in out and "  nobody" in out and "[" not in out, out


def test_a_surround_run_prints_the_swarm_not_a_table_of_silent_radios(capsys: Any) -> None:
    from petswarm.lab.run import _print

    silent = {"sent": 0, "delivered": 0, "collided": 0, "lost": 0, "mac_retries": 0, "channel_access_failures": 0}
    driving = {
        "collisions": 0,
        "connected_fraction": 0.994,
        "connected_at_end": True,
        "centre_to_user_m": {"median": 0.18, "p90": 0.29},
        "centre_to_user_end_m": 0.05,
        "extent_m": {"median": 0.69, "p90": 0.74},
        "extent_end_m": 0.7,
    }
    nodes = {f"robot-{i}": silent for i in range(1, 21)}
    _print(_summary(scenario="surround-cylinder", problems=[], nodes=nodes, driving=driving), as_json=False)
    out = capsys.readouterr().out
    assert "radio: silent (none of the 20 nodes sent or received a frame)" in out and "robot-7" not in out, out
    assert "swarm connected 0.994 of the time, and at the end" in out
    assert "swarm centre to user: median 0.18 m, p90 0.29 m, 0.05 m at the end" in out
    assert "swarm extent r: median 0.69 m, 0.70 m at the end" in out


def test_report_prints_its_plots_once_and_json_on_request(tmp_path: Path, capsys: Any) -> None:
    from petswarm.lab.report import report_command
    from tests.unit.test_report_world import _run_record

    run = tmp_path / "run"
    _run_record(run, with_world=True)
    assert report_command(argparse.Namespace(run=str(run), out=None, json=False)) == 0
    out = capsys.readouterr().out
    [plots] = [line for line in out.splitlines() if "plots" in line]
    assert plots.startswith("plots: ") and all(name in plots for name in ("report", "trajectories", "formation"))
    assert report_command(argparse.Namespace(run=str(run), out=None, json=True)) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["summary"]["ok"] and report["driving"]["reactions"] and len(report["plots"]) == 3


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["run", "--robtos", "5"], "petswarm run: error: unrecognized arguments: --robtos (did you mean --robots?)"),
        (["bench", "scale", "--robts", "5"], "petswarm bench scale: error: unrecognized arguments: --robts 5"),
        (["swarm", "status", "--robot", "2", "--jsn"], "petswarm swarm status: error: unrecognized arguments"),
    ],
)
def test_a_mistyped_option_is_refused_by_its_own_command_with_the_nearest_name(
    argv: list[str], says: str, capsys: Any
) -> None:
    with pytest.raises(SystemExit) as stop:
        build_parser().parse_args(argv)
    err = capsys.readouterr().err
    assert (
        stop.value.code == 2
        and says in err
        and f"usage: petswarm {' '.join(argv[: 2 if argv[0] != 'run' else 1])}" in err
    )


def test_version_names_the_installed_package(capsys: Any) -> None:
    from importlib.metadata import version

    with pytest.raises(SystemExit) as stop:
        build_parser().parse_args(["--version"])
    assert stop.value.code == 0 and capsys.readouterr().out == f"petswarm {version('petswarm')}\n"
