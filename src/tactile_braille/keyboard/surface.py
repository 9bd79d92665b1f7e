"""The keyboard's top surface as a height field, for contact with the sensor.

Heights are in mm relative to the plane of the key tops (0), in the keyboard
frame. Each keycap has a flat rounded-rectangle top, braille relief on top,
and a steep skirt down to the gaps between keys. The field is rasterised once per keyboard at
``resolution_mm`` so that the renderer can sample any sensor pose with one
affine warp.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np

from tactile_braille.keyboard.braille import BrailleGeometry, relief_height_mm
from tactile_braille.keyboard.layout import KeyboardLayout


@dataclass(frozen=True)
class KeycapProfile:
    """Shape of the printed keycaps.

    Attributes:
        top_inset_mm: the flat top is smaller than the key cell by this much
            on each side (a 1 u cap has a 15 mm top).
        top_corner_radius_mm: corner rounding of the flat top.
        skirt_slope: height lost per mm outside the flat top (the skirt).
        gap_depth_mm: depth of the gaps between keycaps below the key tops.
    """

    top_inset_mm: float = 2.0
    top_corner_radius_mm: float = 1.5
    skirt_slope: float = 3.0
    gap_depth_mm: float = 8.0


class KeyboardSurface:
    """Raster of the keyboard's surface height.

    Args:
        layout: key positions.
        braille: relief dimensions.
        profile: keycap skirt and gaps.
        resolution_mm: raster cell size.
        margin_mm: extra border around the keys, so that a sensor over the
            keyboard's edge still samples defined heights.
    """

    def __init__(
        self,
        layout: KeyboardLayout,
        braille: BrailleGeometry | None = None,
        profile: KeycapProfile | None = None,
        resolution_mm: float = 0.1,
        margin_mm: float = 20.0,
    ) -> None:
        if not resolution_mm > 0:
            raise ValueError(f"resolution_mm must be positive, got {resolution_mm!r}")
        self.layout = layout
        self.braille = braille or BrailleGeometry()
        self.profile = profile or KeycapProfile()
        self.resolution_mm = float(resolution_mm)
        x_min, x_max, y_min, y_max = layout.bounds_mm
        self.origin_mm = (x_min - margin_mm, y_min - margin_mm)
        self.shape = (
            int(np.ceil((x_max - x_min + 2 * margin_mm) / resolution_mm)) + 1,
            int(np.ceil((y_max - y_min + 2 * margin_mm) / resolution_mm)) + 1,
        )

    def to_cell(self, x_mm: np.ndarray, y_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fractional raster (row, column) of keyboard-frame points."""
        return (
            (np.asarray(x_mm) - self.origin_mm[0]) / self.resolution_mm,
            (np.asarray(y_mm) - self.origin_mm[1]) / self.resolution_mm,
        )

    @property
    def height_mm(self) -> np.ndarray:
        """The height raster, float32, rows along x and columns along y."""
        return self._rasters[0]

    @property
    def key_index(self) -> np.ndarray:
        """Raster of the key each cell belongs to (its top or skirt); -1 in gaps."""
        return self._rasters[1]

    @cached_property
    def _rasters(self) -> tuple[np.ndarray, np.ndarray]:
        floor = -self.profile.gap_depth_mm
        height = np.full(self.shape, floor, dtype=np.float32)
        key_index = np.full(self.shape, -1, dtype=np.int16)
        half_sizes = (
            np.stack(
                [
                    np.full(len(self.layout), self.layout.pitch_mm / 2),
                    self.layout.widths_u * self.layout.pitch_mm / 2,
                ],
                axis=-1,
            )
            - self.profile.top_inset_mm
        )
        corner = self.profile.top_corner_radius_mm
        reach = self.profile.gap_depth_mm / self.profile.skirt_slope
        for key, (half_x, half_y) in zip(self.layout.keys, half_sizes, strict=True):
            rows, cols = self._window(key.centre_x_mm, key.centre_y_mm, half_x + reach, half_y + reach)
            local_x = self.origin_mm[0] + rows[:, None] * self.resolution_mm - key.centre_x_mm
            local_y = self.origin_mm[1] + cols[None, :] * self.resolution_mm - key.centre_y_mm
            # Distance outside the rounded-rectangle top (0 inside it).
            r = min(corner, half_x, half_y)
            qx = np.abs(local_x) - (half_x - r)
            qy = np.abs(local_y) - (half_y - r)
            outside = np.maximum(np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0)) - r, 0.0)
            cap = np.maximum(-self.profile.skirt_slope * outside, floor)
            cap = cap + relief_height_mm(key.name, local_x, local_y, self.braille) * (outside == 0)
            window = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))
            higher = cap > height[window]
            height[window][higher] = cap[higher]
            key_index[window][higher & (cap > floor)] = key.index
        return height, key_index

    def local_heights_mm(
        self,
        raster_from_local: np.ndarray,
        grid_shape: tuple[int, int],
        key_descent_mm: dict[int, float] | None = None,
    ) -> np.ndarray:
        """Heights on a rotated, shifted grid (one affine warp of the raster).

        Args:
            raster_from_local: 2x3 affine map from grid (column, row) to
                raster (column, row), as ``cv2.warpAffine`` takes it with
                ``WARP_INVERSE_MAP``.
            grid_shape: (rows, columns) of the grid.
            key_descent_mm: keys pushed down (key index -> mm), lowered in
                the returned heights.
        """
        rows, cols = grid_shape
        heights = cv2.warpAffine(
            self.height_mm,
            raster_from_local,
            (cols, rows),
            flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=-self.profile.gap_depth_mm,
        )
        if key_descent_mm:
            keys = cv2.warpAffine(
                self.key_index,
                raster_from_local,
                (cols, rows),
                flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
                borderMode=cv2.BORDER_CONSTANT,
                borderValue=-1,
            )
            descent = np.zeros(len(self.layout) + 1, dtype=np.float32)  # last entry: gaps
            for index, mm in key_descent_mm.items():
                descent[index] = mm
            heights -= descent[keys]
        return heights

    def sample(self, x_mm: np.ndarray, y_mm: np.ndarray) -> np.ndarray:
        """Heights at keyboard-frame points (bilinear; the floor off the raster)."""
        row, col = self.to_cell(x_mm, y_mm)
        field = self.height_mm
        r0 = np.clip(np.floor(row).astype(int), 0, self.shape[0] - 2)
        c0 = np.clip(np.floor(col).astype(int), 0, self.shape[1] - 2)
        fr = np.clip(row - r0, 0.0, 1.0)
        fc = np.clip(col - c0, 0.0, 1.0)
        top = field[r0, c0] * (1 - fc) + field[r0, c0 + 1] * fc
        bottom = field[r0 + 1, c0] * (1 - fc) + field[r0 + 1, c0 + 1] * fc
        return top * (1 - fr) + bottom * fr

    def _window(self, cx: float, cy: float, half_x: float, half_y: float):
        r_lo, c_lo = self.to_cell(cx - half_x, cy - half_y)
        r_hi, c_hi = self.to_cell(cx + half_x, cy + half_y)
        rows = np.arange(max(int(r_lo), 0), min(int(np.ceil(r_hi)) + 1, self.shape[0]))
        cols = np.arange(max(int(c_lo), 0), min(int(np.ceil(c_hi)) + 1, self.shape[1]))
        return rows, cols
