"""MkDocs hook: the guide's generated pages, made from the code at every build (``mkdocs.yml``, ``hooks:``).

The command-line reference, the scenario keys and the wire protocol come from ``cli/reference.py``; the changelog
is the repository's ``CHANGELOG.md``. None of them is written into ``docs/``: each build makes them anew.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parents[1]


def on_files(files: Files, config: Any) -> Files:
    """Add the generated pages to the build's files, before the navigation is made from them."""
    from cli.main import build_parser
    from cli.reference import cli_markdown, scenario_markdown, wire_markdown

    pages = {
        "reference/cli.md": cli_markdown(build_parser()),
        "reference/scenario.md": scenario_markdown(),
        "reference/wire.md": wire_markdown(),
        "changelog.md": (ROOT / "CHANGELOG.md").read_text(),
    }
    if not (ROOT / "docs/figures/index.md").exists():
        pages["figures/index.md"] = _figures_placeholder()
    for path, content in pages.items():
        files.append(File.generated(config, path, content=content))
    return files


def _figures_placeholder() -> str:
    """The figures page before ``petswarm bench all --out docs/figures`` has written it: what that command runs."""
    from petswarm.bench.all import plan_markdown

    return "\n".join(
        [
            "# Figures",
            "",
            "Not generated in this tree yet: `petswarm bench all --out docs/figures` writes this page, with one header",
            "(command, date, machine, load) above every bench's table and plots, one section per figure below. It",
            "runs these commands, each with `--out docs/figures/NAME`:",
            "",
            *plan_markdown(),
            "",
        ]
    )
