"""Episode pictures: a top view of the keyboard with the goal, the sensor's path,
the pressed key and the current tactile image; and episode GIFs."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from tactile_braille._io import atomic_path
from tactile_braille.keyboard.layout import KeyboardLayout

PX_PER_MM = 2.5
_GOAL = (60, 170, 60)
_PRESSED_RIGHT = (40, 120, 230)
_PRESSED_WRONG = (220, 60, 50)
_KEY = (205, 205, 205)
_KEY_EDGE = (120, 120, 120)
_PATH = (230, 150, 30)
_SENSOR = (200, 40, 40)


def top_view(
    layout: KeyboardLayout,
    view_mm: tuple[float, float, float, float],
    goal_key: str,
    path_mm: Sequence[tuple[float, float]],
    dome_radius_mm: float,
    pressed_key: str | None,
    tactile_image: np.ndarray,
) -> np.ndarray:
    """RGB top view of the keyboard region ``view_mm = (x0, x1, y0, y1)``.

    The image's rows run along the keyboard's x (towards the typist) and its
    columns along -y, so the keyboard reads as a typist sees it. The goal key
    is green, a pressed key blue (right) or red (wrong), the sensor's path
    orange with the dome's footprint at its end; the tactile image is inset.
    """
    x0, x1, y0, y1 = view_mm
    height, width = int((x1 - x0) * PX_PER_MM), int((y1 - y0) * PX_PER_MM)
    canvas = np.full((height, width, 3), 245, dtype=np.uint8)

    def to_px(x: float, y: float) -> tuple[int, int]:
        return round((y1 - y) * PX_PER_MM), round((x - x0) * PX_PER_MM)

    for key in layout.keys:
        half_x = layout.pitch_mm / 2 - 0.8
        half_y = key.width_u * layout.pitch_mm / 2 - 0.8
        if key.centre_x_mm + half_x < x0 or key.centre_x_mm - half_x > x1:
            continue
        if key.centre_y_mm + half_y < y0 or key.centre_y_mm - half_y > y1:
            continue
        colour = _KEY
        if key.name == goal_key:
            colour = _GOAL
        if key.name == pressed_key:
            colour = _PRESSED_RIGHT if pressed_key == goal_key else _PRESSED_WRONG
        top_left = to_px(key.centre_x_mm - half_x, key.centre_y_mm + half_y)
        bottom_right = to_px(key.centre_x_mm + half_x, key.centre_y_mm - half_y)
        cv2.rectangle(canvas, top_left, bottom_right, colour, -1)
        cv2.rectangle(canvas, top_left, bottom_right, _KEY_EDGE, 1)
        label = key.name if len(key.name) <= 5 else key.name[:5]
        text_at = to_px(key.centre_x_mm + 2.0, key.centre_y_mm + 4.0)
        cv2.putText(canvas, label, text_at, cv2.FONT_HERSHEY_SIMPLEX, 0.32, (60, 60, 60), 1, cv2.LINE_AA)

    points = np.array([to_px(x, y) for x, y in path_mm], dtype=np.int32)
    if len(points) > 1:
        cv2.polylines(canvas, [points], False, _PATH, 2, cv2.LINE_AA)
    if len(points):
        cv2.circle(canvas, tuple(points[-1]), int(dome_radius_mm * PX_PER_MM), _SENSOR, 2, cv2.LINE_AA)
        cv2.circle(canvas, tuple(points[-1]), 3, _SENSOR, -1, cv2.LINE_AA)

    inset = cv2.cvtColor(np.ascontiguousarray(tactile_image), cv2.COLOR_GRAY2RGB)
    side = min(height, width) // 2
    inset = cv2.resize(inset, (side, side), interpolation=cv2.INTER_NEAREST)
    canvas[:side, width - side :] = inset
    cv2.rectangle(canvas, (width - side, 0), (width - 1, side - 1), (40, 40, 40), 1)
    return canvas


def save_gif(frames: Sequence[np.ndarray], path: str | Path, fps: float = 4.0) -> Path:
    """Write RGB frames as an animated GIF (atomically)."""
    from PIL import Image

    if not frames:
        raise ValueError("no frames to write")
    images = [Image.fromarray(np.asarray(frame, dtype=np.uint8)) for frame in frames]
    with atomic_path(path) as temporary:
        images[0].save(temporary, format="GIF", save_all=True, append_images=images[1:],
                       duration=int(1000 / fps), loop=0)  # fmt: skip
    return Path(path)
