"""One way for the short commands (stats, swarm, chaos) to talk to a hub and say why when they cannot."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

from radio_hub.interface import open_session
from radio_hub.values import HubUnavailable


def with_hub(command: str, endpoint: str, body: Callable[[Any], int]) -> int:
    """Run ``body(session)`` on a client session to ``endpoint``; exit code 2 with the reason when the hub
    (or a robot behind it) cannot be reached."""
    try:
        session = open_session("client", endpoint)
    except HubUnavailable as err:
        print(f"petswarm {command}: {err}", file=sys.stderr)
        return 2
    try:
        return body(session)
    except HubUnavailable as err:
        print(f"petswarm {command}: {err}", file=sys.stderr)
        return 2
    finally:
        session.close()
