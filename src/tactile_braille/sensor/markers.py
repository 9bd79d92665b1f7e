"""Each pin's marker as the reference draws it, tabulated once per sensor for the batched renderer.

The reference (:class:`~tactile_braille.sensor.tactip.TacTip`) fills each
pin's marker as a polygon with OpenCV on a 1/16-pixel grid, blurs the frame
(3 x 3 box) and area-resizes the crop by 4. Blur and resize are linear, so a
marker adds to the observation its pixels filtered by one 6 x 6 kernel at
stride 4 (:data:`FILTER` along each axis). Both the pixels and that footprint
depend only on the pin and on where its centre falls on the 1/16-pixel grid
within a cell, so they are drawn once for every such position:
:func:`marker_tables`.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import cv2
import numpy as np

from tactile_braille.sensor.config import TacTipConfig
from tactile_braille.sensor.tactip import SUBPIXEL_BITS, TacTip

AREA_FACTOR = 4
"""The crop (400 px) is area-resized to the observation (100 px) by this factor."""
FILTER = np.convolve(np.ones(3), np.ones(AREA_FACTOR))
"""One axis of the 3 x 3 box blur then the 4 x 4 area mean: weights 1 2 3 3 2 1 over 6 pixels."""
FILTER_SUM = float(FILTER.sum() ** 2)
"""The 2-D filter's weights add up to 144: a fully lit observation pixel."""


class MarkerTables(NamedTuple):
    """Every pin's marker at every position of its centre on the fill's grid.

    Attributes:
        footprints: uint8 (pins, 64, 64, K, K), in 1/144 of a lit observation
            pixel: what pin ``p`` adds to the observation when its centre lies
            ``i / 16`` pixels (rows) and ``j / 16`` pixels (columns) into its
            4-pixel cell; the patch's first cell is ``margin`` cells before
            the centre's.
        masks: uint8 (pins, 16, 16, M, M): the marker's pixels when its centre
            lies ``i / 16`` and ``j / 16`` pixels past a whole pixel ``V``;
            the mask's first pixel is ``V - half``.
        margin: cells of a footprint before its centre's cell.
        half: pixels of a mask before its centre's pixel.
    """

    footprints: np.ndarray
    masks: np.ndarray
    margin: int
    half: int

    @property
    def cells(self) -> int:
        """Cells per side of a footprint."""
        return self.footprints.shape[-1]


@functools.lru_cache(maxsize=4)
def marker_tables(config: TacTipConfig) -> MarkerTables:
    """Draw every pin's marker of ``config``'s sensor at every 1/16-pixel position (a second or two).

    Markers are filled as the reference fills them, so a centre on the
    1/16-pixel grid gets the reference's pixels exactly (up to the rounding
    of each vertex on its own). Each of the 16 x 16 fractional positions is
    drawn once, every pin in its own tile of one canvas; the 4 x 4 whole-pixel
    shifts within a cell are read off the filtered canvas. Cached per sensor.
    """
    outline = TacTip(config)._pin_outline_px  # (pins, vertices, 2): (column, row) pixels around the centre
    pins = len(outline)
    reach_px = float(np.abs(outline).max()) + 1.0  # a pixel to spare for the fill's rounding
    # A marker covers crop rows v - reach .. v + reach; observation cell i filters rows 4 i - 1 .. 4 i + 4.
    margin = int((reach_px + AREA_FACTOR) // AREA_FACTOR)
    cells = margin + int((reach_px + AREA_FACTOR + 1) // AREA_FACTOR) + 1
    half = int(np.ceil(reach_px))
    sub = 1 << SUBPIXEL_BITS
    shifts = AREA_FACTOR - 1  # whole-pixel positions within a cell past the first
    tile = AREA_FACTOR * cells + len(FILTER) - AREA_FACTOR + shifts
    per_row = int(np.ceil(np.sqrt(pins)))
    tile_origin = np.stack(np.divmod(np.arange(pins), per_row), axis=-1)[:, ::-1] * tile  # (column, row)
    # A centre at tile pixel base + f / 16 stands for one at 4 c + a + f / 16 in the crop (cell c,
    # whole pixel a); its footprint's cell i then filters tile pixels from 4 i + 3 - a on.
    base = AREA_FACTOR * margin + AREA_FACTOR
    starts = (shifts - np.arange(AREA_FACTOR))[:, None] + AREA_FACTOR * np.arange(cells)  # (a, i)
    rows, cols = tile_origin[:, 1, None, None] + starts, tile_origin[:, 0, None, None] + starts
    span = np.arange(2 * half + 2)
    mask_rows = (tile_origin[:, 1, None] + base - half + span)[:, :, None]
    mask_cols = (tile_origin[:, 0, None] + base - half + span)[:, None, :]
    kernel = np.outer(FILTER, FILTER).astype(np.float32)
    canvas = np.zeros((tile * per_row, tile * per_row), np.uint8)
    footprints = np.empty((pins, AREA_FACTOR * sub, AREA_FACTOR * sub, cells, cells), np.uint8)
    masks = np.empty((pins, sub, sub, len(span), len(span)), np.uint8)
    for f_row, f_col in np.ndindex(sub, sub):
        centre = base + np.array([f_col, f_row]) / sub
        polygons = np.rint((tile_origin[:, None, :] + centre + outline) * sub).astype(np.int32)
        canvas[:] = 0
        cv2.fillPoly(canvas, list(polygons), 1, lineType=cv2.LINE_8, shift=SUBPIXEL_BITS)
        masks[:, f_row, f_col] = canvas[mask_rows, mask_cols]
        filtered = cv2.filter2D(canvas, cv2.CV_32F, kernel, anchor=(0, 0), borderType=cv2.BORDER_CONSTANT)
        patches = filtered[rows[:, :, None, :, None], cols[:, None, :, None, :]]  # (pins, a_row, a_col, i, j)
        footprints[:, f_row::sub, f_col::sub] = np.rint(patches).astype(np.uint8)
    return MarkerTables(footprints, masks, margin, half)
