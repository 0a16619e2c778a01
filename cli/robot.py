"""``petswarm robot``: the options of a robot process, parsed into ``petswarm.lab.robot_command.RobotOptions``."""

from __future__ import annotations

import argparse

from cli.common import add_hub, add_link_security, add_node_clock, add_profile
from cli.options import options_of
from petswarm.lab.arguments import bounded, int_auto, position, robot_id, seed, surround_config
from petswarm.lab.robot_command import RobotOptions


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


def robot_options(args: argparse.Namespace) -> RobotOptions:
    """The typed options of a parsed ``petswarm robot`` command line."""
    return options_of(RobotOptions, args)
