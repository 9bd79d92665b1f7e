"""From a raw camera frame to the binary tactile observation.

Written once and applied to every frame, real or rendered: crop to the
sensor's bounding box, area-resize, adaptive mean threshold.
"""

from __future__ import annotations

import cv2
import numpy as np

from tactile_braille.sensor.config import ImageProcessing


def process_frame(frame: np.ndarray, processing: ImageProcessing | None = None) -> np.ndarray:
    """Turn one raw frame into a ``(size, size)`` uint8 image of 0 and 255.

    Args:
        frame: grey ``(H, W)`` or colour ``(H, W, 3)`` BGR uint8 image, as an
            OpenCV capture or the renderer returns it.
        processing: crop, size and threshold parameters.

    Raises:
        ValueError: the frame is not a uint8 image large enough for the crop.
    """
    processing = processing or ImageProcessing()
    frame = np.asarray(frame)
    if frame.dtype != np.uint8:
        raise ValueError(f"expected a uint8 camera frame, got dtype {frame.dtype}")
    if frame.ndim == 3 and frame.shape[2] == 3:
        frame = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    elif frame.ndim != 2:
        raise ValueError(f"expected an (H, W) or (H, W, 3) frame, got shape {frame.shape}")
    x0, y0, x1, y1 = processing.crop_px
    if frame.shape[0] < y1 or frame.shape[1] < x1:
        raise ValueError(f"frame of shape {frame.shape} is smaller than the crop box {processing.crop_px}")
    cropped = frame[y0:y1, x0:x1]
    size = processing.size_px
    resized = cv2.resize(cropped, (size, size), interpolation=cv2.INTER_AREA)
    return threshold_image(resized, processing)


def threshold_image(resized: np.ndarray, processing: ImageProcessing) -> np.ndarray:
    """The last step of :func:`process_frame`: the adaptive mean threshold of the resized grey image."""
    return cv2.adaptiveThreshold(
        resized,
        255,
        cv2.ADAPTIVE_THRESH_MEAN_C,
        cv2.THRESH_BINARY,
        processing.threshold_block_px,
        processing.threshold_constant,
    )
