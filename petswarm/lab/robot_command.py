"""The options of a robot process (``petswarm robot``) and the ``RobotConfig`` they describe. The command line
and a model-time run build robots from the same command lines, so both take them from here: the CLI adds
them to its parser, ``model_run`` parses a run's robot argv with ``robot_parser()``.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from petswarm.lab.arguments import (
    add_link_security,
    bounded,
    int_auto,
    position,
    readable_file,
    robot_id,
    seed,
    surround_config,
    world_name,
)

if TYPE_CHECKING:
    from petswarm.robot import RobotConfig


def add_robot_arguments(robot: argparse.ArgumentParser) -> None:
    """The options of ``petswarm robot``, added to ``robot`` (its subcommand parser)."""
    add_node_clock(robot)
    robot.add_argument(
        "--id",
        type=robot_id,
        required=True,
        help="robot id 1-65533, also its short address; 'auto' claims the lowest free one",
    )
    add_hub(robot)
    robot.add_argument("--pan", type=int_auto, default=0x1000, help="PAN ID to start on (default 0x1000)")
    robot.add_argument("--channel", type=bounded(int, 11, 26), default=11, help="802.15.4 channel 11-26 (default 11)")
    robot.add_argument(
        "--pos",
        type=position,
        default=None,
        help="position x,y in metres; write --pos=-1,2 when x is negative (default: a 1.5 m grid by id, five to a row)",
    )
    robot.add_argument(
        "--ping-interval",
        type=bounded(float, 0, 3600),
        default=0.0,
        help="broadcast a ping every this many seconds (default 0: never)",
    )
    robot.add_argument("--seed", type=seed, default=0, help="seed of the robot's own random choices (default 0)")
    robot.add_argument(
        "--user",
        type=bounded(int, 0, 65535),
        default=0,
        help="start connected to this user, following (default 0: a waiting robot)",
    )
    robot.add_argument(
        "--region-rssi",
        type=bounded(int, -120, 0),
        default=-70,
        help="as master: the available region, in dBm heard (default -70, about 10 m)",
    )
    robot.add_argument(
        "--step-deadline",
        type=bounded(float, 0.005, 10),
        default=None,
        help="seconds each organizing step waits for answers before retrying (default 0.1; the profile's when it "
        "sets one)",
    )
    robot.add_argument(
        "--step-retries",
        type=bounded(int, 0, 50),
        default=5,
        help="retries of an organizing step before it gives up on the missing (default 5)",
    )
    robot.add_argument("--record", metavar="FILE", help="append every event to this JSON-lines file as it happens")
    add_profile(robot, "the robot's MCU and UART latency per frame, its organizing steps' deadline")
    add_link_security(robot)
    robot.add_argument(
        "--heading",
        type=bounded(float, -360, 360),
        default=0.0,
        help="heading in degrees, counter-clockwise from +x (default 0); orients the IR receivers",
    )
    robot.add_argument(
        "--ir-estimator",
        choices=("paper", "lsq"),
        default="lsq",
        help="relative location from IR: equations (1)-(3) or the least-squares fit (default lsq)",
    )
    robot.add_argument(
        "--ir-slot", type=bounded(float, 0.01, 5), default=0.1, help="seconds each token holder shines (default 0.1)"
    )
    robot.add_argument(
        "--ir-deadline",
        type=bounded(float, 0.005, 10),
        default=0.05,
        help="seconds the token holder waits for the start sign's and the token's answers (default 0.05)",
    )
    robot.add_argument(
        "--ir-retries",
        type=bounded(int, 0, 50),
        default=3,
        help="retries of those two steps before the holder moves on without the missing (default 3)",
    )

    robot.add_argument(
        "--protocol",
        choices=("paper", "slotted"),
        default="paper",
        help="organizing protocol when this robot is master (default paper)",
    )
    robot.add_argument(
        "--formation",
        choices=("swarm", "surround"),
        default="swarm",
        help="swarm: the leader-follower middleware; surround: the surround law on IR beacons and echoes "
        "(default swarm)",
    )
    robot.add_argument(
        "--surround-human",
        default="user",
        metavar="ID",
        help="surround: node id of the human's IR beacon (default %(default)s)",
    )
    robot.add_argument(
        "--surround-config",
        type=surround_config,
        default=None,
        metavar="JSON",
        help="surround: law settings as a JSON object, e.g. '{\"stiffness\": 8}' (default: the documented gains)",
    )


def robot_parser() -> argparse.ArgumentParser:
    """A parser of robot command lines (``robot --id 3 ...``), as the CLI parses them."""
    parser = argparse.ArgumentParser(prog="petswarm")
    sub = parser.add_subparsers(dest="command", required=True)
    add_robot_arguments(sub.add_parser("robot"))
    return parser


def robot_config(args: argparse.Namespace) -> RobotConfig:
    """The robot a ``petswarm robot`` command line describes (also how a model-time run builds its robots)."""
    from petswarm.controllers.surround import SurroundConfig
    from petswarm.controllers.surround_pilot import SurroundDriverConfig
    from petswarm.managers.exchange import StepTiming
    from petswarm.managers.formation import FormationConfig
    from petswarm.managers.relative_location import TokenConfig
    from petswarm.profiles import robot_profile
    from petswarm.robot import RobotConfig
    from radio_hub.interface import read_key_file

    profile = robot_profile(args.profile)
    deadline = args.step_deadline if args.step_deadline is not None else profile.step_deadline_s
    timing = StepTiming(StepTiming().deadline_s if deadline is None else deadline, args.step_retries)
    formation = FormationConfig(protocol=args.protocol, step=timing, min_rssi_dbm=args.region_rssi)
    return RobotConfig(
        robot_id=args.id,
        endpoint=args.hub,
        world=args.world,
        pan_id=args.pan,
        channel=args.channel,
        position=args.pos,
        ping_interval=args.ping_interval,
        seed=args.seed,
        user=args.user,
        formation=formation,
        token=TokenConfig(
            slot_s=args.ir_slot, step=StepTiming(args.ir_deadline, args.ir_retries), estimator=args.ir_estimator
        ),
        heading_deg=args.heading,
        record=args.record,
        formation_mode=args.formation,
        surround=SurroundDriverConfig(law=args.surround_config or SurroundConfig(), human_id=args.surround_human),
        profile=args.profile,
        link_key=read_key_file(args.link_key).hex() if args.link_key else None,
        link_mic=args.link_mic,
    )


def add_profile(p: argparse.ArgumentParser, sets: str) -> None:
    """``--profile``: the testbed profile (docs/PROFILES.md); ``sets`` says what it sets for this command."""
    from petswarm.profiles import DEFAULT_PROFILE, PROFILES

    p.add_argument(
        "--profile",
        choices=PROFILES,
        default=DEFAULT_PROFILE,
        help=f"testbed profile (default %(default)s: today's ideal air and instant processing; kim2017: the swarm "
        f"paper's testbed, docs/PROFILES.md): {sets}",
    )


def add_world(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--world",
        type=world_name,
        default="default",
        help="key prefix shared by a hub and its nodes (default %(default)s)",
    )


def add_hub(p: argparse.ArgumentParser) -> None:
    p.add_argument("--hub", default="tcp/127.0.0.1:7447", help="the hub's zenoh endpoint (default %(default)s)")
    add_world(p)
    add_tls(p, "client")


def add_tls(p: argparse.ArgumentParser, side: str) -> None:
    """TLS files and a zenoh config file (README "Trust model"); none of them on loopback."""
    tls = p.add_argument_group("transport security (a hub on another host; see README 'Trust model')")
    if side == "hub":
        tls.add_argument("--tls-cert", type=readable_file, metavar="PEM", help="the hub's certificate: listen on TLS")
        tls.add_argument("--tls-key", type=readable_file, metavar="PEM", help="the hub certificate's private key")
        tls.add_argument(
            "--tls-ca",
            type=readable_file,
            metavar="PEM",
            help="ask every client for a certificate signed by this CA (mutual TLS) and enforce the access "
            "control: robot-N and user-N publish only on their own keys, operator asks and commands, "
            "nobody but the hub publishes on down/**",
        )
        tls.add_argument(
            "--acl-ids",
            type=bounded(int, 1, 65533),
            default=64,
            help="certificates robot-1..robot-N and user-1..user-N get node rights (default %(default)s)",
        )
    else:
        tls.add_argument("--tls-ca", type=readable_file, metavar="PEM", help="check the hub's certificate with this CA")
        tls.add_argument(
            "--tls-cert",
            type=readable_file,
            metavar="PEM",
            help="this process's certificate (common name robot-N, user-N or operator) for a hub asking for one",
        )
        tls.add_argument("--tls-key", type=readable_file, metavar="PEM", help="that certificate's private key")
    tls.add_argument(
        "--zenoh-config", type=readable_file, metavar="FILE", help="a zenoh JSON5 config file the session starts from"
    )


def add_node_clock(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--clock",
        choices=("wall", "lockstep"),
        default="wall",
        help="wall (default): run on the wall clock; lockstep: on model time granted by a `petswarm hub "
        "--clock lockstep` (the node waits for that hub at start)",
    )
