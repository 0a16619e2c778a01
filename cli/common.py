"""Options several commands share (``--hub``, ``--world``, ``--profile``, transport and link security, a node's
``--clock``), each added to a command's parser by one function here."""

from __future__ import annotations

import argparse
import difflib

from petswarm.lab.arguments import bounded, link_key_file, readable_file, world_name


class CommandParser(argparse.ArgumentParser):
    """A parser whose subcommands refuse an argument they do not know themselves, with their own usage and the
    nearest option: argparse hands it up to the top, which printed ``petswarm [-h] COMMAND ...`` for a typo
    such as ``petswarm run --robtos 5``."""

    def parse_known_args(self, args=None, namespace=None):  # type: ignore[no-untyped-def,override]
        """As argparse's, but an argument left over is an error of this parser's."""
        parsed, extra = super().parse_known_args(args, namespace)
        if extra:
            options = [o for o in self._option_string_actions if o.startswith("--")]
            near = difflib.get_close_matches(extra[0].split("=")[0], options, n=1)
            self.error(f"unrecognized arguments: {' '.join(extra)}" + (f" (did you mean {near[0]}?)" if near else ""))
        return parsed, extra


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
    """``--world``: the key prefix a hub and its nodes share."""
    p.add_argument(
        "--world",
        type=world_name,
        default="default",
        help="key prefix shared by a hub and its nodes (default %(default)s)",
    )


def add_hub(p: argparse.ArgumentParser) -> None:
    """``--hub``, ``--world`` and a client's transport security: how a node or a tool reaches its hub."""
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
    """``--clock``: a node process's clock (``petswarm.lab.robot_command.NODE_CLOCKS``)."""
    parser.add_argument(
        "--clock",
        choices=("wall", "lockstep"),
        default="wall",
        help="wall (default): run on the wall clock; lockstep: on model time granted by a `petswarm hub "
        "--clock lockstep` (the node waits for that hub at start)",
    )


def add_link_security(p: argparse.ArgumentParser) -> None:
    """``--link-key`` and ``--link-mic``: 802.15.4 link security (docs/SECURITY.md), off without a key."""
    p.add_argument(
        "--link-key",
        type=link_key_file,
        metavar="FILE",
        help="802.15.4 link security (AES-CCM*, docs/SECURITY.md) with the network key in FILE (32 hex digits); "
        "default: off",
    )
    p.add_argument(
        "--link-mic", type=int, choices=(4, 8), default=4, help="bytes of the frames' MIC with --link-key (default 4)"
    )
