"""Figures for the PNGs the library writes, without pyplot and without choosing a backend.

Library code must not call ``matplotlib.use`` (it switches the backend of the
user's whole process, e.g. a notebook's inline or a desktop backend) nor go
through ``matplotlib.pyplot`` (its global current-figure state is shared with
the user's own plots and is not thread-safe). A bare ``matplotlib.figure.Figure``
belongs to no figure manager: ``Figure.savefig`` renders a PNG with Agg by
itself, and the figure is freed like any other object once unreferenced. So
these helpers are safe to call from any thread, under any backend, and inside
a user's notebook.

This is a bottom-layer module: it imports nothing from ``tactile_braille``
except :mod:`tactile_braille._io`, and matplotlib only when a figure is made.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from tactile_braille._io import atomic_path

if TYPE_CHECKING:
    import numpy as np
    from matplotlib.colors import Colormap
    from matplotlib.figure import Figure

PNG_DPI = 110
"""Resolution of every PNG the library writes."""


def new_figure(
    rows: int = 1,
    columns: int = 1,
    figsize: tuple[float, float] | None = None,
    gridspec_kw: dict[str, Any] | None = None,
    **subplot_kw: Any,
) -> tuple[Figure, np.ndarray]:
    """A figure and its ``rows x columns`` grid of axes (always a 2-D array).

    ``gridspec_kw`` goes to the grid (e.g. ``height_ratios``), ``subplot_kw`` to each axes (e.g.
    ``projection="3d"``).
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    axes = fig.subplots(rows, columns, squeeze=False, subplot_kw=subplot_kw or None, gridspec_kw=gridspec_kw)
    return fig, axes


def save_figure(fig: Figure, output: str | Path) -> Path:
    """Save a figure as PNG atomically (temporary file, then rename); returns ``output``."""
    with atomic_path(output) as temporary:
        fig.savefig(temporary, format="png", dpi=PNG_DPI)
    return Path(output)


def colormap(name: str, n: int | None = None) -> Colormap:
    """The registered colormap ``name``, resampled to ``n`` colours if given (as ``plt.get_cmap``)."""
    import matplotlib

    cmap = matplotlib.colormaps[name]
    return cmap if n is None else cmap.resampled(n)
