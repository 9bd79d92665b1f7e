"""The keyboard's surface height field."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_braille.keyboard.braille import dot_positions_mm
from tactile_braille.keyboard.layout import ALL_TASK_KEYS, KeyboardLayout
from tactile_braille.keyboard.surface import KeyboardSurface, KeycapProfile


def test_raster_covers_keyboard_with_margin(surface, layout):
    x_min, x_max, y_min, y_max = layout.bounds_mm
    assert surface.origin_mm == pytest.approx((x_min - 20.0, y_min - 20.0))
    assert surface.height_mm.shape == surface.shape
    assert surface.key_index.shape == surface.shape
    assert surface.height_mm.dtype == np.float32
    rows, cols = surface.to_cell(x_max + 20.0, y_max + 20.0)
    assert rows <= surface.shape[0] - 1
    assert cols <= surface.shape[1] - 1


@pytest.mark.parametrize("key", ["A", "Q", "SPACE", "UP", "ESC", "ENTER"])
def test_height_zero_on_a_key_top_away_from_relief(surface, layout, key):
    x, y = layout.centre_mm(key)
    # 5 mm along the row from the centre: on the flat top, clear of any dots (|y| <= 1.25 + 0.75)
    # and arrow ridges (|y| <= 2.8 + 0.75 only near the head, which sits at |x| >= 0.5).
    assert surface.sample(x + 5.5, y + 5.5) == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("letter", list("ABLWZ"))
def test_height_at_braille_dot_centres_is_dot_height(surface, layout, letter):
    cx, cy = layout.centre_mm(letter)
    dots = dot_positions_mm(letter) + np.array([cx, cy])
    np.testing.assert_allclose(surface.sample(dots[:, 0], dots[:, 1]), 0.5, atol=0.01)


def test_height_between_dots_is_key_top(surface, layout):
    cx, cy = layout.centre_mm("L")  # dots 1, 2, 3
    assert surface.sample(cx - 1.25, cy + 1.25) == pytest.approx(0.0, abs=1e-6)
    cx, cy = layout.centre_mm("A")  # only dot 1: dot 2 position is flat
    assert surface.sample(cx, cy + 1.25) == pytest.approx(0.0, abs=1e-6)


def test_space_has_no_relief(surface, layout):
    cx, cy = layout.centre_mm("SPACE")
    x, y = np.meshgrid(np.linspace(cx - 5, cx + 5, 41), np.linspace(cy - 5, cy + 5, 41))
    np.testing.assert_allclose(surface.sample(x, y), 0.0, atol=1e-6)


@pytest.mark.parametrize("key", ["UP", "DOWN", "LEFT", "RIGHT"])
def test_arrow_relief_at_key_centre(surface, layout, key):
    cx, cy = layout.centre_mm(key)
    assert surface.sample(cx, cy) == pytest.approx(0.5, abs=0.01)  # every arrow's shaft crosses the centre


@pytest.mark.parametrize(("left", "right"), [("G", "H"), ("Q", "W"), ("A", "Q")])
def test_gap_between_keys_is_below_key_tops(surface, layout, left, right):
    (x0, y0), (x1, y1) = layout.centre_mm(left), layout.centre_mm(right)
    if left == "A":  # across rows: midpoint in x at A's y
        mid_x, mid_y = (x0 + x1) / 2, y0
    else:
        mid_x, mid_y = (x0 + x1) / 2, (y0 + y1) / 2
    height = surface.sample(mid_x, mid_y)
    assert height < -3.0
    assert height >= -surface.profile.gap_depth_mm - 1e-6


def test_height_never_exceeds_relief(surface):
    assert surface.height_mm.max() == pytest.approx(0.5, abs=1e-3)
    assert surface.height_mm.min() == pytest.approx(-8.0)


def test_sample_off_raster_is_floor(surface):
    assert surface.sample(-1000.0, 1000.0) == pytest.approx(-8.0)


@pytest.mark.parametrize("key", ALL_TASK_KEYS)
def test_key_index_names_the_key_at_its_centre(surface, layout, key):
    row, col = surface.to_cell(*layout.centre_mm(key))
    index = surface.key_index[round(float(row)), round(float(col))]
    assert layout.keys[index].name == key


def test_key_index_between_keys_is_a_neighbours_skirt_and_minus_one_off_the_keyboard(surface, layout):
    gx, gy = layout.centre_mm("G")
    row, col = surface.to_cell(gx, gy - 9.5)
    index = surface.key_index[round(float(row)), round(float(col))]
    assert layout.keys[index].name in ("G", "H")
    x_min, _, y_min, _ = layout.bounds_mm
    row, col = surface.to_cell(x_min - 10.0, y_min - 10.0)
    assert surface.key_index[round(float(row)), round(float(col))] == -1
    # Wherever the raster is at the gap floor, no key owns it.
    floor = surface.height_mm <= -surface.profile.gap_depth_mm
    assert (surface.key_index[floor] == -1).all()
    assert (surface.key_index[~floor] >= 0).all()


def test_local_heights_identity_warp_matches_raster(surface, layout):
    """An affine map that picks a raster window returns that window; pushed-down keys sink."""
    cx, cy = layout.centre_mm("G")
    row, col = (round(float(v)) for v in surface.to_cell(cx, cy))
    affine = np.array([[1.0, 0.0, col - 10], [0.0, 1.0, row - 10]])
    heights = surface.local_heights_mm(affine, (21, 21))
    np.testing.assert_allclose(heights, surface.height_mm[row - 10 : row + 11, col - 10 : col + 11])
    g = layout.key("G").index
    lowered = surface.local_heights_mm(affine, (21, 21), key_descent_mm={g: 1.5})
    np.testing.assert_allclose(lowered, heights - 1.5, atol=1e-5)


def test_custom_profile_changes_gap_depth():
    shallow = KeyboardSurface(KeyboardLayout(), profile=KeycapProfile(gap_depth_mm=4.0), resolution_mm=0.5)
    assert shallow.height_mm.min() == pytest.approx(-4.0)


@pytest.mark.parametrize("resolution", [0.0, -0.1])
def test_invalid_resolution_raises(resolution):
    with pytest.raises(ValueError, match="resolution_mm"):
        KeyboardSurface(KeyboardLayout(), resolution_mm=resolution)
