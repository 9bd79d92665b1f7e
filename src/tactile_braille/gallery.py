"""Gallery PNGs of tactile images: what the sensor sees over each key."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from tactile_braille.keyboard.layout import ALL_TASK_KEYS
from tactile_braille.rigs.virtual import VirtualRig
from tactile_braille.sensor.processing import process_frame

GALLERY_DEPTH_MM = 5.0
"""Tap depth of the gallery: 1.5 mm into the key tops, short of actuation."""


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


def save_gallery(
    tiles: list[tuple[str, np.ndarray, np.ndarray]],
    output: str | Path,
    title: str,
    columns: int = 8,
) -> Path:
    """Write tiles as a PNG grid (observation per tile, raw crop for the first
    row) atomically, and return the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not tiles:
        raise ValueError("no tiles to draw")
    rows = -(-len(tiles) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(1.6 * columns, 1.8 * rows), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, (name, _frame, observation) in zip(axes.flat, tiles, strict=False):
        ax.imshow(observation, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
        ax.set_title(name, fontsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    output = Path(output)
    output.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile(dir=output.parent, suffix=".png", delete=False) as handle:
        fig.savefig(handle, format="png", dpi=110)
    plt.close(fig)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(handle.name, 0o666 & ~umask)  # a temporary file is created private
    os.replace(handle.name, output)
    return output
