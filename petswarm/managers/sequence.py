"""Sequence manager: the robot's states (paper Fig. 4) and the record of every transition.

Pure code: it keeps the state, refuses transitions the design does not allow, and records each one as
a structured event with wall and monotonic timestamps. ``enter`` and ``restore`` change the state without
recording: they return the ``StateChange``, which a sans-IO core (``petswarm.managers.formation_core``) hands out as
an action for its runtime to record; ``transition`` and ``restore_driving`` do both at once, into the runtime's
``EventLog`` (``petswarm.managers.event_log``, the one part that reads the clock).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from petswarm.managers.event_log import EventLog


class RobotState(enum.IntEnum):
    """Where a robot is in the swarm process. Codes go on the wire in scan replies."""

    WAITING = 1
    FOLLOWING = 2
    LEADING = 3
    REMOTE_CONTROL = 4
    ORGANIZING = 5
    MASTER_DRIVING = 6
    SLAVE_DRIVING = 7
    COMMAND_WAITING = 8
    """Connected to its owner (the belt answered within 1 m), waiting for the user to choose an operation."""
    EMERGENCY = 9
    """Lost its user while leading or following: stopped, alert sent to the belt."""

    @property
    def label(self) -> str:
        """Lower-case name with dashes, as printed."""
        return self.name.lower().replace("_", "-")


DRIVING = frozenset(
    {
        RobotState.FOLLOWING,
        RobotState.LEADING,
        RobotState.REMOTE_CONTROL,
        RobotState.COMMAND_WAITING,
        RobotState.EMERGENCY,
    }
)
"""The states of a robot connected to its user, outside any swarm."""

_ALLOWED: dict[RobotState, frozenset[RobotState]] = {
    RobotState.WAITING: frozenset({RobotState.ORGANIZING, *DRIVING}),
    RobotState.ORGANIZING: frozenset(
        {RobotState.WAITING, RobotState.SLAVE_DRIVING, RobotState.MASTER_DRIVING, *DRIVING}
    ),
    # the master's role passes between members of a running swarm on a driving-mode change (Table 3, Change)
    RobotState.SLAVE_DRIVING: frozenset({RobotState.WAITING, RobotState.MASTER_DRIVING}),
    RobotState.MASTER_DRIVING: frozenset({*DRIVING, RobotState.SLAVE_DRIVING}),
    **{s: frozenset({RobotState.ORGANIZING, RobotState.WAITING, *DRIVING} - {s}) for s in DRIVING},
}


class TransitionError(RuntimeError):
    """A transition the state machine does not allow."""


@dataclass(frozen=True)
class StateChange:
    """One transition that happened, to be recorded as a ``state`` event."""

    frm: RobotState
    to: RobotState
    detail: dict[str, Any] = field(default_factory=dict)

    def fields(self) -> dict[str, Any]:
        """The ``state`` event's fields."""
        return {"frm": self.frm.label, "to": self.to.label, **self.detail}


class SequenceManager:
    """The robot's state, its previous driving state (restored after a swarm), and its transitions."""

    def __init__(self, log: EventLog, state: RobotState = RobotState.WAITING) -> None:
        self.log = log
        self.state = state
        self.previous_driving: RobotState | None = None

    def enter(self, to: RobotState, **detail: Any) -> StateChange:
        """Move to ``to`` without recording it; raises TransitionError when Fig. 4 has no such arrow."""
        if to not in _ALLOWED[self.state]:
            raise TransitionError(f"no transition from {self.state.label} to {to.label}")
        if self.state in DRIVING and to == RobotState.ORGANIZING:
            self.previous_driving = self.state
        elif to in (RobotState.WAITING, RobotState.SLAVE_DRIVING):
            # a slave or a waiting robot has no user of its own, so no driving state to go back to; kept, it
            # would make a later candidate (waiting -> organizing) look connected to its former user
            self.previous_driving = None
        change = StateChange(self.state, to, detail)
        self.state = to
        return change

    def restore(self, **detail: Any) -> StateChange:
        """Back to the driving state the robot had before it organized a swarm, without recording it."""
        return self.enter(self.previous_driving or RobotState.FOLLOWING, **detail)

    def transition(self, to: RobotState, **detail: Any) -> None:
        """Move to ``to`` and record it; raises TransitionError when Fig. 4 has no such arrow."""
        self.log.record("state", **self.enter(to, **detail).fields())

    def restore_driving(self, **detail: Any) -> RobotState:
        """Back to the driving state the robot had before it organized a swarm, recorded."""
        change = self.restore(**detail)
        self.log.record("state", **change.fields())
        return change.to

    @property
    def user_connected(self) -> bool:
        """True in a driving state or as a master (the user is this robot's owner)."""
        return (
            self.state in DRIVING
            or self.state == RobotState.MASTER_DRIVING
            or (self.state == RobotState.ORGANIZING and self.previous_driving is not None)
        )
