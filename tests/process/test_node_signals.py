"""A lockstep node's loop closes without ever putting SIGTERM back to its default action, and a wall-clock
robot that stopped is not killed by the next SIGTERM.

Each check runs in its own interpreter: it sends itself SIGTERM, which a test worker must not get. The signal
is sent at the worst moment, from inside asyncio's close, right after it resets one of the loop's signals.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
import time

SCRIPT = textwrap.dedent(
    """
    import os, signal
    from petswarm.clock import LockstepLoop

    class Loop(LockstepLoop):
        def remove_signal_handler(self, sig):
            removed = super().remove_signal_handler(sig)
            os.kill(os.getpid(), signal.SIGTERM)  # the run's SIGTERM, just after asyncio reset a signal
            return removed

    async def work():
        return 0

    loop = Loop()
    loop.add_signal_handler(signal.SIGTERM, lambda: None)
    loop.add_signal_handler(signal.SIGINT, lambda: None)
    loop.run_until_complete(work())
    loop.close()
    os.kill(os.getpid(), signal.SIGTERM)  # and one more once the loop is gone
    print("closed", signal.getsignal(signal.SIGTERM) is signal.SIG_IGN, signal.getsignal(signal.SIGINT) is
          signal.default_int_handler, signal.set_wakeup_fd(-1))
    """
)

RUN_LOOP_SCRIPT = textwrap.dedent(
    """
    import signal
    from petswarm.clock import LockstepLoop

    def mine(signum, frame):
        pass

    signal.signal(signal.SIGTERM, mine)

    async def work():
        return 0

    loop = LockstepLoop()
    loop.run_until_complete(work())
    loop.close()
    print("kept", signal.getsignal(signal.SIGTERM) is mine)
    """
)


def _python(script: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)


def test_a_node_loop_closes_with_sigterm_ignored_even_when_one_comes_while_it_closes() -> None:
    proc = _python(SCRIPT)
    assert proc.returncode == 0, (proc.returncode, proc.stderr)
    # SIGTERM ignored, SIGINT back to Python's own, and the wake-up fd on the closed self-pipe released
    assert proc.stdout.split() == ["closed", "True", "True", "-1"], proc.stdout


def test_a_loop_that_never_handled_sigterm_leaves_its_process_handler_alone() -> None:
    proc = _python(RUN_LOOP_SCRIPT)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["kept", "True"], proc.stdout


def test_a_wall_clock_robot_that_stopped_on_sigterm_is_not_killed_by_the_next_one(make_air) -> None:
    """A robot stops on SIGTERM; the next ones (``timeout``'s to the process group, then its supervisor's)
    find its work done: it ends with 0, not as killed by a signal, and its last event is written."""
    air = make_air()
    air.robot(1)
    robot = air.sup.children["robot-1"]
    deadline = time.monotonic() + 30
    while robot.poll() is None and time.monotonic() < deadline:
        robot.send_signal(signal.SIGTERM)
        time.sleep(0.005)
    assert robot.wait(5) == 0, air.sup.log_tail("robot-1")
    assert "Exception ignored" not in air.sup.log_tail("robot-1", 50)
