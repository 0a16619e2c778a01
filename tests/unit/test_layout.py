"""The arrows of the layout (docs/DESIGN.md, "Packages"): cli -> petswarm -> radio_hub's public faces
(interface, values, hosting, datasheet, determinism); pure models load no I/O.

The arrows are read from the source (every import, also inside functions), so a forbidden import fails here
even on a code path no other test runs. What a pure model loads is seen in a fresh interpreter, as a process
that imports it would.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("cli", "petswarm", "radio_hub")
PUBLIC_FACES = (
    "radio_hub.interface",
    "radio_hub.values",
    "radio_hub.hosting",
    "radio_hub.datasheet",
    "radio_hub.determinism",
)
PURE_MODELS = (
    # the robot's sans-IO cores and the vocabulary and models they share
    "petswarm.managers.formation_core",
    "petswarm.managers.token_schedule",
    "petswarm.controllers.driving_core",
    "petswarm.controllers.surround_core",
    "petswarm.managers.actions",
    "petswarm.managers.decisions",
    "petswarm.managers.exchange",
    "petswarm.managers.ir_estimator",
    "petswarm.managers.messages",
    "petswarm.managers.sequence",
    "petswarm.managers.serial_link",
    "petswarm.controllers.formation_shapes",
    "petswarm.controllers.side_check",
    "petswarm.controllers.motion",
    "petswarm.controllers.pet_controller",
    "petswarm.controllers.slave_controller",
    "petswarm.controllers.surround",
    "petswarm.controllers.surround_batch",
    "petswarm.controllers.surround_improved",
    "petswarm.controllers.surround_memory",
    "petswarm.controllers.surround_pilot",
    "petswarm.controllers.surround_safe",
    "petswarm.controllers.surround_sensing",
    "petswarm.wearables.activity",
    "petswarm.wearables.gestures",
    "petswarm.wearables.imu",
    "petswarm.wearables.lf_location",
    "petswarm.wearables.plan",
    "petswarm.wearables.user_link",
    "petswarm.angles",
    "petswarm.draws",
    "petswarm.grid",
    "petswarm.scenario",
    # the hub's pure face and its models of the air and the physics
    "radio_hub.values",
    "radio_hub.datasheet",
    "radio_hub.air.chaos",
    "radio_hub.air.error_model",
    "radio_hub.air.mac",
    "radio_hub.air.medium",
    "radio_hub.air.propagation",
    "radio_hub.air.security",
    "radio_hub.physics.ble",
    "radio_hub.physics.ir_air",
    "radio_hub.physics.lf",
    "radio_hub.physics.light",
    "radio_hub.physics.world",
)
"""Modules that compute and never do I/O: importing one loads no transport, no event loop and no threads."""
IO_MODULES = ("zenoh", "asyncio", "threading")


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
    """Not even lazily inside a function: the runs' old import cycle (run <-> run_scenario, now launch -> run,
    run_scenario, model_run, lockstep_run) and the radio port's (port <-> zenoh_link) stay gone."""
    ours = list(MODULES)
    reach = {m: {t for t, _ in _edges(m) if t in MODULES and t != m} for m in ours}
    pairs = sorted((a, b) for a in reach for b in reach[a] if a < b and a in reach.get(b, set()))
    assert not pairs, pairs


@pytest.mark.parametrize("package", sorted(m for m, p in MODULES.items() if p.name == "__init__.py"))
def test_every_subpackage_says_what_is_in_it(package: str) -> None:
    if package in PACKAGES:
        return
    assert ast.get_docstring(ast.parse(MODULES[package].read_text())), package


def _loaded(module: str) -> list[str]:
    """The I/O modules a fresh interpreter holds after importing ``module``."""
    probe = f"import json, sys\nimport {module}\nprint(json.dumps([m for m in {IO_MODULES!r} if m in sys.modules]))"
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, check=True, cwd=ROOT
    )
    return json.loads(done.stdout.splitlines()[-1])


@pytest.mark.parametrize("module", PURE_MODELS)
def test_a_pure_model_loads_neither_zenoh_nor_asyncio_nor_threads(module: str) -> None:
    assert module in MODULES, module
    assert _loaded(module) == [], f"importing {module} loads {_loaded(module)}"


def test_the_purity_probe_sees_io_when_it_is_loaded() -> None:
    """The check above could pass vacuously: a node's face does load zenoh, asyncio and threads."""
    assert _loaded("radio_hub.interface") == list(IO_MODULES)


def test_no_upward_arrow_between_petswarm_layers() -> None:
    """The lab's runs never import a bench, nor wearables a scenario: the layers below never reach above."""
    above = {"petswarm.lab": ("petswarm.bench", "petswarm.explore"), "petswarm.wearables": ("petswarm.scenario",)}
    bad = [
        (m, t)
        for m in MODULES
        for layer, forbidden in above.items()
        if m.startswith(layer + ".")
        for t, _ in _edges(m)
        if any(t == f or t.startswith(f + ".") for f in forbidden)
    ]
    assert not bad, bad


@pytest.mark.parametrize("face", [f for f in PUBLIC_FACES if f != "radio_hub.determinism"])
def test_a_public_face_names_what_it_hands_out(face: str) -> None:
    """A face imports its names, one by one, and lists them in ``__all__``: no module ``__getattr__`` that hands
    on whatever a caller asks for, so what petswarm takes from the hub is what the faces spell out."""
    tree = ast.parse(MODULES[face].read_text())
    functions = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert "__getattr__" not in functions, face
    exported = next(
        ast.literal_eval(n.value)
        for n in tree.body
        if isinstance(n, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__all__" for t in n.targets)
    )
    imported = {
        a.asname or a.name for _, n in [(0, x) for x in tree.body] if isinstance(n, ast.ImportFrom) for a in n.names
    }
    defined = {n.name for n in tree.body if isinstance(n, ast.FunctionDef | ast.ClassDef)} | {
        t.id for n in tree.body if isinstance(n, ast.Assign) for t in n.targets if isinstance(t, ast.Name)
    }
    assert set(exported) <= imported | defined, sorted(set(exported) - imported - defined)


PARSER_CALLS = ("add_argument", "add_argument_group", "add_mutually_exclusive_group", "add_parser", "add_subparsers")
"""The calls that define a command line; with ``ArgumentParser(...)`` they live in ``cli/`` only."""


def _parser_definitions(path: Path) -> list[str]:
    """Where a file defines command-line options: ``line: call`` for each such call."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        name = func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else ""
        if name in PARSER_CALLS or name == "ArgumentParser":
            found.append(f"{node.lineno}: {name}")
    return found


@pytest.mark.parametrize("module", sorted(m for m in MODULES if _top(m) != "cli"))
def test_every_command_line_option_is_defined_in_cli(module: str) -> None:
    """The command line has one home: petswarm and radio_hub take typed options, never an argparse parser."""
    found = _parser_definitions(MODULES[module])
    assert not found, f"{module} defines command-line options outside cli/ (at {', '.join(found)})"


def test_the_option_probe_sees_a_parser_definition(tmp_path: Path) -> None:
    """The probe above finds each way of defining options (a guard against a probe that never fires)."""
    probe = tmp_path / "probe.py"
    probe.write_text(
        "import argparse\np = argparse.ArgumentParser()\np.add_argument('--x')\ns = p.add_subparsers()\n"
        "s.add_parser('y').add_argument_group('g')\n"
    )
    found = sorted(f.split(": ")[1] for f in _parser_definitions(probe))
    assert found == ["ArgumentParser", "add_argument", "add_argument_group", "add_parser", "add_subparsers"]
