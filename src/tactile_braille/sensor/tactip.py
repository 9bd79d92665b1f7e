"""Rendering a TacTip's raw camera frame from its contact with a surface.

The TacTip is a soft hemispherical dome whose inside is lined with pins
(white-tipped markers) and filmed by a camera. When the dome presses on an
object the skin is indented; the pins on the indented skin tilt and move, and
the camera sees the pin pattern change. The model, step by step:

1. **Contact.** The surface's height field is sampled on a square grid in the
   sensor's frame (one affine warp). The geometric overlap of the surface with
   the undeformed dome is the indentation.
2. **Skin.** The elastic skin and gel spread the indentation: the skin's
   inward displacement ``w`` is the indentation smoothed by a Gaussian of
   width ``skin_smoothing_mm``.
3. **Pins.** A pin stands ``pin_length_mm`` off the skin along its normal:
   where the skin slopes, the tip moves sideways by ``-pin_length * grad(w)``
   (pins splay away from each bump, so braille dots show as local rosettes),
   and the inward push moves it towards the axis by ``w * sin(theta)``.
4. **Camera.** Pins are drawn as ellipses, blurred by the lens, (foreshortened on the
   dome's flanks) by an orthographic camera on the dome's axis, over a dark
   background, with seedable lighting gain and pixel noise.

Orientation: at ``yaw_deg = 0`` braille reads upright in the image (the
paper's rig achieved that with its -145 degree tool rotation): image rows run
along the keyboard's ``x`` (towards the typist) and columns along ``-y``.
"""

from __future__ import annotations

from functools import cached_property
from typing import NamedTuple

import cv2
import numpy as np

from tactile_braille.keyboard.surface import KeyboardSurface
from tactile_braille.sensor.config import TacTipConfig
from tactile_braille.sensor.processing import process_frame

_ELLIPSE_VERTICES = 6
SUBPIXEL_BITS = 4
"""Markers are filled on a 1/16-pixel grid (OpenCV's ``shift``)."""
NOISE_BANK_MARGIN_PX = 64


class FrameNuisance(NamedTuple):
    """The nuisances of one rendered frame (none: the noiseless ideal).

    Attributes:
        dx_mm, dy_mm, dyaw_deg: unmodelled pose error added to the tap's pose.
        gain: lighting gain of the frame.
        noise_offset_px: (row, column) of the frame's window into the sensor's
            fixed bank of pixel noise, or None for no pixel noise.
    """

    dx_mm: float = 0.0
    dy_mm: float = 0.0
    dyaw_deg: float = 0.0
    gain: float = 1.0
    noise_offset_px: tuple[int, int] | None = None


class TacTip:
    """A simulated TacTip: contact, skin, pins, camera.

    Args:
        config: sensor geometry, camera and nuisance parameters.
        grid_px: side of the square contact grid across the dome.
    """

    def __init__(self, config: TacTipConfig | None = None, grid_px: int = 100) -> None:
        self.config = config or TacTipConfig()
        if grid_px < 16:
            raise ValueError(f"grid_px must be at least 16, got {grid_px}")
        self.grid_px = int(grid_px)
        self.grid_spacing_mm = self.config.dome_diameter_mm / self.grid_px
        centre = (self.grid_px - 1) / 2
        offsets = (np.arange(self.grid_px) - centre) * self.grid_spacing_mm
        self._local_x_mm, self._local_y_mm = np.meshgrid(offsets, offsets, indexing="ij")
        radial = np.hypot(self._local_x_mm, self._local_y_mm)
        dome = self.config.dome_height_mm(radial).astype(np.float32)
        # Outside the dome's footprint nothing can be touched.
        self._dome_height_mm = np.where(radial <= self.config.dome_diameter_mm / 2, dome, 1e3).astype(
            np.float32
        )

    # ---------------------------------------------------------------- pins
    @cached_property
    def pin_rest_mm(self) -> np.ndarray:
        """(n_pins, 2) rest positions of the pins projected on the sensor plane."""
        return self._pin_layout[0]

    @cached_property
    def _pin_layout(self) -> tuple[np.ndarray, np.ndarray]:
        """Pins on concentric rings laid geodesically over the dome.

        Ring ``i`` holds ``6 i`` pins at arc length ``i * pitch`` from the
        apex (the TacTip's pattern; the count is the centred hexagonal number
        ``1 + 3 n (n + 1)``), alternate rings offset by half a pin. Returns the
        projected positions (n, 2) and each pin's polar angle on the dome's
        sphere (n,).
        """
        config = self.config
        radius = config.dome_radius_mm
        rim_angle = np.arcsin(min(config.dome_diameter_mm / 2 / radius, 1.0))
        # The outermost ring sits at 93 % of the arc from apex to rim.
        pitch = 0.93 * radius * rim_angle / config.pin_rings
        arcs, azimuths = [0.0], [0.0]
        for ring in range(1, config.pin_rings + 1):
            count = 6 * ring
            phase = 0.5 * (ring % 2)
            arcs.extend([ring * pitch] * count)
            azimuths.extend(2 * np.pi * (np.arange(count) + phase) / count)
        theta = np.asarray(arcs) / radius
        projected = radius * np.sin(theta)
        azimuths = np.asarray(azimuths)
        positions = np.stack([projected * np.cos(azimuths), projected * np.sin(azimuths)], axis=-1)
        return positions, theta

    @cached_property
    def _pin_grid_index(self) -> tuple[np.ndarray, np.ndarray]:
        centre = (self.grid_px - 1) / 2
        cells = np.rint(self.pin_rest_mm / self.grid_spacing_mm + centre).astype(int)
        cells = np.clip(cells, 1, self.grid_px - 2)
        return cells[:, 0], cells[:, 1]

    @cached_property
    def _ellipse_unit(self) -> tuple[np.ndarray, np.ndarray]:
        angles = np.linspace(0, 2 * np.pi, _ELLIPSE_VERTICES, endpoint=False)
        return np.cos(angles), np.sin(angles)

    # ------------------------------------------------------------- contact
    def raster_from_local(
        self, surface: KeyboardSurface, x_mm: float, y_mm: float, yaw_deg: float
    ) -> np.ndarray:
        """Affine map from the contact grid (column, row) to the surface raster."""
        yaw = np.radians(yaw_deg)
        c, s = np.cos(yaw), np.sin(yaw)
        step = self.grid_spacing_mm / surface.resolution_mm
        centre = (self.grid_px - 1) / 2
        origin_row, origin_col = surface.to_cell(x_mm, y_mm)
        # local (a, b) = ((row - centre) * spacing, (col - centre) * spacing)
        # keyboard x = x + c a - s b ; keyboard y = y + s a + c b
        return np.array(
            [
                [c * step, s * step, origin_col - (s + c) * centre * step],
                [-s * step, c * step, origin_row - (c - s) * centre * step],
            ]
        )

    def indentation_mm(
        self,
        surface: KeyboardSurface,
        x_mm: float,
        y_mm: float,
        apex_height_mm: float,
        yaw_deg: float = 0.0,
        key_descent_mm: dict[int, float] | None = None,
    ) -> np.ndarray:
        """Overlap of the surface with the undeformed dome on the contact grid.

        Args:
            surface: the keyboard's height field.
            x_mm, y_mm: position of the dome's apex in the keyboard frame.
            apex_height_mm: height of the apex above the key tops (negative
                when pushed below them).
            yaw_deg: rotation of the sensor about its axis.
            key_descent_mm: keys pushed down by the tap (index -> mm).
        """
        heights = surface.local_heights_mm(
            self.raster_from_local(surface, x_mm, y_mm, yaw_deg),
            (self.grid_px, self.grid_px),
            key_descent_mm,
        )
        return np.maximum(heights - (self._dome_height_mm + np.float32(apex_height_mm)), 0.0)

    def pin_displacement_mm(self, indentation_mm: np.ndarray) -> np.ndarray:
        """(n_pins, 2) sideways motion of the pins for an indentation field."""
        config = self.config
        sigma_px = config.skin_smoothing_mm / self.grid_spacing_mm
        skin = cv2.GaussianBlur(indentation_mm, (0, 0), sigma_px, borderType=cv2.BORDER_CONSTANT)
        rows, cols = self._pin_grid_index
        # Central differences of the skin at the pins (the grid has a margin
        # of one cell around every pin).
        step = 2 * self.grid_spacing_mm
        slope = np.stack(
            [skin[rows + 1, cols] - skin[rows - 1, cols], skin[rows, cols + 1] - skin[rows, cols - 1]],
            axis=-1,
        )
        tilt = (-config.pin_length_mm / step) * slope
        towards_axis, sin_theta = self._pin_inward
        return tilt + (skin[rows, cols] * sin_theta)[:, None] * towards_axis

    @cached_property
    def _pin_inward(self) -> tuple[np.ndarray, np.ndarray]:
        """Unit vectors from each pin towards the axis, and each pin's sin(theta)."""
        positions, theta = self._pin_layout
        radial = np.hypot(positions[:, 0], positions[:, 1])[:, None]
        towards_axis = -np.divide(positions, radial, out=np.zeros_like(positions), where=radial > 0)
        return towards_axis, np.sin(theta)

    # -------------------------------------------------------------- camera
    @cached_property
    def _background(self) -> np.ndarray:
        config = self.config
        width, height = config.camera_px
        cx, cy = config.image_centre_px
        yy, xx = np.mgrid[0:height, 0:width]
        r = np.hypot(xx - cx, yy - cy) / config.image_radius_px
        # Dim vignetted interior, darker outside the dome, a faint rim.
        inside = config.background_level * (1.0 - 0.35 * np.clip(r, 0, 1) ** 2)
        level = np.where(r <= 1.0, inside, 0.4 * config.background_level)
        level += 25.0 * np.exp(-(((r - 1.02) / 0.015) ** 2))
        return np.clip(level, 0, 255).astype(np.uint8)

    @cached_property
    def _dome_box_px(self) -> tuple[int, int, int, int]:
        config = self.config
        width, height = config.camera_px
        cx, cy = config.image_centre_px
        reach = config.image_radius_px * 1.08
        return (
            max(int(cx - reach), 0),
            max(int(cy - reach), 0),
            min(int(cx + reach) + 1, width),
            min(int(cy + reach) + 1, height),
        )

    @cached_property
    def _noise_bank(self) -> tuple[np.ndarray, np.ndarray]:
        width, height = self.config.camera_px
        bank_rng = np.random.default_rng(0x7AC71B)
        shape = (height + NOISE_BANK_MARGIN_PX, width + NOISE_BANK_MARGIN_PX)
        noise = np.rint(self.config.nuisance.pixel_noise_std * bank_rng.standard_normal(shape))
        # Stored as its positive and negative parts: two saturating uint8
        # operations are 3-4x faster than one mixed-type addition.
        return np.clip(noise, 0, 255).astype(np.uint8), np.clip(-noise, 0, 255).astype(np.uint8)

    def draw_nuisance(self, rng: np.random.Generator) -> FrameNuisance:
        """One frame's nuisances from ``rng``: pose jitter, lighting gain, noise offset.

        The draws, in this order, are those every rendered frame makes; the
        batched renderer (:mod:`tactile_braille.sensor.batched`) takes them so
        that both paths render the same frame from the same generator.
        """
        nuisance = self.config.nuisance
        dx = nuisance.position_jitter_mm * rng.standard_normal()
        dy = nuisance.position_jitter_mm * rng.standard_normal()
        dyaw = nuisance.yaw_jitter_deg * rng.standard_normal()
        gain = max(1.0 + nuisance.lighting_gain_std * rng.standard_normal(), 0.1)
        offset = None
        if nuisance.pixel_noise_std > 0:
            row, col = rng.integers(0, NOISE_BANK_MARGIN_PX, size=2)
            offset = (int(row), int(col))
        return FrameNuisance(float(dx), float(dy), float(dyaw), float(gain), offset)

    def render_frame(
        self,
        surface: KeyboardSurface,
        x_mm: float,
        y_mm: float,
        apex_height_mm: float,
        yaw_deg: float = 0.0,
        rng: np.random.Generator | None = None,
        key_descent_mm: dict[int, float] | None = None,
    ) -> np.ndarray:
        """The raw grey camera frame (uint8, camera height x width) at a pose.

        ``rng`` draws the nuisances (pose jitter, lighting, pixel noise);
        without it the frame is the noiseless ideal.
        """
        drawn = FrameNuisance() if rng is None else self.draw_nuisance(rng)
        indentation = self.indentation_mm(
            surface,
            x_mm + drawn.dx_mm,
            y_mm + drawn.dy_mm,
            apex_height_mm,
            yaw_deg + drawn.dyaw_deg,
            key_descent_mm,
        )
        positions = self.pin_rest_mm + self.pin_displacement_mm(indentation)

        frame = cv2.convertScaleAbs(self._background, alpha=drawn.gain)
        self._draw_pins(frame, positions, drawn.gain)
        if drawn.noise_offset_px is not None:
            height, width = frame.shape
            dy, dx = drawn.noise_offset_px
            brighter, darker = self._noise_bank
            cv2.add(frame, brighter[dy : dy + height, dx : dx + width], dst=frame)
            cv2.subtract(frame, darker[dy : dy + height, dx : dx + width], dst=frame)
        return frame

    @cached_property
    def _pin_outline_px(self) -> np.ndarray:
        """(n_pins, vertices, 2) outline of each pin's marker around its centre.

        Markers are ellipses foreshortened along the dome's radial direction
        by ``cos(theta)``; pins move little, so the rest orientation is used.
        """
        config = self.config
        positions, theta = self._pin_layout
        # Image column runs along -y, image row along x.
        radial = np.stack([-positions[:, 1], positions[:, 0]], axis=-1)
        norm = np.linalg.norm(radial, axis=-1, keepdims=True)
        radial = np.divide(radial, norm, out=np.tile([1.0, 0.0], (len(radial), 1)), where=norm > 0)
        tangential = np.stack([-radial[:, 1], radial[:, 0]], axis=-1)
        radius_px = config.marker_radius_mm * config.px_per_mm
        cos_a, sin_a = self._ellipse_unit
        return (radius_px * np.cos(theta))[:, None, None] * radial[:, None, :] * cos_a[
            None, :, None
        ] + radius_px * tangential[:, None, :] * sin_a[None, :, None]

    def _draw_pins(self, frame: np.ndarray, positions_mm: np.ndarray, gain: float) -> None:
        config = self.config
        scale = config.px_per_mm
        cx, cy = config.image_centre_px
        centres = np.stack([cx - scale * positions_mm[:, 1], cy + scale * positions_mm[:, 0]], axis=-1)
        vertices = centres[:, None, :] + self._pin_outline_px
        polygons = np.rint(vertices * (1 << SUBPIXEL_BITS)).astype(np.int32)
        level = int(min(config.pin_level * gain, 255))
        cv2.fillPoly(frame, polygons, level, lineType=cv2.LINE_8, shift=SUBPIXEL_BITS)
        # The lens's blur, over the dome's bounding box only (the rest is flat).
        x0, y0, x1, y1 = self._dome_box_px
        roi = frame[y0:y1, x0:x1]
        cv2.blur(roi, (3, 3), dst=roi)

    def observe(
        self,
        surface: KeyboardSurface,
        x_mm: float,
        y_mm: float,
        apex_height_mm: float,
        yaw_deg: float = 0.0,
        rng: np.random.Generator | None = None,
        key_descent_mm: dict[int, float] | None = None,
    ) -> np.ndarray:
        """The processed binary observation at a pose (render + :func:`process_frame`)."""
        frame = self.render_frame(surface, x_mm, y_mm, apex_height_mm, yaw_deg, rng, key_descent_mm)
        return process_frame(frame, self.config.processing)
