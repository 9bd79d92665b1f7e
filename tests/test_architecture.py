"""The package's shape: data flows one way through the layers, and functions stay readable.

docs/architecture.md draws the layers; these tests keep the code to the drawing.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "tactile_braille"

LAYERS = {
    "_io": 0, "_version": 0, "_registration": 0, "_tasks": 0, "_figures": 0,
    "keyboard": 1,
    "sensor": 2,
    "rigs": 3,
    "datasets": 4,
    "envs": 5, "gallery": 5,
    "supervised": 6,
    "agents": 7,
    "evaluation": 8,
    "sweep": 9, "baselines": 9, "search": 9, "tuning": 9,
    "cli": 10, "cli_config": 10,
}  # fmt: skip
"""Each top-level module or subpackage and its layer: a module imports only from its layer and below."""
LONGEST_FUNCTION_LINES = 80


def _modules() -> list[Path]:
    return sorted(p for p in PACKAGE.rglob("*.py") if p.name != "__init__.py" or p.parent != PACKAGE)


def _layer_of(path: Path) -> str:
    return path.relative_to(PACKAGE).parts[0].removesuffix(".py")


def _imported_layers(path: Path) -> set[str]:
    """The package's layers a module imports, at module level or inside functions."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
    return {n.split(".")[1] for n in names if n.startswith("tactile_braille.")}


def test_every_module_has_a_layer():
    assert {_layer_of(p) for p in _modules()} <= set(LAYERS)


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_module_imports_a_layer_above_its_own(path):
    own = LAYERS[_layer_of(path)]
    above = sorted(layer for layer in _imported_layers(path) if LAYERS[layer] > own)
    assert not above, f"{path.relative_to(PACKAGE)} (layer {own}) imports {above}, a layer above"


def test_the_layer_check_sees_an_upward_import(tmp_path):
    module = tmp_path / "module.py"
    module.write_text("def f():\n    from tactile_braille.agents.training import train\n")
    assert _imported_layers(module) == {"agents"}


def _functions(path: Path):
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            yield node.name, node.lineno, node.end_lineno - node.lineno + 1


def test_no_function_is_longer_than_80_lines():
    long = [
        f"{path.relative_to(PACKAGE)}:{line} {name} ({length} lines)"
        for path in _modules()
        for name, line, length in _functions(path)
        if length > LONGEST_FUNCTION_LINES
    ]
    assert not long, long


def test_every_import_of_the_package_resolves():
    """Imports inside functions run only when their branch does (a Ray trial, a robot): check them all."""
    import importlib

    missing = []
    for path in _modules():
        for node in ast.walk(ast.parse(path.read_text())):
            if (
                isinstance(node, ast.ImportFrom)
                and node.level == 0
                and (node.module or "").startswith("tactile_braille")
            ):
                module = importlib.import_module(node.module)
                missing += [
                    f"{path.relative_to(PACKAGE)}: {node.module}.{alias.name}"
                    for alias in node.names
                    if not hasattr(module, alias.name)
                    and importlib.util.find_spec(f"{node.module}.{alias.name}") is None
                ]
    assert not missing, missing
