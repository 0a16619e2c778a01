"""The README and the user guide: the guide builds with ``mkdocs build --strict``, its reference pages are made from
the code, and the README stays short and free of dates, issue numbers and branch names."""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from cli.main import build_parser
from cli.reference import cli_markdown, scenario_markdown, wire_markdown

ROOT = Path(__file__).resolve().parents[2]
DATE = re.compile(r"\b20\d\d-\d\d-\d\d\b|\b\d\d:\d\d UTC\b")
TRACKER = re.compile(r"\b(issue|issues) \d+|\bbranch `|\bPR #?\d+", re.I)
GUIDE = [
    ROOT / "README.md",
    ROOT / "docs/index.md",
    *sorted((ROOT / "docs/concepts").glob("*.md")),
    *sorted((ROOT / "docs/howto").glob("*.md")),
]
"""Pages for users: no dates, no history, no issue numbers or branches (history is in CHANGELOG.md)."""


@pytest.mark.timeout(120)
def test_the_guide_builds_with_mkdocs_strict(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
        capture_output=True,
        text=True,
        timeout=110,
        cwd=ROOT,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},  # no banner about Material's successor
    )
    assert done.returncode == 0, done.stderr[-3000:]
    site = tmp_path / "site"
    for page in ("reference/cli", "reference/scenario", "reference/wire", "figures", "changelog"):
        assert (site / page / "index.html").exists(), page  # the generated pages are in the build


def test_the_readme_is_at_most_250_lines_and_names_no_date_issue_or_branch() -> None:
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= 250
    for path in GUIDE:
        text = path.read_text()
        assert not DATE.findall(text), (path.name, DATE.findall(text))
        assert not TRACKER.findall(text), (path.name, TRACKER.findall(text))


def _commands(parser: argparse.ArgumentParser, path: tuple[str, ...]) -> list[tuple[tuple[str, ...], list[str]]]:
    found = [(path, [o for a in parser._actions for o in a.option_strings if o not in ("-h", "--help")])]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found += _commands(sub, (*path, name))
    return found


def test_the_cli_reference_has_every_command_and_every_option() -> None:
    parser = build_parser()
    page = cli_markdown(parser)
    sections = page.split("\n#")
    for path, options in _commands(parser, ("petswarm",)):
        title = " ".join(path)
        section = next((s for s in sections if s.lstrip("#").strip().split("\n")[0] == title), None)
        assert section is not None, f"no section for {title}"
        for option in options:
            assert f"`{option}" in section, f"{title}: {option} missing"


def test_the_reference_follows_the_code_and_refuses_an_undescribed_scenario_key(monkeypatch) -> None:
    from petswarm import scenario
    from petswarm.controllers.surround import SurroundConfig

    page = scenario_markdown()
    for key in (*scenario.TOP_KEYS, *scenario.ROBOTS_KEYS, *scenario.USER_KEYS, *SurroundConfig().to_dict()):
        assert f"`{key}`" in page, key
    assert "| `tx_range_m` | `30` |" in page  # a nested medium table's key with its default, from the dataclass
    monkeypatch.setattr(scenario, "TOP_KEYS", (*scenario.TOP_KEYS, "gravity"))
    with pytest.raises(ValueError, match="no description of top-level key"):
        scenario_markdown()


def test_the_wire_reference_lists_every_message_type() -> None:
    from radio_hub.link import wire

    page = wire_markdown()
    types = [cls.TYPE for cls in wire.Message.__subclasses__() if cls.TYPE]
    assert len(types) > 10
    for kind in types:
        assert f"### `{kind}`" in page, kind
    assert "petswarm/WORLD/up/NODE_ID" in page
