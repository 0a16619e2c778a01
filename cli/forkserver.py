"""``python -m cli.forkserver FD ROOM``: the fork server of a run's robot processes (``petswarm.lab.forking``).

It imports what a ``petswarm robot`` process imports, as lean as one (no OpenSSL), then forks a robot for each
request on the socket ``FD``; ``ROOM`` is blank space on its command line that a child overwrites with its own.
"""

import os
import socket
import sys
from pathlib import Path

from cli.lean import leave_out_openssl

leave_out_openssl(["robot"])  # before anything imports asyncio: every child is a robot

import gc  # noqa: E402

import cli.main  # noqa: E402
import petswarm.lab.lockstep_node  # noqa: E402 - imported once here instead of in every robot
import petswarm.lab.runtime  # noqa: E402
import petswarm.robot  # noqa: E402
from petswarm.lab.forking import become, serve  # noqa: E402

petswarm.robot.load_numpy()  # once here, shared with every child, instead of in each robot at its start


def main() -> int:
    """Serve until the supervisor leaves (0); in a child, run its ``petswarm`` command and return its code."""
    server_pid = os.getpid()
    try:  # the server learns of its children's ends through pidfds; without them, robots start the ordinary way
        os.close(os.pidfd_open(server_pid))
    except OSError as err:
        print(f"fork server: no pidfds here ({err}); the supervisor starts robots the ordinary way", file=sys.stderr)
        return 3
    # the command line, made here once: in every robot it cost about 0.1 s of CPU, most of it importing what the
    # parser and the version line use (importlib.metadata, the bench and chaos commands' options)
    parser = cli.main.build_parser()
    gc.freeze()  # what is imported stays shared with the children: the collector never touches it
    request = serve(socket.socket(fileno=int(sys.argv[1])))
    if request is None:
        return 0
    argv = become(request, server_pid)
    sys.argv[0] = str(Path(cli.main.__file__).with_name("__main__.py"))
    return cli.main.main(argv, parser)


raise SystemExit(main())
