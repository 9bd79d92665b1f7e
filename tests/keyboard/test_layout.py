"""Key geometry of the 84-key ANSI layout in the keyboard frame."""

from __future__ import annotations

import itertools

import pytest

from tactile_braille.keyboard.layout import (
    ALL_TASK_KEYS,
    ALPHABET_KEYS,
    ARROW_KEYS,
    KEY_PITCH_MM,
    KeyboardLayout,
    key_set,
)


def test_has_84_unique_keys(layout):
    assert len(layout) == 84
    names = [key.name for key in layout.keys]
    assert len(set(names)) == 84
    assert [key.index for key in layout.keys] == list(range(84))
    assert layout.centres_mm.shape == (84, 2)


@pytest.mark.parametrize(
    ("name", "centre"),
    [
        ("Q", (0.0, 0.0)),
        ("W", (0.0, -19.0)),
        ("P", (0.0, -171.0)),
        ("A", (19.0, -4.75)),
        ("Z", (38.0, -14.25)),
        ("UP", (38.0, -237.5)),
        ("DOWN", (57.0, -237.5)),
        ("LEFT", (57.0, -218.5)),
        ("RIGHT", (57.0, -256.5)),
    ],
)
def test_key_centres_match_the_papers_rig(layout, name, centre):
    assert layout.centre_mm(name) == pytest.approx(centre, abs=1e-9)


def test_space_bar_is_on_the_bottom_row_close_to_the_papers_centre(layout):
    x, y = layout.centre_mm("SPACE")
    assert x == pytest.approx(57.0)
    assert y == pytest.approx(-92.5, abs=0.2)
    assert layout.key("SPACE").width_u == 6.25


def test_rows_are_one_pitch_apart_in_x(layout):
    for row_letters, x in (("QWERTYUIOP", 0.0), ("ASDFGHJKL", 19.0), ("ZXCVBNM", 38.0)):
        for letter in row_letters:
            assert layout.centre_mm(letter)[0] == pytest.approx(x)


@pytest.mark.parametrize(("row", "stagger"), [("QWERTYUIOP", 0.0), ("ASDFGHJKL", 4.75), ("ZXCVBNM", 14.25)])
def test_ansi_row_stagger(layout, row, stagger):
    """Each letter row is shifted along y by the ANSI stagger, keys one pitch apart."""
    for i, letter in enumerate(row):
        assert layout.centre_mm(letter)[1] == pytest.approx(-(i * KEY_PITCH_MM + stagger))


def test_a_and_z_rows_staggered_relative_to_q_row(layout):
    assert layout.centre_mm("Q")[1] - layout.centre_mm("A")[1] == pytest.approx(4.75)
    assert layout.centre_mm("Q")[1] - layout.centre_mm("Z")[1] == pytest.approx(14.25)


def test_neighbouring_keys_do_not_overlap(layout):
    """Within a row the key cells tile the row: centre distance = sum of half widths."""
    for row in range(6):
        keys = sorted((k for k in layout.keys if k.row == row), key=lambda k: -k.centre_y_mm)
        for left, right in itertools.pairwise(keys):
            gap = left.centre_y_mm - right.centre_y_mm
            assert gap == pytest.approx((left.width_u + right.width_u) / 2 * KEY_PITCH_MM)


def test_unknown_key_raises_key_error_listing_valid_keys(layout):
    with pytest.raises(KeyError, match="unknown key 'KEY_A'") as info:
        layout.key("KEY_A")
    message = str(info.value)
    assert "valid keys" in message
    for name in ("Q", "SPACE", "LEFT", "ESC"):
        assert name in message
    with pytest.raises(KeyError):
        layout.centre_mm("a")  # names are case-sensitive


def test_membership(layout):
    assert "SPACE" in layout
    assert "ENTER" in layout
    assert "NOPE" not in layout


def test_key_footprint(layout):
    assert layout.key("Q").footprint_mm == pytest.approx((19.0, 19.0))
    assert layout.key("SPACE").footprint_mm == pytest.approx((19.0, 6.25 * 19.0))


def test_bounds_contain_all_key_centres(layout):
    x_min, x_max, y_min, y_max = layout.bounds_mm
    assert x_min == pytest.approx(-2 * 19.0 - 9.5)
    assert x_max == pytest.approx(3 * 19.0 + 9.5)
    # Rows are 16 u long, starting 2 u to the left of the Q centre.
    assert y_max == pytest.approx(2 * 19.0)
    assert y_min == pytest.approx(-14 * 19.0)
    centres = layout.centres_mm
    assert (centres[:, 0] > x_min).all() and (centres[:, 0] < x_max).all()
    assert (centres[:, 1] > y_min).all() and (centres[:, 1] < y_max).all()


def test_pitch_scales_the_layout():
    small = KeyboardLayout(pitch_mm=18.0)
    assert small.centre_mm("P") == pytest.approx((0.0, -162.0))
    assert small.centre_mm("A") == pytest.approx((18.0, -4.5))


@pytest.mark.parametrize("pitch", [0.0, -19.0, float("nan")])
def test_invalid_pitch_raises(pitch):
    with pytest.raises(ValueError, match="pitch_mm"):
        KeyboardLayout(pitch_mm=pitch)


def test_key_sets():
    assert key_set("arrows") == ("UP", "DOWN", "LEFT", "RIGHT") == ARROW_KEYS
    assert key_set("alphabet") == ALPHABET_KEYS
    assert len(ALPHABET_KEYS) == 27
    assert ALPHABET_KEYS[:26] == tuple("ABCDEFGHIJKLMNOPQRSTUVWXYZ")
    assert ALPHABET_KEYS[-1] == "SPACE"
    assert key_set("all") == ALL_TASK_KEYS == ALPHABET_KEYS + ARROW_KEYS
    assert len(ALL_TASK_KEYS) == 31


def test_all_task_keys_exist_in_layout(layout):
    for name in ALL_TASK_KEYS:
        assert name in layout


def test_unknown_key_set_raises_with_choices():
    with pytest.raises(ValueError, match="unknown key set 'digits'") as info:
        key_set("digits")
    for name in ("alphabet", "arrows", "all"):
        assert name in str(info.value)
