"""TacTip sensor parameters, with presets for the paper's tip and the standard one."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np


@dataclass(frozen=True)
class ImageProcessing:
    """Processing from a raw camera frame to the binary observation.

    The paper's values: crop to the sensor's bounding box, area-resize to
    100 x 100, adaptive mean threshold (block 11, constant -30). No blur.

    Attributes:
        crop_px: (x0, y0, x1, y1) bounding box of the sensor in the frame.
        size_px: side of the square observation.
        threshold_block_px: neighbourhood of the adaptive threshold (odd).
        threshold_constant: subtracted from the local mean (negative keeps
            only pixels clearly brighter than their surroundings).
    """

    crop_px: tuple[int, int, int, int] = (110, 40, 510, 440)
    size_px: int = 100
    threshold_block_px: int = 11
    threshold_constant: float = -30.0

    def __post_init__(self) -> None:
        x0, y0, x1, y1 = self.crop_px
        if not (0 <= x0 < x1 and 0 <= y0 < y1):
            raise ValueError(f"crop_px must be (x0, y0, x1, y1) with x0 < x1, y0 < y1; got {self.crop_px}")
        if self.size_px < 8:
            raise ValueError(f"size_px must be at least 8, got {self.size_px}")
        if self.threshold_block_px < 3 or self.threshold_block_px % 2 == 0:
            raise ValueError(f"threshold_block_px must be odd and >= 3, got {self.threshold_block_px}")


@dataclass(frozen=True)
class Nuisance:
    """Seedable imperfections of a real sensor, drawn once per rendered frame.

    Attributes:
        pixel_noise_std: std of additive camera noise (grey levels).
        lighting_gain_std: relative std of the LED brightness.
        position_jitter_mm: std of the unmodelled pose error in x and y.
        yaw_jitter_deg: std of the unmodelled yaw error.
    """

    pixel_noise_std: float = 6.0
    lighting_gain_std: float = 0.05
    position_jitter_mm: float = 0.1
    yaw_jitter_deg: float = 0.5

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not value >= 0:
                raise ValueError(f"{name} must be non-negative, got {value!r}")


@dataclass(frozen=True)
class TacTipConfig:
    """Geometry, camera and skin mechanics of a TacTip.

    Attributes:
        name: preset name.
        pin_rings: pins form a hexagonal pattern of this many rings around a
            central pin: ``1 + 3 * rings * (rings + 1)`` pins (10 rings = 331).
        pin_radius_mm: radius of a pin's body.
        marker_radius_mm: radius of the painted white marker on the pin's
            end face, which is what the camera sees.
        dome_diameter_mm: diameter of the dome where it meets the sensor body.
        dome_depth_mm: height of the dome from its rim to its apex.
        pin_length_mm: effective lever of a pin: a tilt of the skin by slope
            ``s`` moves the pin's image sideways by ``length * s``. The
            physical pins are shorter (2-3 mm); the default folds in the
            gel's amplification and was set, with ``skin_smoothing_mm``, so
            that the paper's CNN recipe reads the 31 keys from single images
            about as well as it did on the real sensor (~98 % here, 99 % in
            the paper; see docs/results.md for the sensitivity).
        skin_smoothing_mm: std of the Gaussian that spreads an indentation
            through the elastic skin and gel.
        camera_px: (width, height) of the raw camera frame.
        image_radius_px: radius of the dome's rim in the raw frame.
        background_level: grey level of the dark inside of the sensor.
        pin_level: grey level of a pin tip at nominal lighting.
        processing: how raw frames become observations.
        nuisance: seedable imperfections.
    """

    name: str = "braille_331"
    pin_rings: int = 10
    pin_radius_mm: float = 0.625
    marker_radius_mm: float = 0.45
    dome_diameter_mm: float = 25.0
    dome_depth_mm: float = 7.2
    pin_length_mm: float = 6.0
    skin_smoothing_mm: float = 0.8
    camera_px: tuple[int, int] = (640, 480)
    image_radius_px: float = 195.0
    background_level: int = 35
    pin_level: int = 215
    processing: ImageProcessing = field(default_factory=ImageProcessing)
    nuisance: Nuisance = field(default_factory=Nuisance)

    def __post_init__(self) -> None:
        if self.pin_rings < 1:
            raise ValueError(f"pin_rings must be at least 1, got {self.pin_rings}")
        for name in (
            "pin_radius_mm",
            "marker_radius_mm",
            "dome_diameter_mm",
            "dome_depth_mm",
            "image_radius_px",
        ):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)!r}")
        if self.marker_radius_mm > self.pin_radius_mm:
            raise ValueError("marker_radius_mm cannot exceed pin_radius_mm")
        if self.dome_depth_mm > self.dome_diameter_mm / 2:
            raise ValueError("dome_depth_mm cannot exceed half the dome diameter (a hemisphere)")
        width, height = self.camera_px
        _, _, x1, y1 = self.processing.crop_px
        if x1 > width or y1 > height:
            raise ValueError(f"crop {self.processing.crop_px} does not fit a {width}x{height} frame")

    @property
    def pin_count(self) -> int:
        """Number of pins (a centred hexagonal number)."""
        return 1 + 3 * self.pin_rings * (self.pin_rings + 1)

    @property
    def dome_radius_mm(self) -> float:
        """Radius of the sphere the dome is cut from."""
        half = self.dome_diameter_mm / 2
        return (half**2 + self.dome_depth_mm**2) / (2 * self.dome_depth_mm)

    @property
    def image_centre_px(self) -> tuple[float, float]:
        """Centre of the dome in the raw frame: the centre of the crop box."""
        x0, y0, x1, y1 = self.processing.crop_px
        return (x0 + x1) / 2, (y0 + y1) / 2

    @property
    def px_per_mm(self) -> float:
        """Scale of the (orthographic) camera at the dome's rim."""
        return self.image_radius_px / (self.dome_diameter_mm / 2)

    def dome_height_mm(self, radial_mm: np.ndarray) -> np.ndarray:
        """Height of the dome surface above its apex at a horizontal distance."""
        radius = self.dome_radius_mm
        r = np.minimum(np.asarray(radial_mm, float), radius)
        return radius - np.sqrt(radius**2 - r**2)


PRESETS: dict[str, TacTipConfig] = {
    "braille_331": TacTipConfig(),
    # The standard TacTip: 127 pins on a 40 mm dome (a near-hemisphere, here
    # 14 mm deep), larger pins; the same camera and processing.
    "tactip_127": TacTipConfig(
        name="tactip_127",
        pin_rings=6,
        pin_radius_mm=1.0,
        marker_radius_mm=0.75,
        dome_diameter_mm=40.0,
        dome_depth_mm=14.0,
        pin_length_mm=6.0,
        skin_smoothing_mm=1.2,
    ),
}
"""Sensor presets by name: the paper's 331-pin tip and the standard 127-pin one."""


def sensor_preset(name: str, **overrides) -> TacTipConfig:
    """The preset called ``name``, optionally with fields replaced."""
    try:
        config = PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown sensor preset {name!r}; choose one of {sorted(PRESETS)}") from None
    return replace(config, **overrides) if overrides else config
