"""The TacTip renderer for a batch of taps at once, in torch (CPU or CUDA).

The same contact -> skin -> pin -> frame -> processing model as
:class:`~tactile_braille.sensor.tactip.TacTip`, the reference, which renders
one tap at a time with OpenCV; this one returns the processed ``(B, 100, 100)``
observations of ``B`` taps:

1. **Contact.** The surface raster is sampled on every tap's contact grid
   (bilinear, as the reference's affine warp); pressed keys are lowered by
   their descent through the key-index raster (nearest).
2. **Skin.** The Gaussian blur of the indentation is two matrix products with
   the reference's own kernel (zero border), read at the pins' cells.
3. **Pins.** As the reference: tilt by the skin's slope, push towards the axis.
4. **Frame and processing, fused.** Instead of drawing a 640 x 480 frame, each
   pin adds its tabulated footprint (:mod:`tactile_braille.sensor.markers`)
   to the resized image, scaled by its contrast over the background. Where
   markers overlap, the reference's fill of all of them at once leaves some
   doubly covered pixels dark: those markers' pixels are counted on a
   frame-sized canvas and the dark ones taken out. The background, the
   lighting gain and the pixel noise (4 x 4 block means of the reference's
   own noise bank) add in the same domain; the image is rounded and
   thresholded as OpenCV's adaptive mean threshold does.

Stages 1-3 and the threshold run either as the reference's own OpenCV calls,
one tap at a time (``kernels="opencv"``: exact, and the faster on a CPU), or
as batched tensor operations on any device (``kernels="torch"``).

What is approximate: a marker's vertices are rounded with its centre rather
than each on its own; how many of the doubly covered pixels the reference
leaves lit is a measured share, not OpenCV's scan-line rule; the background
is not rounded per pixel, the blurred frame not rounded to grey levels, the
noise not saturated (and the reference blurs only the dome's bounding box,
which holds the crop). On random taps over every key set the processed
images equal the reference's in 99.4 % (331-pin tip) and 99.9 % (127-pin tip)
of their pixels on average, every image in at least 98 %
(``tests/sensor/test_batched.py``, ``benchmarks/render.py``).
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np
import torch
import torch.nn.functional as F

from tactile_braille.keyboard.surface import KeyboardSurface
from tactile_braille.sensor.markers import AREA_FACTOR, FILTER, FILTER_SUM, SUBPIXEL_BITS, marker_tables
from tactile_braille.sensor.processing import threshold_image
from tactile_braille.sensor.tactip import NOISE_BANK_MARGIN_PX, FrameNuisance, TacTip

EVEN_COVER_LIT = 0.46
"""Of the pixels that overlapping markers cover an even number of times, the share the reference's
fill of all markers at once leaves lit (measured with OpenCV on 400 random piles of 2-5 markers of the
331-pin tip; odd counts are always lit). Not a parity rule: each polygon's edge pixels are drawn
whatever the others do."""
KERNELS = ("opencv", "torch")


class TapNuisances(NamedTuple):
    """The nuisances of a batch of frames, as arrays over the batch (see :class:`FrameNuisance`)."""

    dx_mm: np.ndarray
    dy_mm: np.ndarray
    dyaw_deg: np.ndarray
    gain: np.ndarray
    noise_offset_px: np.ndarray | None
    """(B, 2) rows and columns into the noise bank, or None for no pixel noise."""

    @classmethod
    def stack(cls, frames: list[FrameNuisance]) -> TapNuisances:
        """The batch of ``frames`` (all with pixel noise, or all without)."""
        noisy = {frame.noise_offset_px is not None for frame in frames}
        if len(noisy) > 1:
            raise ValueError("a batch's frames must all have pixel noise or all have none")
        columns = list(zip(*frames, strict=True)) if frames else [()] * 5
        offsets = np.array(columns[4], dtype=np.int64).reshape(-1, 2) if noisy == {True} else None
        return cls(*(np.asarray(c, dtype=np.float64) for c in columns[:4]), offsets)


class BatchedTacTip:
    """A TacTip that renders and processes many taps on one surface at once.

    Args:
        sensor: the reference sensor (geometry, camera, processing, noise bank).
        surface: the keyboard's height field.
        device: torch device of the tensors (``"cpu"``, ``"cuda"``).
        kernels: where contact, skin and threshold run: ``"opencv"`` (the
            reference's calls, one tap at a time; CPU only, its default) or
            ``"torch"`` (batched; the default on other devices).

    Example:
        >>> from tactile_braille.keyboard.layout import KeyboardLayout
        >>> layout = KeyboardLayout()
        >>> renderer = BatchedTacTip(TacTip(), KeyboardSurface(layout))
        >>> x, y = layout.centre_mm("A")
        >>> renderer.observe(np.array([x, x]), np.array([y, y + 2.0]), np.array([-1.5, -1.5])).shape
        torch.Size([2, 100, 100])
    """

    def __init__(
        self,
        sensor: TacTip,
        surface: KeyboardSurface,
        device: str | torch.device = "cpu",
        kernels: str | None = None,
    ) -> None:
        processing = sensor.config.processing
        x0, y0, x1, y1 = processing.crop_px
        if (x1 - x0, y1 - y0) != (AREA_FACTOR * processing.size_px,) * 2:
            raise ValueError(
                f"the batched renderer resizes the crop by exactly {AREA_FACTOR}: crop {processing.crop_px} "
                f"to {processing.size_px} px is not that"
            )
        width, height = sensor.config.camera_px
        if x0 < 1 or y0 < 1 or x1 >= width or y1 >= height:
            raise ValueError(
                f"the batched renderer blurs a pixel past the crop: crop {processing.crop_px} must lie at "
                f"least a pixel inside the {width}x{height} frame"
            )
        self.device = torch.device(device)
        self.kernels = kernels or ("opencv" if self.device.type == "cpu" else "torch")
        if self.kernels not in KERNELS:
            raise ValueError(f"kernels must be one of {KERNELS}, got {kernels!r}")
        if self.kernels == "opencv" and self.device.type != "cpu":
            raise ValueError(f"kernels='opencv' runs on the CPU; on {self.device} use kernels='torch'")
        self.sensor, self.surface = sensor, surface
        # Taps per pass: small passes keep a CPU's intermediates in its caches.
        self.chunk = 64 if self.device.type == "cpu" else 1024
        tensor = self._tensor
        self._height = F.pad(tensor(surface.height_mm + surface.profile.gap_depth_mm), (1, 1, 1, 1))
        self._key_index = tensor(surface.key_index, torch.long)
        self._dome = tensor(sensor._dome_height_mm)
        rows, cols = sensor._pin_grid_index
        grid = sensor.grid_px
        steps = np.array([0, grid, -grid, -1, 1])  # each pin's cell, then row + 1, row - 1, column - 1, + 1
        self._pin_cells = tensor((steps[:, None] + rows * grid + cols).reshape(-1), torch.long)
        self._pin_rest = tensor(sensor.pin_rest_mm)
        towards_axis, sin_theta = sensor._pin_inward
        self._towards_axis, self._sin_theta = tensor(towards_axis), tensor(sin_theta)
        self._blur = tensor(_skin_blur_matrix(sensor))
        self._tables = marker_tables(sensor.config)
        self._footprints = tensor(self._tables.footprints, torch.uint8).reshape(-1, self._tables.cells**2)
        self._masks = tensor(self._tables.masks, torch.uint8).reshape(-1, self._tables.masks.shape[-1] ** 2)
        self._background_frame = tensor(sensor._background)
        self._background = tensor(_filtered_crop(sensor._background.astype(np.float64), processing.crop_px))
        brighter, darker = sensor._noise_bank
        box = (AREA_FACTOR, AREA_FACTOR)
        noise = brighter.astype(np.float64) - darker
        self._noise = tensor(cv2.boxFilter(noise, -1, box, anchor=(0, 0), borderType=cv2.BORDER_CONSTANT))
        # Two markers can only share a pixel when their centres are closer than twice a marker's reach
        # (its outline's, and a pixel more for the fill's rounding).
        self._touch_px = 2 * (float(np.linalg.norm(sensor._pin_outline_px, axis=-1).max()) + 1.0)

    def _tensor(self, array: np.ndarray, dtype: torch.dtype = torch.float32) -> torch.Tensor:
        return torch.as_tensor(np.ascontiguousarray(array)).to(device=self.device, dtype=dtype)

    # ------------------------------------------------------------ rendering
    def observe(
        self,
        x_mm: np.ndarray,
        y_mm: np.ndarray,
        apex_height_mm: np.ndarray,
        yaw_deg: np.ndarray | None = None,
        key_descent_mm: np.ndarray | None = None,
        nuisances: TapNuisances | None = None,
    ) -> torch.Tensor:
        """The processed observations of a batch of taps, as the reference's ``observe`` makes each.

        Args:
            x_mm, y_mm: (B,) positions of the dome's apex in the keyboard frame.
            apex_height_mm: (B,) heights of the apex above the key tops.
            yaw_deg: (B,) rotations of the sensor (default 0).
            key_descent_mm: (B, n_keys) how far each tap pushes each key
                down (None: no key moves).
            nuisances: each frame's nuisances (None: noiseless frames).

        Returns:
            uint8 tensor (B, size, size) of 0 and 255 on the renderer's device.

        Raises:
            ValueError: an argument's shape or values are wrong (nothing is rendered).
        """
        x = np.asarray(x_mm, np.float64)
        if x.ndim != 1:
            raise ValueError(f"x_mm must be a (B,) batch of positions, got shape {x.shape}")
        batch = len(x)
        y, apex = _batch_of(y_mm, batch, "y_mm"), _batch_of(apex_height_mm, batch, "apex_height_mm")
        yaw = np.zeros(batch) if yaw_deg is None else _batch_of(yaw_deg, batch, "yaw_deg")
        descent = None if key_descent_mm is None else np.asarray(key_descent_mm, np.float32)
        if descent is not None and descent.shape != (batch, len(self.surface.layout)):
            shape = (batch, len(self.surface.layout))
            raise ValueError(f"key_descent_mm must have shape (B, n_keys) = {shape}, got {descent.shape}")
        gain, offsets = np.ones(batch), None
        if nuisances is not None:
            x, y = (
                x + _batch_of(nuisances.dx_mm, batch, "dx_mm"),
                y + _batch_of(nuisances.dy_mm, batch, "dy_mm"),
            )
            yaw = yaw + _batch_of(nuisances.dyaw_deg, batch, "dyaw_deg")
            gain = _batch_of(nuisances.gain, batch, "gain")
            offsets = nuisances.noise_offset_px
            if offsets is not None:
                offsets = np.asarray(offsets, np.int64)
                if offsets.shape != (batch, 2) or ((offsets < 0) | (offsets >= NOISE_BANK_MARGIN_PX)).any():
                    raise ValueError(
                        f"noise_offset_px must be (B, 2) in [0, {NOISE_BANK_MARGIN_PX}) (B = {batch})"
                    )
        if not np.isfinite(np.concatenate([x, y, apex, yaw, gain])).all():
            raise ValueError("tap poses and gains must be finite")
        size = self.sensor.config.processing.size_px
        out = torch.empty((batch, size, size), dtype=torch.uint8, device=self.device)
        for start in range(0, batch, self.chunk):
            part = slice(start, start + self.chunk)
            tap_descent = None if descent is None else descent[part]
            tap_offsets = None if offsets is None else offsets[part]
            out[part] = self._observe(
                x[part], y[part], apex[part], yaw[part], tap_descent, gain[part], tap_offsets
            )
        return out

    def _observe(self, x, y, apex, yaw, descent, gain, offsets) -> torch.Tensor:
        if self.kernels == "opencv":
            descents = [None] * len(x) if descent is None else descent
            taps = zip(x, y, apex, yaw, descents, strict=True)
            positions = self._tensor(np.stack([self._pin_positions_opencv(*tap) for tap in taps]))
        else:
            positions = self._pin_positions(self._indentation(x, y, apex, yaw, descent))
        image = self._image(self._centres_px(positions), self._tensor(gain), offsets)
        grey = torch.clamp(torch.floor(image + 0.5), 0, 255)
        if self.kernels == "opencv":
            processing = self.sensor.config.processing
            grey = grey.to(torch.uint8).numpy()
            return torch.from_numpy(np.stack([threshold_image(g, processing) for g in grey]))
        return self._threshold(grey)

    def _pin_positions_opencv(self, x, y, apex, yaw, descent) -> np.ndarray:
        """One tap's pin positions (pins, 2) in mm, by the reference's own contact and skin stages."""
        sensor = self.sensor
        pushed = None if descent is None else {int(k): float(descent[k]) for k in np.flatnonzero(descent > 0)}
        indentation = sensor.indentation_mm(self.surface, x, y, apex, yaw, pushed)
        return sensor.pin_rest_mm + sensor.pin_displacement_mm(indentation)

    def _indentation(self, x, y, apex, yaw, descent) -> torch.Tensor:
        """(B, G, G) overlap of the surface with the dome on each tap's contact grid."""
        sensor, surface = self.sensor, self.surface
        grid = sensor.grid_px
        cells = (np.arange(grid) - (grid - 1) / 2) * sensor.grid_spacing_mm / surface.resolution_mm
        local_x, local_y = self._tensor(cells)[None, :, None], self._tensor(cells)[None, None, :]
        yaw_rad = np.radians(yaw)
        cos, sin = self._tensor(np.cos(yaw_rad))[:, None, None], self._tensor(np.sin(yaw_rad))[:, None, None]
        row0, col0 = surface.to_cell(x, y)
        # Grid rows run along the keyboard's x, columns along its y, turned by the yaw.
        rows = self._tensor(row0)[:, None, None] + cos * local_x - sin * local_y
        cols = self._tensor(col0)[:, None, None] + sin * local_x + cos * local_y
        heights = _bilinear(self._height, rows, cols) - surface.profile.gap_depth_mm
        if descent is not None and descent.any():
            keys = _nearest(self._key_index, rows, cols).reshape(len(x), -1)
            table = self._tensor(np.concatenate([descent, np.zeros((len(x), 1), np.float32)], axis=1))
            keys = torch.where(keys < 0, len(surface.layout), keys)  # gaps: the table's last column
            heights = heights - torch.gather(table, 1, keys).reshape(-1, grid, grid)
        return torch.clamp(heights - (self._dome + self._tensor(apex)[:, None, None]), min=0.0)

    def _pin_positions(self, indentation: torch.Tensor) -> torch.Tensor:
        """(B, pins, 2) pin positions on the sensor plane in mm, from each tap's indentation."""
        config, batch = self.sensor.config, len(indentation)
        skin = self._blur @ indentation @ self._blur.T
        at_pins = skin.reshape(batch, -1).index_select(1, self._pin_cells).reshape(batch, 5, -1)
        centre, below, above, left, right = at_pins.unbind(1)
        tilt = (-config.pin_length_mm / (2 * self.sensor.grid_spacing_mm)) * torch.stack(
            [below - above, right - left], dim=-1
        )
        return self._pin_rest + tilt + (centre * self._sin_theta)[..., None] * self._towards_axis

    def _centres_px(self, positions: torch.Tensor) -> torch.Tensor:
        """(B, pins, 2) pin centres in the crop, (row, column) in camera pixels."""
        config = self.sensor.config
        cx, cy = config.image_centre_px
        x0, y0, _, _ = config.processing.crop_px
        scale = config.px_per_mm
        # Image rows run along the sensor's x, columns along its -y.
        return torch.stack([cy - y0 + scale * positions[..., 0], cx - x0 - scale * positions[..., 1]], dim=-1)

    # ---------------------------------------------------- frame, processing
    def _image(
        self, centres: torch.Tensor, gain: torch.Tensor, noise_offsets: np.ndarray | None
    ) -> torch.Tensor:
        """(B, size, size) resized grey image before rounding: background, pins and noise."""
        config = self.sensor.config
        size = config.processing.size_px
        batch, pins = centres.shape[:2]
        tables, phases = self._tables, AREA_FACTOR << SUBPIXEL_BITS
        # Centres on the fill's 1/16-pixel grid: their cell, and where in it.
        sixteenths = torch.round(centres * (1 << SUBPIXEL_BITS)).long()
        cell, phase = (
            torch.div(sixteenths, phases, rounding_mode="floor"),
            torch.remainder(sixteenths, phases),
        )
        pin = torch.arange(pins, device=self.device)
        rows = (pin * phases + phase[..., 0]) * phases + phase[..., 1]
        footprints = self._footprints.index_select(0, rows.reshape(-1)).reshape(batch, pins, -1).float()
        level = torch.floor(torch.clamp(config.pin_level * gain, max=255.0))
        under = _take(self._background_frame.reshape(-1), self._frame_index(torch.round(centres).long()))
        contrast = (level[:, None] - under * gain[:, None]) / FILTER_SUM
        canvas = _Canvas(batch, size, tables.cells, self.device)
        canvas.add(cell - tables.margin, footprints * contrast[..., None], tables.cells)
        self._darken_overlaps(canvas, centres, level, gain)
        image = canvas.image() + self._background * gain[:, None, None]
        if noise_offsets is not None:
            image = image + self._noise_at(noise_offsets)
        return image

    def _frame_index(self, crop_px: torch.Tensor) -> torch.Tensor:
        """Flat index into the camera frame of (..., 2) crop pixels (row, column), clamped to the frame."""
        x0, y0, _, _ = self.sensor.config.processing.crop_px
        height, width = self._background_frame.shape
        rows = (crop_px[..., 0] + y0).clamp(0, height - 1)
        return rows * width + (crop_px[..., 1] + x0).clamp(0, width - 1)

    def _darken_overlaps(
        self, canvas: _Canvas, centres: torch.Tensor, level: torch.Tensor, gain: torch.Tensor
    ):
        """Take out what overlapping markers leave dark in the reference's frame.

        The footprints counted each marker whole. The pixels two markers
        share are found from their masks, pair by pair among the pairs close
        enough; a pixel that ``n >= 2`` markers cover loses ``n - lit(n)``
        times its contrast (``lit``: 1 for odd ``n``, else
        :data:`EVEN_COVER_LIT`), spread over the observation cells its filter
        feeds.
        """
        tables, sub, pins = self._tables, 1 << SUBPIXEL_BITS, centres.shape[1]
        sixteenths = torch.round(centres * sub).long()
        whole, fraction = torch.div(sixteenths, sub, rounding_mode="floor"), torch.remainder(sixteenths, sub)
        mask_rows = (torch.arange(pins, device=self.device) * sub + fraction[..., 0]) * sub + fraction[..., 1]
        taps, p, q = torch.nonzero(
            torch.triu(torch.cdist(centres, centres) < self._touch_px, 1), as_tuple=True
        )
        side = tables.masks.shape[-1]
        # Which close pairs share a pixel: q's mask read in p's frame.
        mask_p = self._masks.index_select(0, mask_rows[taps, p])
        mask_q = self._masks.index_select(0, mask_rows[taps, q])
        shift = whole[taps, q] - whole[taps, p]
        span = torch.arange(side, device=self.device)
        rows = span[None, :, None] - shift[:, 0, None, None]
        cols = span[None, None, :] - shift[:, 1, None, None]
        valid = ((rows >= 0) & (rows < side) & (cols >= 0) & (cols < side)).reshape(len(taps), -1)
        index = (rows.clamp(0, side - 1) * side + cols.clamp(0, side - 1)).reshape(len(taps), -1)
        overlap = mask_p.bool() & torch.gather(mask_q, 1, index).bool() & valid
        pair, pixel = torch.nonzero(overlap, as_tuple=True)
        if len(pair) == 0:
            return
        # Every pixel two markers share, once per pair that shares it: a pixel that n markers cover
        # is listed n (n - 1) / 2 times. Canvas pixel r is crop pixel r - pad.
        pad = tables.half + AREA_FACTOR * tables.cells
        side_px = AREA_FACTOR * self.sensor.config.processing.size_px + 2 * pad
        origin = whole[taps[pair], p[pair]] - tables.half + pad
        row = origin[:, 0] + torch.div(pixel, side, rounding_mode="floor")
        col = origin[:, 1] + pixel % side
        on_canvas = (row >= 0) & (row < side_px) & (col >= 0) & (col < side_px)
        keys = (taps[pair] * side_px + row) * side_px + col
        keys, listed = torch.unique(keys[on_canvas], return_counts=True)
        count = torch.round((1 + torch.sqrt(1 + 8 * listed.double())) / 2).float()
        odd = torch.remainder(count, 2)
        lost = count - (odd + (1 - odd) * EVEN_COVER_LIT)
        owner = torch.div(keys, side_px * side_px, rounding_mode="floor")
        row = torch.div(keys, side_px, rounding_mode="floor") % side_px - pad
        col = keys % side_px - pad
        under = _take(self._background_frame.reshape(-1), self._frame_index(torch.stack([row, col], dim=-1)))
        dark = lost * (level[owner] - under * gain[owner])
        for row_cell, row_weight in _cells_fed(row):
            for col_cell, col_weight in _cells_fed(col):
                canvas.add_cells(owner, row_cell, col_cell, -dark * row_weight * col_weight / FILTER_SUM)

    def _noise_at(self, offsets: np.ndarray) -> torch.Tensor:
        """(B, size, size) each frame's pixel noise, area-resized: its window into the block means."""
        processing = self.sensor.config.processing
        x0, y0, _, _ = processing.crop_px
        width = self._noise.shape[1]
        steps = torch.arange(processing.size_px, device=self.device) * AREA_FACTOR
        base = (steps[:, None] + y0) * width + steps[None, :] + x0
        offsets = self._tensor(offsets, torch.long)
        return _take(
            self._noise.reshape(-1), base[None] + (offsets[:, 0] * width + offsets[:, 1])[:, None, None]
        )

    def _threshold(self, grey: torch.Tensor) -> torch.Tensor:
        """OpenCV's adaptive mean threshold of rounded grey levels (binary, replicated border)."""
        processing = self.sensor.config.processing
        block, size = processing.threshold_block_px, grey.shape[-1]
        padded = F.pad(grey[:, None], (block // 2 + 1, block // 2) * 2, mode="replicate")[:, 0]
        padded[:, 0, :] = 0
        padded[:, :, 0] = 0
        # Box sums from an integral image (exact in float64 for grey levels).
        integral = padded.double().cumsum_(1).cumsum_(2)
        sums = (
            integral[:, block:, block:]
            - integral[:, :size, block:]
            - integral[:, block:, :size]
            + integral[:, :size, :size]
        )
        mean = torch.round(sums / block**2).to(grey.dtype)
        # OpenCV keeps src - mean > -ceil(C) for THRESH_BINARY.
        above = grey - mean > -np.ceil(processing.threshold_constant)
        return above.to(torch.uint8) * 255


class _Canvas:
    """A batch of ``size``-pixel square images padded by ``pad`` on every side, that patches add into."""

    def __init__(self, batch: int, size: int, pad: int, device: torch.device) -> None:
        self.batch, self.size, self.pad = batch, size, pad
        self.side = size + 2 * pad
        self.flat = torch.zeros(batch * self.side * self.side, device=device)

    def add(self, first: torch.Tensor, patches: torch.Tensor, cells: int, images: torch.Tensor | None = None):
        """Add square ``patches`` (..., cells * cells) whose first pixel is at ``first`` (..., 2).

        Without ``images`` the leading axis of ``first`` is the batch; with
        it, ``images`` (N,) names each patch's image. Patches that reach past
        the padding are dropped.
        """
        device = patches.device
        first = first + self.pad
        inside = ((first >= 0) & (first <= self.side - cells)).all(dim=-1)
        patches = patches * inside[..., None]
        first = first.clamp(0, self.side - cells)
        span = torch.arange(cells, device=device)
        index = (first[..., 0, None, None] + span[:, None]) * self.side + first[..., 1, None, None] + span
        if images is None:
            images = torch.arange(self.batch, device=device).reshape(-1, *([1] * (first.dim() - 2)))
        index = index + (images * self.side * self.side)[..., None, None]
        self.flat.index_add_(0, index.reshape(-1), patches.reshape(-1))

    def add_cells(self, images: torch.Tensor, rows: torch.Tensor, cols: torch.Tensor, values: torch.Tensor):
        """Add ``values`` at single pixels (images, rows, columns); those off the canvas are dropped."""
        rows, cols = rows + self.pad, cols + self.pad
        inside = (rows >= 0) & (rows < self.side) & (cols >= 0) & (cols < self.side)
        index = (images * self.side + rows) * self.side + cols
        self.flat.index_add_(0, index[inside], values[inside])

    def image(self) -> torch.Tensor:
        pad, size = self.pad, self.size
        return self.flat.reshape(self.batch, self.side, self.side)[:, pad : pad + size, pad : pad + size]


def _cells_fed(pixel: torch.Tensor) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """The two observation cells a crop pixel row (or column) feeds through the 6-pixel filter, with weights.

    Pixel ``4 i + j - 1`` feeds cell ``i`` with weight ``FILTER[j]`` and, for
    ``j < 2``, cell ``i - 1`` with ``FILTER[j + 4]`` (weight 0 otherwise).
    """
    weights = torch.as_tensor(FILTER, dtype=torch.float32, device=pixel.device)
    cell = torch.div(pixel + 1, AREA_FACTOR, rounding_mode="floor")
    j = torch.remainder(pixel + 1, AREA_FACTOR)
    spill = torch.where(
        j + AREA_FACTOR < len(FILTER), weights[(j + AREA_FACTOR).clamp(max=len(FILTER) - 1)], 0.0
    )
    return [(cell, weights[j]), (cell - 1, spill)]


def _skin_blur_matrix(sensor: TacTip) -> np.ndarray:
    """The reference's skin blur along one axis of the contact grid as a matrix (its kernel, zero border)."""
    sigma_px = sensor.config.skin_smoothing_mm / sensor.grid_spacing_mm
    size = int(np.rint(sigma_px * 4 * 2 + 1)) | 1  # OpenCV's own kernel size for a float image
    kernel = cv2.getGaussianKernel(size, sigma_px, cv2.CV_64F)[:, 0]
    offsets = np.arange(sensor.grid_px)[None, :] - np.arange(sensor.grid_px)[:, None] + size // 2
    return np.where((offsets >= 0) & (offsets < size), kernel[np.clip(offsets, 0, size - 1)], 0.0)


def _filtered_crop(frame: np.ndarray, crop_px: tuple[int, int, int, int]) -> np.ndarray:
    """A frame's crop blurred and area-resized as the reference does, in float (not rounded)."""
    x0, y0, x1, _ = crop_px
    size = (x1 - x0) // AREA_FACTOR
    view, span = frame[y0 - 1 :, x0 - 1 :], AREA_FACTOR * size
    out = np.zeros((size, size))
    for a, b in np.ndindex(len(FILTER), len(FILTER)):
        out += FILTER[a] * FILTER[b] * view[a : a + span : AREA_FACTOR, b : b + span : AREA_FACTOR]
    return out / FILTER_SUM


def _batch_of(values, batch: int, name: str) -> np.ndarray:
    array = np.asarray(values, np.float64)
    if array.shape != (batch,):
        raise ValueError(f"{name} must have shape ({batch},) like x_mm, got {array.shape}")
    return array


def _take(flat: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """``flat[index]`` through ``index_select`` (several times faster than indexing on a CPU)."""
    return flat.index_select(0, index.reshape(-1)).reshape(index.shape)


def _bilinear(padded: torch.Tensor, rows: torch.Tensor, cols: torch.Tensor) -> torch.Tensor:
    """A raster at fractional cells, bilinear, 0 off it (``padded``: the raster in a ring of zeros)."""
    height, width = padded.shape[0] - 2, padded.shape[1] - 2
    r0, c0 = torch.floor(rows), torch.floor(cols)
    fr, fc = rows - r0, cols - c0
    top = (r0.long() + 1).clamp_(0, height) * (width + 2) + (c0.long() + 1).clamp_(0, width)
    flat = padded.reshape(-1)
    upper = _take(flat, top) * (1 - fc) + _take(flat, top + 1) * fc
    lower = _take(flat, top + width + 2) * (1 - fc) + _take(flat, top + width + 3) * fc
    return upper * (1 - fr) + lower * fr


def _nearest(raster: torch.Tensor, rows: torch.Tensor, cols: torch.Tensor) -> torch.Tensor:
    """An integer raster at the nearest cells; -1 off it."""
    height, width = raster.shape
    r, c = torch.round(rows).long(), torch.round(cols).long()
    inside = (r >= 0) & (r < height) & (c >= 0) & (c < width)
    values = _take(raster.reshape(-1), r.clamp(0, height - 1) * width + c.clamp(0, width - 1))
    return torch.where(inside, values, -1)
