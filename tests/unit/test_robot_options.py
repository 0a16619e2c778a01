"""A robot is built from typed options (``RobotOptions``): a model-time run turns them into its config directly, a
process run starts ``petswarm robot`` with their ``argv()``, which the CLI parses back. Both must give the same
robot, so the options must survive the trip through the command line, every field of them."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from cli.main import build_parser, robot_options
from petswarm.controllers.surround import SurroundConfig
from petswarm.lab.robot_command import RobotOptions, robot_config

TRANSPORT = {"tls_ca", "tls_cert", "tls_key", "zenoh_config"}
"""The process's zenoh session's options: not the robot's."""


def parsed(argv: list[str]) -> RobotOptions:
    return robot_options(build_parser().parse_args(argv))


def test_robot_options_default_to_what_the_command_line_does() -> None:
    args = build_parser().parse_args(["robot", "--id", "3"])
    assert robot_options(args) == RobotOptions(id=3)
    taken = set(vars(args)) - {"command"} - TRANSPORT
    assert taken == {f.name for f in dataclasses.fields(RobotOptions)}, taken ^ {
        f.name for f in dataclasses.fields(RobotOptions)
    }


def _unusual(tmp_path: Path) -> RobotOptions:
    """Options with every field away from its default (negative x and heading, odd floats, a law's settings)."""
    key = tmp_path / "net.key"
    key.write_text("00112233445566778899aabbccddeeff\n")
    return RobotOptions(
        id=7,
        hub="tcp/127.0.0.1:9999",
        world="w41",
        clock="lockstep",
        pan=0x2A2A,
        channel=20,
        pos=(-1.25, 0.1 + 0.2),
        ping_interval=0.30000000000000004,
        seed=2**63 + 5,
        user=2,
        region_rssi=-80,
        step_deadline=0.3,
        step_retries=2,
        record=str(tmp_path / "robot-7.jsonl"),
        profile="kim2017",
        link_key=str(key),
        link_mic=8,
        heading=-123.456789,
        ir_estimator="paper",
        ir_slot=0.2,
        ir_deadline=0.07,
        ir_retries=4,
        protocol="slotted",
        formation="surround",
        surround_human="user-3",
        surround_config=SurroundConfig.from_dict({"stiffness": 9.5, "law": "improved"}),
    )


def test_the_sample_moves_every_field_from_its_default(tmp_path: Path) -> None:
    """Else the round trip below would not cover every option."""
    options, default = _unusual(tmp_path), RobotOptions(id=1)
    same = [f.name for f in dataclasses.fields(RobotOptions) if getattr(options, f.name) == getattr(default, f.name)]
    assert same == []


def test_options_come_back_from_their_command_line(tmp_path: Path) -> None:
    options = _unusual(tmp_path)
    assert parsed(options.argv()) == options
    assert robot_config(parsed(options.argv())) == robot_config(options)


@pytest.mark.parametrize(
    "changes",
    [{}, {"pos": (3, -2)}, {"heading": 90}, {"ping_interval": 1}, {"step_deadline": 1}, {"pos": (0.0, 0.0)}],
    ids=repr,
)
def test_plain_options_come_back_too(changes: dict[str, object]) -> None:
    """Integers given for floats become floats, as the command line makes them (a robot logs 1.0, not 1)."""
    options = RobotOptions(id=4, **changes)  # type: ignore[arg-type]
    again = parsed(options.argv())
    assert again == options
    assert {f.name: repr(getattr(again, f.name)) for f in dataclasses.fields(again)} == {
        f.name: repr(getattr(options, f.name)) for f in dataclasses.fields(options)
    }


def test_the_command_line_names_only_what_differs_from_the_defaults() -> None:
    assert RobotOptions(id=5, hub="tcp/h:1", world="w").argv() == [
        "robot",
        "--id",
        "5",
        "--hub",
        "tcp/h:1",
        "--world",
        "w",
    ]
    assert RobotOptions(id=5, user=1).argv()[-2:] == ["--user", "1"]
