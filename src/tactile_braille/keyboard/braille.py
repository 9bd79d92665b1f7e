"""Braille on the keycaps: grade-1 letter cells, arrow shapes, dot geometry.

A braille cell has six dot positions, numbered down the left column (1, 2, 3)
and then down the right column (4, 5, 6). Letters use the standard grade-1
alphabet. The arrow keys carry raised arrows; SPACE is blank.

Relief is described in the **keycap frame** (mm): origin at the key centre,
``x`` towards the typist (down the cell) and ``y`` to the typist's left, the
axes of the keyboard frame. A reader in front of the keyboard therefore sees
column 1-2-3 at ``y > 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BRAILLE_DOTS: dict[str, tuple[int, ...]] = {
    "A": (1,), "B": (1, 2), "C": (1, 4), "D": (1, 4, 5), "E": (1, 5),
    "F": (1, 2, 4), "G": (1, 2, 4, 5), "H": (1, 2, 5), "I": (2, 4), "J": (2, 4, 5),
    "K": (1, 3), "L": (1, 2, 3), "M": (1, 3, 4), "N": (1, 3, 4, 5), "O": (1, 3, 5),
    "P": (1, 2, 3, 4), "Q": (1, 2, 3, 4, 5), "R": (1, 2, 3, 5), "S": (2, 3, 4),
    "T": (2, 3, 4, 5), "U": (1, 3, 6), "V": (1, 2, 3, 6), "W": (2, 4, 5, 6),
    "X": (1, 3, 4, 6), "Y": (1, 3, 4, 5, 6), "Z": (1, 3, 5, 6),
}  # fmt: skip
"""Raised dots of each letter in the standard (grade-1) braille alphabet."""

# Arrow pointing "up" (towards -x, away from the typist) as polyline segments
# (x0, y0, x1, y1) in mm: a shaft and a chevron head.
_ARROW_UP_SEGMENTS = np.array(
    [
        (3.5, 0.0, -3.0, 0.0),
        (-3.5, 0.0, -0.5, 2.8),
        (-3.5, 0.0, -0.5, -2.8),
    ]
)
# Rotations (deg, counter-clockwise from +x towards +y) turning "up" into each arrow.
_ARROW_ROTATION_DEG = {"UP": 0.0, "LEFT": -90.0, "DOWN": 180.0, "RIGHT": 90.0}


@dataclass(frozen=True)
class BrailleGeometry:
    """Dimensions of the braille relief (standard values by default).

    Attributes:
        dot_base_diameter_mm: diameter of a dot where it meets the keycap.
        dot_height_mm: height of a dot (and of an arrow ridge).
        dot_pitch_mm: distance between neighbouring dots of a cell.
        ridge_width_mm: base width of the ridges that draw an arrow.
    """

    dot_base_diameter_mm: float = 1.5
    dot_height_mm: float = 0.5
    dot_pitch_mm: float = 2.5
    ridge_width_mm: float = 1.5

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not value > 0:
                raise ValueError(f"{name} must be positive, got {value!r}")


def dot_positions_mm(letter: str, geometry: BrailleGeometry | None = None) -> np.ndarray:
    """(n_dots, 2) centres of the raised dots of ``letter`` in the keycap frame."""
    geometry = geometry or BrailleGeometry()
    try:
        dots = BRAILLE_DOTS[letter.upper()]
    except KeyError:
        raise ValueError(f"no braille cell for {letter!r}; letters A-Z only") from None
    pitch = geometry.dot_pitch_mm
    positions = []
    for dot in dots:
        column, row = divmod(dot - 1, 3)
        positions.append(((row - 1) * pitch, (0.5 - column) * pitch))
    return np.array(positions, dtype=float)


def arrow_segments_mm(key: str) -> np.ndarray:
    """(n, 4) ridge segments (x0, y0, x1, y1) of the arrow on key ``key``."""
    try:
        angle = np.radians(_ARROW_ROTATION_DEG[key])
    except KeyError:
        raise ValueError(f"{key!r} is not an arrow key") from None
    c, s = np.cos(angle), np.sin(angle)
    rotation = np.array([[c, -s], [s, c]])
    starts = _ARROW_UP_SEGMENTS[:, :2] @ rotation.T
    ends = _ARROW_UP_SEGMENTS[:, 2:] @ rotation.T
    return np.hstack([starts, ends])


def relief_height_mm(
    key: str, x_mm: np.ndarray, y_mm: np.ndarray, geometry: BrailleGeometry | None = None
) -> np.ndarray:
    """Height of the raised relief of ``key`` above its keycap top.

    Dots are spherical caps; arrow ridges have the same circular cross-section
    swept along their segments. Keys without relief (SPACE and every other
    non-letter, non-arrow key) return zeros.

    Args:
        key: key name.
        x_mm, y_mm: points in the keycap frame (any broadcastable shapes).
        geometry: relief dimensions.
    """
    geometry = geometry or BrailleGeometry()
    x_mm, y_mm = np.broadcast_arrays(np.asarray(x_mm, float), np.asarray(y_mm, float))
    height = np.zeros(x_mm.shape)
    if key in BRAILLE_DOTS:
        base_radius = geometry.dot_base_diameter_mm / 2
        for cx, cy in dot_positions_mm(key, geometry):
            distance = np.hypot(x_mm - cx, y_mm - cy)
            height = np.maximum(height, _cap_profile(distance, base_radius, geometry.dot_height_mm))
    elif key in _ARROW_ROTATION_DEG:
        base_radius = geometry.ridge_width_mm / 2
        for x0, y0, x1, y1 in arrow_segments_mm(key):
            distance = _distance_to_segment(x_mm, y_mm, x0, y0, x1, y1)
            height = np.maximum(height, _cap_profile(distance, base_radius, geometry.dot_height_mm))
    return height


def _cap_profile(distance: np.ndarray, base_radius: float, height: float) -> np.ndarray:
    """Spherical cap of given base radius and height, as a function of distance."""
    sphere_radius = (base_radius**2 + height**2) / (2 * height)
    inside = distance < base_radius
    z = np.sqrt(np.maximum(sphere_radius**2 - distance**2, 0.0)) - (sphere_radius - height)
    return np.where(inside, np.maximum(z, 0.0), 0.0)


def _distance_to_segment(x, y, x0, y0, x1, y1):
    dx, dy = x1 - x0, y1 - y0
    t = np.clip(((x - x0) * dx + (y - y0) * dy) / (dx * dx + dy * dy), 0.0, 1.0)
    return np.hypot(x - (x0 + t * dx), y - (y0 + t * dy))
