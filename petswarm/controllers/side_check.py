"""Telling a user ahead from one behind by moving: the LF fix cannot (pet-bot-wearable.md: front/back is
ambiguous, y >= 0), so a robot takes the side its mode implies: following, the user ahead; leading, behind.
That holds while it drove with him, not after he walked round it as it stood (waiting for a command, in remote
control, in an emergency): it then drives away from him, and he is lost for good.

The check: while the user stands (the belt says so), the robot's own motion changes its distance to him by
a predictable amount. Driving toward the side it believes him on must close the distance; if the fixes say
it opened (or the other way round) he is on the other side. Pure: motion and fixes in, a verdict out.
"""

from __future__ import annotations

from dataclasses import dataclass

from petswarm.wearables.lf_location import UserFix

PROBE_M = 0.15
"""Own motion along the believed line to the user that makes a verdict: six times the LF's ranging error at
2 m (1.2 % a burst, ``LfConfig.noise_db``), so the fixes' change has a sign to read."""
UNSURE_SPEED_MPS = 0.5
"""Top speed toward a standing user while his side is unchecked: a slow walk. Before a verdict a robot on the
wrong side drives away from him by at most PROBE_M, one LF period (0.35 s) at this speed and its braking
(0.5 m/s at 1.5 m/s^2): 0.41 m, instead of over a metre at its top speed."""
ACTIVITY_LAG_S = 1.25
"""How long a walk may go unreported by the belt: its recogniser needs three sign changes (1.5 gait cycles) in
its window, 1.25 s at the slowest stroll it knows (1.2 Hz). A refuted side waits this long, the robot still: a
walk that began during the check, mistaken for the robot's own motion, shows by then."""
CHANGE_M = 0.1
"""The distance's change the fixes must show for a verdict: about three sigma of the difference of two fixes
at 2 m (3.4 cm); a smaller one (the robot moved across the line) starts the check over."""


@dataclass
class SideCheck:
    """Armed when the robot's side is assumed rather than known; disarmed by a verdict.

    Only motion along the robot's axis tells the sides apart: the user's mirror image across the antennas'
    line has the same left offset, so sideways motion changes both distances alike (it is predicted and
    taken out of what the fixes show)."""

    armed: bool = False
    reference_m: float | None = None
    """The distance of the fix the check started from."""
    along_m: float = 0.0
    """How the robot's motion along its axis since then should have changed the distance, were the user where
    it believes (the mirror image: the opposite)."""
    across_m: float = 0.0
    """How its sideways motion changed the distance, on either side."""

    def arm(self, fix: UserFix | None) -> None:
        """The side is an assumption from now on (a mode chosen, a turn-about done); ``fix``: the last one."""
        self.armed = True
        self._start(fix)

    def restart(self) -> None:
        """The user moved: what was measured so far says nothing of the side."""
        self._start(None)

    def _start(self, fix: UserFix | None) -> None:
        self.reference_m = None if fix is None else fix.distance_m
        self.along_m = self.across_m = 0.0

    def moved(self, vx: float, vy: float, fix: UserFix | None, dt: float) -> None:
        """The robot moved at (vx, vy) m/s in its own frame for ``dt`` s, the user believed at ``fix``."""
        if self.armed and self.reference_m is not None and fix is not None and fix.distance_m > 0:
            self.along_m -= vx * fix.forward_m / fix.distance_m * dt
            self.across_m -= vy * fix.left_m / fix.distance_m * dt

    def judge(self, fix: UserFix) -> bool | None:
        """A new fix: True the side is confirmed, False the user is on the other side, None no verdict yet."""
        if not self.armed:
            return None
        if self.reference_m is None:
            self._start(fix)
            return None
        if abs(self.along_m) < PROBE_M:
            return None
        observed = fix.distance_m - self.reference_m - self.across_m
        if abs(observed) < CHANGE_M:
            self._start(fix)
            return None
        self.armed = False
        return observed * self.along_m > 0
