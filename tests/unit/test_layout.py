"""The arrows of the layout (docs/DESIGN.md, "Packages"): cli -> petswarm -> radio_hub.interface/datasheet/determinism.

Read from the source (every import, also inside functions), so a forbidden import fails here even on a code
path no other test runs.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("cli", "petswarm", "radio_hub")
PUBLIC_FACES = ("radio_hub.interface", "radio_hub.datasheet", "radio_hub.determinism")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py"))}


MODULES = _modules()


def _imports(path: Path) -> list[tuple[str, str | None]]:
    """(module, name) for every import in the file; name is None for ``import module``."""
    found: list[tuple[str, str | None]] = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(alias.name, None) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found += [(node.module, alias.name) for alias in node.names]
    return found


def _target(module: str, name: str | None) -> str:
    """The module an import reaches: ``from pkg import mod`` reaches ``pkg.mod`` when that is a module."""
    if name is not None and f"{module}.{name}" in MODULES:
        return f"{module}.{name}"
    return module


def _top(module: str) -> str:
    return module.split(".")[0]


def _edges(importer: str) -> list[tuple[str, str | None]]:
    return [(_target(m, n), n) for m, n in _imports(MODULES[importer]) if _top(m) in PACKAGES]


def test_the_layout_is_there() -> None:
    """The packages the design names exist (a guard against checking an empty tree)."""
    for name in ("petswarm.lab", "petswarm.bench", "petswarm.managers", "radio_hub.interface", "radio_hub.datasheet"):
        assert name in MODULES, name


@pytest.mark.parametrize("module", sorted(m for m in MODULES if _top(m) == "radio_hub"))
def test_radio_hub_imports_neither_petswarm_nor_cli(module: str) -> None:
    bad = [t for t, _ in _edges(module) if _top(t) in ("petswarm", "cli")]
    assert not bad, f"{module} imports {bad}"


@pytest.mark.parametrize("module", sorted(m for m in MODULES if _top(m) == "petswarm"))
def test_petswarm_never_imports_cli(module: str) -> None:
    bad = [t for t, _ in _edges(module) if _top(t) == "cli"]
    assert not bad, f"{module} imports {bad}"


@pytest.mark.parametrize("module", sorted(m for m in MODULES if _top(m) == "petswarm"))
def test_petswarm_takes_radio_hub_only_through_its_public_faces(module: str) -> None:
    bad = [t for t, _ in _edges(module) if _top(t) == "radio_hub" and t not in PUBLIC_FACES]
    assert not bad, (
        f"{module} imports {bad}; petswarm takes radio_hub only through radio_hub.interface and radio_hub.datasheet"
    )


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_private_name_crosses_a_package(module: str) -> None:
    """``from x import _name`` only within one (sub)package: another package sees public names only."""
    home = module.rsplit(".", 1)[0] if MODULES[module].name != "__init__.py" else module
    bad = [
        f"{t}.{n}"
        for t, n in _edges(module)
        if n and n.startswith("_") and not n.startswith("__") and t.rsplit(".", 1)[0] != home
    ]
    assert not bad, f"{module} imports private {bad}"


def test_no_two_modules_import_each_other() -> None:
    """Within cli and petswarm, not even lazily inside a function: the runs' old import cycle (run <->
    run_scenario, now launch -> run, run_scenario, model_run, lockstep_run) stays gone."""
    ours = [m for m in MODULES if _top(m) in ("cli", "petswarm")]
    reach = {m: {t for t, _ in _edges(m) if t in MODULES and t != m} for m in ours}
    pairs = sorted((a, b) for a in reach for b in reach[a] if a < b and a in reach.get(b, set()))
    assert not pairs, pairs


@pytest.mark.parametrize("package", sorted(m for m, p in MODULES.items() if p.name == "__init__.py"))
def test_every_subpackage_says_what_is_in_it(package: str) -> None:
    if package in PACKAGES:
        return
    assert ast.get_docstring(ast.parse(MODULES[package].read_text())), package
