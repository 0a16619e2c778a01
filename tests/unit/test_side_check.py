"""The side check: a robot's own motion toward a standing user must close the distance on the side it believes."""

from __future__ import annotations

from petswarm.controllers.side_check import PROBE_M, SideCheck
from petswarm.wearables.lf_location import UserFix


def _fix(forward: float, left: float = 0.0) -> UserFix:
    distance = (forward**2 + left**2) ** 0.5
    return UserFix(forward, left, distance, 0.0, True)


def _drive(
    check: SideCheck, believed_forward: float, true_forward: float, vx: float, seconds: float
) -> list[bool | None]:
    """Drive at ``vx`` for ``seconds`` with a fix every 0.35 s; the user stands ``true_forward`` ahead (negative:
    behind), the robot believes him at ``believed_forward`` (the LF gives the distance, the belief the sign)."""
    verdicts = []
    x = 0.0
    for step in range(round(seconds / 0.05)):
        believed = _fix(abs(true_forward - x) * (1 if believed_forward > 0 else -1))
        check.moved(vx, 0.0, believed, 0.05)
        x += vx * 0.05
        if step % 7 == 6:
            verdicts.append(check.judge(_fix(abs(true_forward - x) * (1 if believed_forward > 0 else -1))))
    return verdicts


def test_driving_toward_a_user_on_the_believed_side_confirms_it() -> None:
    check = SideCheck()
    check.arm(_fix(1.8))
    verdicts = _drive(check, believed_forward=1.8, true_forward=1.8, vx=0.5, seconds=1.0)
    assert True in verdicts and False not in verdicts and not check.armed


def test_driving_toward_a_user_on_the_other_side_refutes_it() -> None:
    check = SideCheck()
    check.arm(_fix(1.8))
    # he is behind: driving forward (toward where it believes him) opens the distance
    verdicts = _drive(check, believed_forward=1.8, true_forward=-1.8, vx=0.5, seconds=1.0)
    assert False in verdicts and True not in verdicts and not check.armed


def test_no_verdict_before_enough_motion_or_when_disarmed() -> None:
    check = SideCheck()
    assert check.judge(_fix(1.0)) is None  # not armed
    check.arm(_fix(1.0))
    slow = _drive(check, believed_forward=1.0, true_forward=-1.0, vx=PROBE_M / 2, seconds=0.7)
    assert set(slow) == {None} and check.armed


def test_motion_across_the_axis_gives_no_verdict() -> None:
    """Sideways toward a user abeam closes the distance on either side of the antennas' line: no verdict."""
    check = SideCheck()
    check.arm(_fix(0.1, 1.5))
    for _ in range(20):
        check.moved(0.0, 0.5, _fix(0.1, 1.5), 0.05)
    assert abs(check.along_m) < PROBE_M and check.across_m < -0.4
    assert check.judge(_fix(0.1, 1.0)) is None and check.armed
