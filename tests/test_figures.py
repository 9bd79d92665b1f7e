"""Figures: library code writes PNGs without pyplot and without touching the user's backend."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import matplotlib
import numpy as np
import pytest
from PIL import Image

import tactile_braille
from tactile_braille._figures import PNG_DPI, colormap, new_figure, save_figure
from tactile_braille.gallery import save_gallery
from tactile_braille.keyboard.keycaps import build_keycap, save_keycap_preview
from tactile_braille.supervised.report import save_confusion_matrix

PACKAGE = Path(tactile_braille.__file__).parent

PYPLOT_ALLOWED = {"envs/braille_env.py"}
"""``render_mode="human"`` opens an interactive window on the user's backend: pyplot is meant for that."""


def _imports(tree: ast.AST) -> list[str]:
    """Every module an ``import`` names, and ``module.name`` for each ``from module import name``."""
    names = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names += [node.module] + [f"{node.module}.{alias.name}" for alias in node.names]
    return names


def _parse(relative: str) -> ast.AST:
    return ast.parse((PACKAGE / relative).read_text(), filename=relative)


def test_library_code_never_selects_a_backend_nor_imports_pyplot():
    offenders = []
    for path in sorted(PACKAGE.rglob("*.py")):
        name = path.relative_to(PACKAGE).as_posix()
        text = path.read_text()
        if "matplotlib" not in text:  # no way to reach it without naming it
            continue
        tree = ast.parse(text, filename=name)
        imported = _imports(tree)
        if "matplotlib.use" in imported or any(
            isinstance(node, ast.Attribute) and node.attr == "use"
            and isinstance(node.value, ast.Name) and node.value.id == "matplotlib"
            for node in ast.walk(tree)
        ):  # fmt: skip
            offenders.append(f"{name}: matplotlib.use")
        if "matplotlib.pyplot" in imported and name not in PYPLOT_ALLOWED:
            offenders.append(f"{name}: matplotlib.pyplot")
    assert offenders == []


def test_figures_module_sits_at_the_bottom_and_keycaps_does_not_reach_up():
    own = {n for n in _imports(_parse("_figures.py")) if n.startswith("tactile_braille")}
    assert own <= {"tactile_braille._io", "tactile_braille._io.atomic_path"}
    assert not any(n.startswith("tactile_braille.gallery") for n in _imports(_parse("keyboard/keycaps.py")))


def test_save_figure_writes_a_png_of_figsize_times_dpi(tmp_path):
    fig, axes = new_figure(1, 2, figsize=(2.0, 1.5))
    assert axes.shape == (1, 2)
    axes[0, 1].plot([0, 1], [1, 0])
    path = save_figure(fig, tmp_path / "out" / "x.png")
    assert path == tmp_path / "out" / "x.png"
    assert sorted(p.name for p in path.parent.iterdir()) == ["x.png"]  # no temporary file left
    with Image.open(path) as image:
        assert image.format == "PNG"
        assert image.size == (round(2.0 * PNG_DPI), round(1.5 * PNG_DPI))


def test_new_figure_passes_subplot_keywords_and_colormap_resamples():
    _, axes = new_figure(2, 1, projection="3d")
    assert axes.shape == (2, 1)
    assert {ax.name for ax in axes.ravel()} == {"3d"}
    assert colormap("tab20", 5).N == 5
    assert colormap("viridis").N == matplotlib.colormaps["viridis"].N


def test_keycap_preview_writes_a_png(surface, tmp_path):
    caps = [build_keycap("A", surface=surface)]
    path = save_keycap_preview(caps, tmp_path / "preview.png")
    with Image.open(path) as image:  # one top and the underside: 2 x 1 panels of 2.0 x 2.1 in
        assert image.format == "PNG"
        assert image.size == (round(4.0 * PNG_DPI), round(2.1 * PNG_DPI))


@pytest.fixture
def svg_backend():
    """The backend set to ``svg`` for the test (read and written raw: reading an unresolved
    backend through ``rcParams[...]`` would itself import pyplot and pick one)."""
    before = matplotlib.rcParams._get("backend")
    matplotlib.rcParams._set("backend", "svg")
    yield
    matplotlib.rcParams._set("backend", before)


def test_saving_leaves_the_backend_and_pyplot_alone(svg_backend, tmp_path):
    had_pyplot = "matplotlib.pyplot" in sys.modules
    save_figure(new_figure()[0], tmp_path / "plain.png")
    tiles = [(f"tile {i}", None, np.full((8, 8), 40 * i, np.uint8)) for i in range(3)]
    save_gallery(tiles, tmp_path / "gallery.png", title="tiles", columns=2)
    save_confusion_matrix(np.array([[3, 1], [0, 2]]), ("A", "B"), tmp_path / "cm.png", "cm")
    assert matplotlib.rcParams._get("backend") == "svg"
    if not had_pyplot:
        assert "matplotlib.pyplot" not in sys.modules
    for name in ("plain.png", "gallery.png", "cm.png"):
        with Image.open(tmp_path / name) as image:
            assert image.format == "PNG"
