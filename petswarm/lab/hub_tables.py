"""The hub's tables for a run: one rule for every hub, a process (``petswarm hub``) or in memory (a model run).

``--config`` gives the radio and the light, a scenario the world (its ``[hub]`` tables and obstacles), and a
profile its MAC, BLE and IR values over both.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from petswarm.scenario import Scenario
    from radio_hub.hosting import EnvironmentConfig


def hub_environment(config: str | None, scenario: Scenario | None, profile: str) -> EnvironmentConfig:
    """The environment a hub runs: ``config`` (a file), then ``scenario``'s world, then ``profile``'s values.

    ValueError names the option at fault (``--config`` or ``--scenario``) and what is wrong with it."""
    from radio_hub.hosting import EnvironmentConfig, apply_profile, environment_from_dict, load_config

    try:
        environment = load_config(config) if config else EnvironmentConfig()
    except OSError as err:  # as a person reads it: the file and what is wrong, not Python's errno
        raise ValueError(f"bad --config: {config}: {(err.strerror or str(err)).lower()}") from None
    except ValueError as err:
        raise ValueError(f"bad --config: {err}") from None
    if scenario is not None:
        try:
            tables = environment_from_dict(scenario.hub_tables())
        except ValueError as err:
            raise ValueError(f"bad --scenario: {err}") from None
        if config:  # --config gives the radio and light; the scenario the world
            tables.medium, tables.ir = environment.medium, environment.ir
        environment = tables
    return environment if profile == "ideal" else apply_profile(environment, profile)
