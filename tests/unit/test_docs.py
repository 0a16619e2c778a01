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


# -- every figure traces to a command ---------------------------------------------------------------------------
#
# The rule, per page (README.md and every docs/ page but the generated docs/figures/): a *figure* is a Markdown
# table with a cell that is a value (a number, a range or ratio of numbers, with a unit; code spans aside), a
# ``text`` (or plain) code block with a number in it, or an image.
# Each must be one of:
# - generated: an image under figures/, or a ``<!-- figure: NAME -->`` line, which the guide's build replaces with
#   what ``petswarm bench all`` wrote for NAME under its header (docs/hooks.py);
# - traced by its command: the block just before it or just after it (its caption) names a command that makes it,
#   as a code span ``petswarm ...`` or ``python -m pytest ...``, or as a line of a bash block; a table row that names
#   its own ``petswarm ...`` command, and a table with a ``source`` column, trace themselves;
# - not a measurement: the line before it is ``<!-- not measured: where the numbers come from -->`` (a standard's
#   constants, what the code allows).

COMMAND_SPAN = re.compile(r"`(?:\.venv/bin/)?(?:petswarm [a-z]|python -m pytest )")
COMMAND_LINE = re.compile(r"^\s*(?:\$ )?(?:time )?(?:\.venv/bin/)?(?:petswarm [a-z]|python -m pytest )")
GENERATED = re.compile(r"^<!-- figure: ([a-z0-9-]+) -->$")
NOT_MEASURED = re.compile(r"^<!-- not measured: \S.* -->$")
CODE_SPAN = re.compile(r"`[^`]*`")
LINK_TARGET = re.compile(r"\]\([^)]*\)")
IMAGE = re.compile(r"!\[[^\]]*\]\(([^)\s]+)")
DIGIT = re.compile(r"\d")
RULED = re.compile(r"[|\s:-]+")
UNIT = r"\s*[%a-zA-Z]{0,4}"
VALUE = re.compile(rf"[~<>=+-]*\s*\d[\d.,]*{UNIT}(?:\s*(?:/|-|to|,)\s*[+-]?\d[\d.,]*{UNIT})*")
"""A table cell that is a measured-looking value: ``3.83``, ``0.16 / 0.32``, ``1/0/0``, ``3.75-3.98 s``, ``5.5x``."""


def _blocks(lines: list[str]) -> list[tuple[str, int, int, str]]:
    """(kind, first line, last line, a fence's language) of each block of a page: fence, table, image or para."""
    blocks, i = [], 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("```"):
            j = i + 1
            while j < len(lines) and not lines[j].startswith("```"):
                j += 1
            blocks.append(("fence", i, j, line[3:].strip().split(" ")[0]))
        elif line.startswith("|"):
            j = i
            while j + 1 < len(lines) and lines[j + 1].startswith("|"):
                j += 1
            blocks.append(("table", i, j, ""))
        elif IMAGE.search(line):
            blocks.append(("image", i, i, ""))
            j = i
        elif line.strip():
            j = i
            while j + 1 < len(lines) and lines[j + 1].strip() and not lines[j + 1].startswith(("```", "|")):
                if IMAGE.search(lines[j + 1]):
                    break
                j += 1
            blocks.append(("para", i, j, ""))
        else:
            j = i
        i = j + 1
    return blocks


def _names_a_command(lines: list[str], block: tuple[str, int, int, str]) -> bool:
    kind, first, last, _ = block
    text = lines[first : last + 1]
    if kind == "fence":
        return any(COMMAND_LINE.match(line) for line in text[1:-1])
    return any(COMMAND_SPAN.search(line) for line in text)


def _is_figure(lines: list[str], block: tuple[str, int, int, str]) -> bool:
    kind, first, last, language = block
    body = lines[first : last + 1]
    if kind == "table":
        if "source" in [cell.strip().lower() for cell in body[0].split("|")]:
            return False  # each row says where its numbers come from
        rows = [CODE_SPAN.sub("", LINK_TARGET.sub("]", row)) for row in body if not COMMAND_SPAN.search(row)]
        cells = [cell.strip() for row in rows if not RULED.fullmatch(row) for cell in row.strip().strip("|").split("|")]
        return any(VALUE.fullmatch(cell) for cell in cells)
    if kind == "fence":
        inside = body[1:-1]
        commands = any(COMMAND_LINE.match(line) for line in inside)
        return language in ("", "text") and not commands and any(DIGIT.search(line) for line in inside)
    if kind == "image":
        match = IMAGE.search(body[0])
        return match is not None and "figures/" not in match.group(1)
    return False


def untraced_figures(text: str) -> list[str]:
    """The figures of a page that neither come from docs/figures nor name their command (the rule above)."""
    lines = text.splitlines()
    blocks = _blocks(lines)
    untraced = []
    for k, block in enumerate(blocks):
        if not _is_figure(lines, block):
            continue
        first = block[1]
        if first and (NOT_MEASURED.match(lines[first - 1]) or GENERATED.match(lines[first - 1])):
            continue
        if any(_names_a_command(lines, blocks[j]) for j in (k - 1, k + 1) if 0 <= j < len(blocks)):
            continue
        untraced.append(f"line {first + 1}: {block[0]} {lines[first][:50]!r}")
    return untraced


FIGURE_PAGES = [ROOT / "README.md", *sorted(p for p in (ROOT / "docs").rglob("*.md") if "figures" not in p.parts)]


@pytest.mark.parametrize("page", FIGURE_PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_figure_is_generated_or_names_its_command(page: Path) -> None:
    assert untraced_figures(page.read_text()) == []


def test_the_trace_rule_refuses_a_hand_pasted_table_and_takes_a_traced_one() -> None:
    table = "| robots | wall s |\n|---|---|\n| 20 | 3.9 |\n"
    assert untraced_figures(f"Some figures:\n\n{table}") == ["line 3: table '| robots | wall s |'"]
    assert untraced_figures("```text\nratio p50: 3.83\n```\n") == ["line 1: fence '```text'"]
    assert untraced_figures("![plot](img/plot.png)\n") == ["line 1: image '![plot](img/plot.png)'"]
    traced = [
        f"From `petswarm run scenarios/surround-cylinder.toml --clock model --seed 1`:\n\n{table}",
        f"{table}\n*`petswarm bench scale --robots 20` printed it.*\n",
        "```bash\npetswarm bench hub --floor\n```\n\n```text\nratio p50: 3.83\n```\n",
        f"<!-- not measured: the standard's constants -->\n{table}",
        "<!-- figure: hub -->\n",
        "![organize](figures/organize/bench_organize.png)\n",
        "| quantity | value | source |\n|---|---|---|\n| aTurnaroundTime | 12 symbols | the standard |\n",
        "| command | does |\n|---|---|\n| `petswarm bench hub --rounds 500` | hub overhead |\n",
        "| robots | ok |\n|---|---|\n| many | yes |\n",  # no value: not a figure
        "| property | holds when |\n|---|---|\n| no_runaway | beyond 1 m it grows by at most 0.5 m |\n",  # a definition
    ]
    for page in traced:
        assert untraced_figures(page) == [], page


def test_every_generated_figure_a_page_quotes_is_one_bench_all_makes() -> None:
    from petswarm.bench.all import FIGURES

    names = {f.name for f in FIGURES}
    quoted = {m.group(1) for page in FIGURE_PAGES for m in map(GENERATED.match, page.read_text().splitlines()) if m}
    assert quoted and quoted <= names, quoted - names
