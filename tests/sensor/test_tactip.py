"""The simulated TacTip: pins, contact, skin and rendered frames."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_braille.sensor.config import (
    PRESETS,
    ImageProcessing,
    Nuisance,
    TacTipConfig,
    sensor_preset,
)
from tactile_braille.sensor.tactip import TacTip

PRESS = -1.5  # apex 1.5 mm below the key tops: in contact, short of actuation
NO_CONTACT = 10.0  # apex 10 mm above the key tops


@pytest.fixture(scope="module")
def tactip_127():
    return TacTip(sensor_preset("tactip_127"))


@pytest.mark.parametrize(("preset", "pins"), [("braille_331", 331), ("tactip_127", 127)])
def test_pin_count(preset, pins):
    config = sensor_preset(preset)
    assert config.pin_count == pins
    sensor = TacTip(config)
    assert sensor.pin_rest_mm.shape == (pins, 2)
    # No two pins coincide (projected spacing shrinks towards the rim, but stays well apart).
    differences = sensor.pin_rest_mm[:, None, :] - sensor.pin_rest_mm[None, :, :]
    distances = np.linalg.norm(differences, axis=-1)
    assert distances[~np.eye(pins, dtype=bool)].min() > config.marker_radius_mm


@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_pins_lie_within_the_dome(preset):
    config = sensor_preset(preset)
    sensor = TacTip(config)
    radial = np.hypot(*sensor.pin_rest_mm.T)
    assert radial.max() < config.dome_diameter_mm / 2
    assert radial.min() == 0.0  # the central pin
    assert radial.max() > 0.8 * config.dome_diameter_mm / 2  # the pattern fills the dome


def test_pins_fit_in_the_crop_box(tactip):
    config = tactip.config
    cx, cy = config.image_centre_px
    x0, y0, x1, y1 = config.processing.crop_px
    px = cx - config.px_per_mm * tactip.pin_rest_mm[:, 1]
    py = cy + config.px_per_mm * tactip.pin_rest_mm[:, 0]
    assert (px > x0).all() and (px < x1).all() and (py > y0).all() and (py < y1).all()


def test_no_contact_gives_zero_indentation_and_displacement(tactip, surface, layout):
    x, y = layout.centre_mm("A")
    indentation = tactip.indentation_mm(surface, x, y, NO_CONTACT)
    assert indentation.shape == (tactip.grid_px, tactip.grid_px)
    assert (indentation == 0).all()
    np.testing.assert_array_equal(tactip.pin_displacement_mm(indentation), 0.0)


@pytest.mark.parametrize("key", ["A", "SPACE", "UP"])
def test_pressing_on_a_key_indents_and_moves_pins(tactip, surface, layout, key):
    x, y = layout.centre_mm(key)
    indentation = tactip.indentation_mm(surface, x, y, PRESS)
    # The flat key top alone indents the apex by 1.5 mm; relief off the apex adds up to 0.5 mm.
    if key == "SPACE":
        assert indentation.max() == pytest.approx(1.5, abs=0.02)
    else:
        assert 1.6 < indentation.max() <= 2.0
    displacement = tactip.pin_displacement_mm(indentation)
    assert displacement.shape == (331, 2)
    assert np.linalg.norm(displacement, axis=1).max() > 0.1


def test_deeper_press_indents_more(tactip, surface, layout):
    x, y = layout.centre_mm("SPACE")
    shallow = tactip.indentation_mm(surface, x, y, -0.5)
    deep = tactip.indentation_mm(surface, x, y, -2.0)
    assert deep.sum() > shallow.sum() > 0
    assert (deep >= shallow).all()


def test_pushed_down_key_indents_less(tactip, surface, layout):
    x, y = layout.centre_mm("SPACE")
    index = layout.key("SPACE").index
    resting = tactip.indentation_mm(surface, x, y, PRESS)
    pushed = tactip.indentation_mm(surface, x, y, PRESS, key_descent_mm={index: 1.0})
    assert pushed.max() == pytest.approx(resting.max() - 1.0, abs=1e-3)


def test_letter_relief_moves_pins_near_its_dots(tactip, surface, layout):
    """A's single dot (dot 1, keycap (-2.5, +1.25)) moves the pins around it, compared with a blank key."""
    a = tactip.pin_displacement_mm(tactip.indentation_mm(surface, *layout.centre_mm("A"), PRESS))
    blank = tactip.pin_displacement_mm(tactip.indentation_mm(surface, *layout.centre_mm("SPACE"), PRESS))
    change = np.linalg.norm(a - blank, axis=1)
    centroid = (tactip.pin_rest_mm * change[:, None]).sum(axis=0) / change.sum()
    np.testing.assert_allclose(centroid, [-2.5, 1.25], atol=0.75)


def test_rendered_frame_shape_and_dtype(tactip, surface, layout):
    frame = tactip.render_frame(surface, *layout.centre_mm("A"), PRESS)
    assert frame.shape == (480, 640)
    assert frame.dtype == np.uint8
    # Bright pins on a dark background.
    assert frame.max() >= 200
    assert np.median(frame) < 60


def test_preset_127_renders(tactip_127, surface, layout):
    frame = tactip_127.render_frame(surface, *layout.centre_mm("A"), PRESS, rng=np.random.default_rng(0))
    assert frame.shape == (480, 640)
    assert frame.dtype == np.uint8


def test_noiseless_render_is_deterministic(tactip, surface, layout):
    x, y = layout.centre_mm("K")
    first = tactip.render_frame(surface, x, y, PRESS, rng=None)
    second = tactip.render_frame(surface, x, y, PRESS)
    np.testing.assert_array_equal(first, second)


def test_same_seed_same_frame_different_seed_different_frame(tactip, surface, layout):
    x, y = layout.centre_mm("K")
    a = tactip.render_frame(surface, x, y, PRESS, rng=np.random.default_rng(7))
    b = tactip.render_frame(surface, x, y, PRESS, rng=np.random.default_rng(7))
    c = tactip.render_frame(surface, x, y, PRESS, rng=np.random.default_rng(8))
    clean = tactip.render_frame(surface, x, y, PRESS)
    np.testing.assert_array_equal(a, b)
    assert (a != c).sum() > 1000
    assert (a != clean).sum() > 1000


def test_noise_free_nuisance_matches_noiseless_render(surface, layout):
    quiet = TacTip(
        TacTipConfig(
            nuisance=Nuisance(pixel_noise_std=0, lighting_gain_std=0, position_jitter_mm=0, yaw_jitter_deg=0)
        )
    )
    x, y = layout.centre_mm("K")
    np.testing.assert_array_equal(
        quiet.render_frame(surface, x, y, PRESS, rng=np.random.default_rng(3)),
        quiet.render_frame(surface, x, y, PRESS),
    )


def test_observation_is_binary_100x100(tactip, surface, layout):
    observation = tactip.observe(surface, *layout.centre_mm("A"), PRESS, rng=np.random.default_rng(0))
    assert observation.shape == (100, 100)
    assert observation.dtype == np.uint8
    assert set(np.unique(observation).tolist()) == {0, 255}
    # Roughly one blob per pin: a sizeable but minority share of white pixels.
    assert 0.03 < (observation == 255).mean() < 0.5


@pytest.mark.parametrize(("first", "second"), [("A", "B"), ("A", "SPACE"), ("L", "W"), ("UP", "DOWN")])
def test_different_keys_give_different_observations(tactip, surface, layout, first, second):
    a = tactip.observe(surface, *layout.centre_mm(first), PRESS)
    b = tactip.observe(surface, *layout.centre_mm(second), PRESS)
    assert (a != b).sum() > 10


def test_same_key_gives_same_noiseless_observation(tactip, surface, layout):
    a = tactip.observe(surface, *layout.centre_mm("A"), PRESS)
    b = tactip.observe(surface, *layout.centre_mm("A"), PRESS)
    np.testing.assert_array_equal(a, b)


def test_space_deforms_the_sensor(tactip, surface, layout):
    x, y = layout.centre_mm("SPACE")
    touching = tactip.observe(surface, x, y, PRESS)
    free = tactip.observe(surface, x, y, NO_CONTACT)
    assert (touching != free).sum() > 200


def test_no_contact_frame_is_the_same_over_any_key(tactip, surface, layout):
    a = tactip.render_frame(surface, *layout.centre_mm("A"), NO_CONTACT)
    b = tactip.render_frame(surface, *layout.centre_mm("UP"), NO_CONTACT)
    np.testing.assert_array_equal(a, b)


def test_braille_reads_upright_in_the_image(tactip, surface, layout):
    """Dot 1 (top-left of the cell) shows up in the top-left quadrant of the image at yaw 0."""
    a = tactip.render_frame(surface, *layout.centre_mm("A"), PRESS).astype(int)
    blank = tactip.render_frame(surface, *layout.centre_mm("SPACE"), PRESS).astype(int)
    rows, cols = np.nonzero(np.abs(a - blank) > 50)
    cx, cy = tactip.config.image_centre_px
    assert rows.size > 0
    assert rows.mean() < cy - 10
    assert cols.mean() < cx - 5


@pytest.mark.parametrize(
    ("key", "direction"), [("UP", (-1, 0)), ("DOWN", (1, 0)), ("LEFT", (0, -1)), ("RIGHT", (0, 1))]
)
def test_arrows_point_their_way_in_the_image(tactip, surface, layout, key, direction):
    """The arrow's head (where the relief concentrates) lies towards its direction in (row, column)."""
    arrow = tactip.render_frame(surface, *layout.centre_mm(key), PRESS).astype(int)
    blank = tactip.render_frame(surface, *layout.centre_mm("SPACE"), PRESS).astype(int)
    rows, cols = np.nonzero(np.abs(arrow - blank) > 50)
    cx, cy = tactip.config.image_centre_px
    offset = np.array([rows.mean() - cy, cols.mean() - cx])
    assert np.dot(offset, direction) > 4.0
    assert abs(offset[1 - int(np.argmax(np.abs(direction)))]) < 3.0


def test_yaw_rotates_what_the_sensor_sees(tactip, surface, layout):
    x, y = layout.centre_mm("A")
    straight = tactip.observe(surface, x, y, PRESS, yaw_deg=0.0)
    turned = tactip.observe(surface, x, y, PRESS, yaw_deg=30.0)
    assert (straight != turned).sum() > 10


def test_grid_too_small_raises():
    with pytest.raises(ValueError, match="grid_px"):
        TacTip(grid_px=8)


def test_sensor_preset_lookup_and_overrides():
    assert sensor_preset("braille_331") is PRESETS["braille_331"]
    assert sensor_preset("tactip_127").name == "tactip_127"
    tuned = sensor_preset("braille_331", pin_rings=5)
    assert tuned.pin_rings == 5
    assert tuned.pin_count == 91
    assert PRESETS["braille_331"].pin_rings == 10  # the preset itself is unchanged


def test_unknown_sensor_preset_raises():
    with pytest.raises(ValueError, match="unknown sensor preset 'gelsight'") as info:
        sensor_preset("gelsight")
    assert "braille_331" in str(info.value) and "tactip_127" in str(info.value)


def test_dome_geometry():
    config = TacTipConfig()
    # A 25 mm wide, 7.2 mm deep cap is cut from a sphere of radius (12.5^2 + 7.2^2) / 14.4.
    assert config.dome_radius_mm == pytest.approx((12.5**2 + 7.2**2) / 14.4)
    assert config.dome_height_mm(0.0) == 0.0
    assert config.dome_height_mm(12.5) == pytest.approx(7.2)
    assert config.px_per_mm == pytest.approx(195.0 / 12.5)
    assert config.image_centre_px == (310.0, 240.0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"pin_rings": 0}, "pin_rings"),
        ({"pin_radius_mm": 0.0}, "pin_radius_mm"),
        ({"marker_radius_mm": 0.0}, "marker_radius_mm"),
        ({"marker_radius_mm": 1.0}, "marker_radius_mm cannot exceed"),
        ({"dome_depth_mm": 13.0}, "hemisphere"),
        ({"image_radius_px": -1.0}, "image_radius_px"),
        ({"camera_px": (400, 300)}, "does not fit"),
        ({"processing": ImageProcessing(crop_px=(110, 40, 700, 440))}, "does not fit"),
    ],
)
def test_config_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        TacTipConfig(**kwargs)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"pixel_noise_std": -1.0},
        {"lighting_gain_std": -0.1},
        {"position_jitter_mm": -0.1},
        {"yaw_jitter_deg": float("nan")},
    ],
)
def test_nuisance_validation(kwargs):
    with pytest.raises(ValueError):
        Nuisance(**kwargs)


def test_even_threshold_block_raises():
    with pytest.raises(ValueError, match="threshold_block_px"):
        TacTipConfig(processing=ImageProcessing(threshold_block_px=12))
