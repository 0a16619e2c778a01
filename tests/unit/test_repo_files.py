"""The repository's own promises: compose.yaml is valid Compose, and CI runs the README's test command."""

import json
import re
from pathlib import Path
from typing import Any

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
    from petswarm.lab.experiment import load

    for path in (ROOT / "examples").glob("experiment-*.toml"):
        assert load(path)["seeds"]


def test_the_compose_user_walks_a_scenario_that_loads():
    from petswarm.scenario import load

    compose = yaml.safe_load((ROOT / "compose.yaml").read_text())
    command = compose["services"]["user"]["command"]
    scenario = load(ROOT / command[command.index("--scenario") + 1])
    assert scenario.user is not None and scenario.user.legs
    assert "127.0.0.1:8047:8047" in compose["services"]["watch"]["ports"]  # the live view, on loopback only


def _subcommands(parser: Any) -> dict[str, Any]:
    import argparse

    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(actions[0].choices) if actions else {}


def test_the_readme_commands_table_is_one_table_and_names_every_subcommand():
    from cli.main import build_parser

    lines = (ROOT / "README.md").read_text().splitlines()
    start = lines.index("## The commands")
    end = next(i for i in range(start + 1, len(lines)) if lines[i].startswith("#"))
    section = lines[start + 1 : end]
    rows = [i for i, line in enumerate(section) if line.lstrip().startswith("|")]
    assert rows, "no table under '## The commands'"
    breaks = [section[i] for i in range(rows[0], rows[-1] + 1) if not section[i].lstrip().startswith("|")]
    assert not breaks, f"blank or text lines break the commands table: {breaks}"
    listed: set[tuple[str, str]] = set()
    for line in (section[i] for i in rows[2:]):  # after the header and its |---| line
        cell = re.split(r"(?<!\\)\|", line)[1].strip().strip("`")
        words = cell.split()
        assert words[0] == "petswarm", line
        actions = words[2].replace("\\|", "|").split("|") if len(words) > 2 and not words[2].startswith("-") else []
        listed |= {(words[1], action) for action in actions} | {(words[1], "")}
    missing = []
    for name, sub in _subcommands(build_parser()).items():
        wanted = [(name, action) for action in _subcommands(sub)] or [(name, "")]
        missing += [" ".join(w).strip() for w in wanted if w not in listed]
    assert not missing, f"README.md's commands table does not list: {missing}"


def test_every_document_the_readme_points_to_is_in_the_repository():
    readme = (ROOT / "README.md").read_text()
    links = re.findall(r"\]\(([^)#\s]+)\)", readme)  # markdown links
    named = re.findall(r"[\w./-]+\.md\b", readme)  # documents named in the text, linked or not
    # a bare name is one the layout block lists beside its folder (docs/: DESIGN.md, RESULTS.md...)
    missing = sorted(
        {p for p in [*links, *named] if "://" not in p and not any((d / p).exists() for d in (ROOT, ROOT / "docs"))}
    )
    assert not missing, f"README.md points to files the repository does not hold: {missing}"
