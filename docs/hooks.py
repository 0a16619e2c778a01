"""MkDocs hook: the guide's generated pages, made from the code at every build (``mkdocs.yml``, ``hooks:``).

The command-line reference, the scenario keys and the wire protocol come from ``cli/reference.py``; the changelog
is the repository's ``CHANGELOG.md``. None of them is written into ``docs/``: each build makes them anew.

A page quotes a generated figure with a line ``<!-- figure: NAME -->``: the build puts there what
``petswarm bench all --out docs/figures`` wrote for it (``docs/figures/NAME/figure.md``: the header naming the
command, date, machine and load, the table, the plots), so no figure of the guide is copied by hand.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ROOT / "docs/figures"
FIGURE_LINE = re.compile(r"^<!-- figure: ([a-z0-9-]+) -->$", re.M)
"""A page's line that stands for a generated figure."""


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


def on_page_markdown(markdown: str, page: Any, config: Any, files: Files) -> str:
    """Each ``<!-- figure: NAME -->`` line becomes that figure as ``bench all`` wrote it, its plots linked from
    the page's folder."""
    page_dir = (ROOT / "docs" / page.file.src_path).parent
    return FIGURE_LINE.sub(lambda m: figure_for(m.group(1), page_dir), markdown)


def figure_for(name: str, page_dir: Path) -> str:
    """The generated figure ``name`` for a page in ``page_dir``, or what to run when it is not generated yet."""
    from petswarm.bench.all import figure_markdown, read_figures, select

    select([name])  # ValueError for a figure bench all does not make: a typo fails the build
    found = [o for o in read_figures(FIGURES) if o.name == name]
    if not found:
        return f"*Not generated in this tree yet: `petswarm bench all --out docs/figures --only {name}`.*\n"
    prefix = os.path.relpath(FIGURES, page_dir).replace(os.sep, "/") + "/"
    return "\n".join(figure_markdown(found[0], prefix))
