"""Start a run: ``run(opts)`` picks the clock (wall, model, lockstep) and the kind of run (robots pinging and
organizing, or a scenario) and hands over to the module that runs it. It is the only module that imports
them all, and none of them imports it, so the runs form no import cycle.
"""

from __future__ import annotations

import sys

from petswarm.lab.run import RunOptions, ping_and_organize, roster_argv, supervise


def run(opts: RunOptions) -> int:
    """Run the emulation; returns the process exit code."""
    scenario = None
    if opts.scenario:
        from petswarm.scenario import ScenarioError, load

        try:
            scenario = load(opts.scenario)
        except ScenarioError as err:
            print(f"petswarm run: {err}", file=sys.stderr)
            return 2
        if scenario.actions and opts.clock != "model":
            kinds = ", ".join(sorted({a["kind"] for a in scenario.actions}))
            print(
                f"petswarm run: {opts.scenario}: {kinds} faults run in model time only (--clock model)", file=sys.stderr
            )
            return 2
    if opts.config is not None:  # checked on every clock before anything starts: unchecked, a traceback in model
        from radio_hub.hosting import config_problem  # time, a hub dead at start on the wall clock

        problem = config_problem(opts.config)
        if problem is not None:
            print(f"petswarm run: --config {problem}", file=sys.stderr)
            return 2
    if opts.clock == "model":
        from petswarm.lab.model_run import run_model

        return run_model(opts, scenario)
    if opts.clock == "lockstep":
        from petswarm.lab.lockstep_run import run_lockstep

        return run_lockstep(opts, scenario)
    if scenario is not None:
        from petswarm.lab.run_scenario import run_scenario

        return run_scenario(opts, scenario)
    return supervise(opts, "run", lambda _record: roster_argv(opts.robots), ping_and_organize)
