"""From a raw camera frame to the 100x100 binary observation."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tactile_braille.sensor.config import ImageProcessing
from tactile_braille.sensor.processing import process_frame

# Disc centres in the raw frame (x, y) inside the default crop box x 110..510, y 40..440,
# and where they land in the 100x100 output (scale 1/4): (row, column).
DISCS = [((310, 240), (50, 50)), ((150, 80), (10, 10)), ((470, 400), (90, 90)), ((210, 360), (80, 25))]
DISC_RADIUS_PX = 10


def _camera_frame(background=30, level=220):
    frame = np.full((480, 640), background, dtype=np.uint8)
    for (x, y), _ in DISCS:
        cv2.circle(frame, (x, y), DISC_RADIUS_PX, level, thickness=-1, lineType=cv2.LINE_AA)
    # A bright disc outside the crop box must not show up.
    cv2.circle(frame, (50, 240), 20, 255, thickness=-1)
    return frame


def test_output_is_binary_100x100_uint8():
    observation = process_frame(_camera_frame())
    assert observation.shape == (100, 100)
    assert observation.dtype == np.uint8
    assert set(np.unique(observation).tolist()) == {0, 255}


def test_discs_are_white_at_their_scaled_positions_and_background_black():
    observation = process_frame(_camera_frame())
    near_disc = np.zeros((100, 100), dtype=bool)
    rows, cols = np.mgrid[0:100, 0:100]
    for _, (r, c) in DISCS:
        assert observation[r, c] == 255, (r, c)
        near_disc |= np.hypot(rows - r, cols - c) <= DISC_RADIUS_PX / 4 + 1.5
    assert (observation[~near_disc] == 0).all()
    # Each disc is a blob of a few pixels, not a single one.
    for _, (r, c) in DISCS:
        assert observation[r - 3 : r + 4, c - 3 : c + 4].sum() // 255 >= 9


def test_uniform_frame_is_all_black():
    assert (process_frame(np.full((480, 640), 128, dtype=np.uint8)) == 0).all()


def test_faint_spots_below_the_threshold_constant_are_dropped():
    frame = np.full((480, 640), 30, dtype=np.uint8)
    cv2.circle(frame, (310, 240), DISC_RADIUS_PX, 50, thickness=-1)  # only 20 levels brighter
    assert (process_frame(frame) == 0).all()


def test_bgr_frame_gives_same_result_as_grey():
    grey = _camera_frame()
    bgr = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
    np.testing.assert_array_equal(process_frame(bgr), process_frame(grey))


def test_custom_processing_size_and_crop():
    processing = ImageProcessing(crop_px=(210, 140, 410, 340), size_px=50)
    observation = process_frame(_camera_frame(), processing)
    assert observation.shape == (50, 50)
    # The centre disc (310, 240) is at the centre of this crop: (25, 25) at scale 1/4.
    assert observation[25, 25] == 255


def test_larger_frame_is_accepted():
    frame = np.zeros((600, 800), dtype=np.uint8)
    frame[:480, :640] = _camera_frame()
    np.testing.assert_array_equal(process_frame(frame), process_frame(_camera_frame()))


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.uint16, np.int32])
def test_wrong_dtype_raises(dtype):
    with pytest.raises(ValueError, match="uint8"):
        process_frame(_camera_frame().astype(dtype))


@pytest.mark.parametrize("shape", [(300, 640), (480, 400), (100, 100)])
def test_frame_smaller_than_crop_raises(shape):
    with pytest.raises(ValueError, match="smaller than the crop box"):
        process_frame(np.zeros(shape, dtype=np.uint8))


@pytest.mark.parametrize("shape", [(480,), (480, 640, 4), (480, 640, 1), (2, 480, 640, 3)])
def test_wrong_ndim_or_channels_raises(shape):
    with pytest.raises(ValueError, match=r"\(H, W\) or \(H, W, 3\)"):
        process_frame(np.zeros(shape, dtype=np.uint8))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"threshold_block_px": 10}, "odd"),
        ({"threshold_block_px": 1}, "odd"),
        ({"crop_px": (300, 40, 200, 440)}, "crop_px"),
        ({"crop_px": (-1, 40, 510, 440)}, "crop_px"),
        ({"size_px": 4}, "size_px"),
    ],
)
def test_invalid_processing_raises(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ImageProcessing(**kwargs)
