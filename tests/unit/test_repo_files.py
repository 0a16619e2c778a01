"""The repository's own promises: compose.yaml is valid Compose, and CI runs the README's test command."""

import json
import re
from pathlib import Path

import jsonschema
import yaml

ROOT = Path(__file__).resolve().parents[2]


def test_compose_file_validates_against_the_compose_specification():
    schema = json.loads((ROOT / "tests/data/compose-spec.json").read_text())
    compose = yaml.safe_load((ROOT / "compose.yaml").read_text())
    jsonschema.Draft7Validator(schema).validate(compose)
    assert {"hub", "robot", "user"} <= set(compose["services"])
    robot = compose["services"]["robot"]["command"]
    assert "auto" in robot and "tcp/hub:7447" in robot  # replicas can scale, explicit endpoint


def test_ci_runs_exactly_the_test_command_of_the_readme():
    readme = (ROOT / "README.md").read_text()
    match = re.search(r"<!-- test-command -->\s*```(?:bash|sh)?\n(.+?)\n```", readme, re.S)
    assert match, "README.md must mark its test command with <!-- test-command -->"
    command = match.group(1).strip()
    ci = (ROOT / ".ci/run").read_text()
    assert command in ci.splitlines()


def test_example_configs_load():
    from radio_hub.config import MediumConfig

    for path in (ROOT / "examples").glob("medium-*.toml"):
        config = MediumConfig.from_file(path)
        assert config != MediumConfig(), f"{path.name} changes nothing"


def test_example_experiments_load():
    from cli.experiment import load

    for path in (ROOT / "examples").glob("experiment-*.toml"):
        assert load(path)["seeds"]


def test_the_compose_user_walks_a_scenario_that_loads():
    from petswarm.scenario import load

    compose = yaml.safe_load((ROOT / "compose.yaml").read_text())
    command = compose["services"]["user"]["command"]
    scenario = load(ROOT / command[command.index("--scenario") + 1])
    assert scenario.user is not None and scenario.user.legs
    assert "127.0.0.1:8047:8047" in compose["services"]["watch"]["ports"]  # the live view, on loopback only
