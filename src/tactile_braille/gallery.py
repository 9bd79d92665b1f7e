"""Gallery PNGs: what the sensor sees over each key, and what a dataset holds."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tactile_braille._figures import colormap, new_figure, save_figure
from tactile_braille.datasets.store import TactileDataset
from tactile_braille.keyboard.layout import ALL_TASK_KEYS, NONE_KEY
from tactile_braille.rigs.virtual import VirtualRig
from tactile_braille.sensor.processing import process_frame

GALLERY_DEPTH_MM = 4.5
"""Tap depth of the gallery: the middle of the paper's reading taps (5 mm + U[-1, 0]),
1 mm into the key tops and short of every key's actuation (the earliest switches,
O and Q, register from 4.85 mm at their centres)."""


def live_gallery_tiles(
    rig: VirtualRig, keys: tuple[str, ...] = ALL_TASK_KEYS, depth_mm: float = GALLERY_DEPTH_MM
) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """Taps for the gallery: ``(title, raw frame, observation)`` per tile.

    One tap at the centre of every key in ``keys``, then off-centre taps on A,
    a tap between keys, a deep tap that presses a key, and a tap with no
    contact.
    """
    poses: list[tuple[str, float, float, float]] = []
    for key in keys:
        x, y = rig.layout.centre_mm(key)
        poses.append((key, x, y, depth_mm))
    ax, ay = rig.layout.centre_mm("A")
    gx, gy = rig.layout.centre_mm("G")
    poses += [
        ("A +4 mm x", ax + 4.0, ay, depth_mm),
        ("A +4 mm y", ax, ay + 4.0, depth_mm),
        ("G|H gap", gx, gy - 9.5, depth_mm),
        ("A pressed 8 mm", ax, ay, 8.0),
        ("no contact", ax, ay, 0.0),
    ]
    tiles = []
    for title, x, y, depth in poses:
        sample = rig.tap(x, y, depth)
        if sample.pressed_key is not None:
            title = f"{title} -> {sample.pressed_key}"
        tiles.append((title, sample.frame, process_frame(sample.frame, rig.sensor.config.processing)))
    return tiles


def draw_activation_map(
    axes,
    x_mm: np.ndarray,
    y_mm: np.ndarray,
    depth_mm: np.ndarray,
    pressed: np.ndarray,
    keys: tuple[str, ...],
    row_title: str,
) -> None:
    """Draw which key each tap of a grid actuated, one axis per depth.

    Args:
        axes: a sequence of matplotlib axes, at least one per distinct depth.
        x_mm, y_mm, depth_mm: the taps (a regular grid in x and y).
        pressed: key name per tap (``"NONE"`` is left blank).
        keys: the keys to colour, in colour order.
        row_title: label of the row.
    """
    code = {key: i + 1 for i, key in enumerate(keys)}
    xs, ys = np.unique(x_mm), np.unique(y_mm)
    cmap = colormap("tab20", len(keys) + 1)
    for column, depth in enumerate(np.unique(depth_mm)):
        at_depth = depth_mm == depth
        grid = np.full((len(xs), len(ys)), np.nan)
        rows = np.searchsorted(xs, x_mm[at_depth])
        cols = np.searchsorted(ys, y_mm[at_depth])
        grid[rows, cols] = [code.get(key, np.nan) for key in pressed[at_depth]]
        ax = axes[column]
        ax.axis("on")
        # Columns run along -y so that the keyboard reads left to right.
        ax.imshow(grid[:, ::-1], cmap=cmap, vmin=0, vmax=len(keys), interpolation="nearest", aspect="auto")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"depth {depth:g} mm", fontsize=7)
        if column == 0:
            ax.set_ylabel(row_title, fontsize=7)


def dataset_figure(dataset: TactileDataset, max_tiles: int = 32):
    """A figure of a dataset: one image per label, and for grids the activation map at each depth."""
    labels = dataset.label_names()
    shown = [name for name in dict.fromkeys(labels)][:max_tiles]
    is_grid = dataset.metadata.procedure.get("procedure") == "grid"
    depths = np.unique(dataset.poses[:, 2]) if is_grid else np.array([])
    columns = max(8, len(depths))
    tile_rows = -(-len(shown) // columns)
    rows = tile_rows + (1 if is_grid else 0)
    fig, axes = new_figure(rows, columns, figsize=(1.5 * columns, 1.7 * rows))
    for ax in axes.flat:
        ax.axis("off")
    for ax, name in zip(axes[:tile_rows].flat, shown, strict=False):
        index = int(np.flatnonzero(labels == name)[0])
        ax.imshow(dataset.observations[index], cmap="gray", vmin=0, vmax=255, interpolation="nearest")
        ax.set_title(name, fontsize=7)
    if is_grid:
        pressed = dataset.pressed_names()
        keys = tuple(k for k in dict.fromkeys(pressed) if k != NONE_KEY)
        draw_activation_map(
            axes[tile_rows], dataset.poses[:, 0], dataset.poses[:, 1], dataset.poses[:, 2], pressed, keys,
            "pressed key",
        )  # fmt: skip
    fig.suptitle(f"{dataset.path.name}: {len(dataset)} taps ({dataset.metadata.procedure.get('procedure')})")
    fig.tight_layout()
    return fig


def save_gallery(
    tiles: list[tuple[str, np.ndarray, np.ndarray]],
    output: str | Path,
    title: str,
    columns: int = 8,
) -> Path:
    """Write tiles as a PNG grid (the processed observation of each tile) atomically."""
    if not tiles:
        raise ValueError("no tiles to draw")
    rows = -(-len(tiles) // columns)
    fig, axes = new_figure(rows, columns, figsize=(1.6 * columns, 1.8 * rows))
    for ax in axes.flat:
        ax.axis("off")
    for ax, (name, _frame, observation) in zip(axes.flat, tiles, strict=False):
        ax.imshow(observation, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
        ax.set_title(name, fontsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, output)
