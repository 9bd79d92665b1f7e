"""Braille cells, arrow shapes and relief heights on the keycaps."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_braille.keyboard.braille import (
    BRAILLE_DOTS,
    BrailleGeometry,
    arrow_segments_mm,
    dot_positions_mm,
    relief_height_mm,
)
from tactile_braille.keyboard.layout import ARROW_KEYS

# Standard grade-1 braille alphabet (dots numbered 1-2-3 down the left column, 4-5-6 down the right).
STANDARD_BRAILLE = {
    "A": {1},
    "B": {1, 2},
    "C": {1, 4},
    "D": {1, 4, 5},
    "E": {1, 5},
    "F": {1, 2, 4},
    "G": {1, 2, 4, 5},
    "H": {1, 2, 5},
    "I": {2, 4},
    "J": {2, 4, 5},
    "K": {1, 3},
    "L": {1, 2, 3},
    "M": {1, 3, 4},
    "N": {1, 3, 4, 5},
    "O": {1, 3, 5},
    "P": {1, 2, 3, 4},
    "Q": {1, 2, 3, 4, 5},
    "R": {1, 2, 3, 5},
    "S": {2, 3, 4},
    "T": {2, 3, 4, 5},
    "U": {1, 3, 6},
    "V": {1, 2, 3, 6},
    "W": {2, 4, 5, 6},
    "X": {1, 3, 4, 6},
    "Y": {1, 3, 4, 5, 6},
    "Z": {1, 3, 5, 6},
}

# Dot centres (x down the cell, y to the reader's left) for the default 2.5 mm pitch.
DOT_CENTRES = {
    1: (-2.5, 1.25),
    2: (0.0, 1.25),
    3: (2.5, 1.25),
    4: (-2.5, -1.25),
    5: (0.0, -1.25),
    6: (2.5, -1.25),
}


@pytest.mark.parametrize("letter", sorted(STANDARD_BRAILLE))
def test_letters_match_standard_braille(letter):
    assert set(BRAILLE_DOTS[letter]) == STANDARD_BRAILLE[letter]


def test_all_26_letters_present_and_distinct():
    assert sorted(BRAILLE_DOTS) == list("ABCDEFGHIJKLMNOPQRSTUVWXYZ")
    cells = {frozenset(dots) for dots in BRAILLE_DOTS.values()}
    assert len(cells) == 26
    for dots in BRAILLE_DOTS.values():
        assert set(dots) <= set(range(1, 7))
        assert len(dots) == len(set(dots))


@pytest.mark.parametrize("letter", sorted(STANDARD_BRAILLE))
def test_dot_positions(letter):
    positions = dot_positions_mm(letter)
    expected = np.array([DOT_CENTRES[d] for d in BRAILLE_DOTS[letter]])
    np.testing.assert_allclose(positions, expected)


def test_dot_one_is_top_left():
    np.testing.assert_allclose(dot_positions_mm("A"), [[-2.5, 1.25]])


def test_lowercase_letter_accepted():
    np.testing.assert_allclose(dot_positions_mm("l"), dot_positions_mm("L"))


def test_dot_pitch_scales_positions():
    positions = dot_positions_mm("Y", BrailleGeometry(dot_pitch_mm=3.0))
    expected = np.array([DOT_CENTRES[d] for d in BRAILLE_DOTS["Y"]]) * 3.0 / 2.5
    np.testing.assert_allclose(positions, expected)


@pytest.mark.parametrize("name", ["SPACE", "1", "", "UP"])
def test_dot_positions_of_non_letter_raises(name):
    with pytest.raises(ValueError, match="letters A-Z"):
        dot_positions_mm(name)


@pytest.mark.parametrize("letter", sorted(STANDARD_BRAILLE))
def test_relief_is_dot_height_at_each_dot_centre(letter):
    x, y = dot_positions_mm(letter).T
    np.testing.assert_allclose(relief_height_mm(letter, x, y), 0.5)


@pytest.mark.parametrize("letter", sorted(STANDARD_BRAILLE))
def test_relief_is_zero_at_absent_dots(letter):
    absent = [DOT_CENTRES[d] for d in range(1, 7) if d not in BRAILLE_DOTS[letter]]
    if not absent:
        pytest.skip("every dot raised")
    x, y = np.array(absent).T
    np.testing.assert_array_equal(relief_height_mm(letter, x, y), 0.0)


def test_relief_zero_between_dots_and_off_the_cell():
    # L has dots 1, 2, 3 (the whole left column); halfway between dots 1 and 2 is flat.
    assert relief_height_mm("L", -1.25, 1.25) == 0.0
    assert relief_height_mm("L", 0.0, 0.0) == 0.0
    assert relief_height_mm("L", 6.0, 6.0) == 0.0


def test_dot_is_a_cap_decreasing_to_zero_at_its_base():
    r = np.linspace(0.0, 1.0, 41)
    heights = relief_height_mm("A", -2.5 + r, np.full_like(r, 1.25))
    assert heights[0] == pytest.approx(0.5)
    assert np.all(np.diff(heights) <= 1e-12)
    assert heights[r >= 0.75].max() == 0.0  # base diameter 1.5 mm
    assert heights[r < 0.7].min() > 0.0


def test_relief_broadcasts():
    x = np.linspace(-4, 4, 9)[:, None]
    y = np.linspace(-4, 4, 5)[None, :]
    assert relief_height_mm("Q", x, y).shape == (9, 5)


def test_custom_dot_height():
    geometry = BrailleGeometry(dot_height_mm=0.8)
    assert relief_height_mm("A", -2.5, 1.25, geometry) == pytest.approx(0.8)


@pytest.mark.parametrize("key", ["SPACE", "ENTER", "1", "Q2"])
def test_keys_without_relief_are_flat(key):
    x, y = np.meshgrid(np.linspace(-8, 8, 65), np.linspace(-8, 8, 65))
    np.testing.assert_array_equal(relief_height_mm(key, x, y), 0.0)


@pytest.mark.parametrize("key", ARROW_KEYS)
def test_arrows_have_relief_on_their_ridges(key):
    segments = arrow_segments_mm(key)
    assert segments.shape == (3, 4)
    for x0, y0, x1, y1 in segments:
        for t in (0.0, 0.5, 1.0):
            assert relief_height_mm(key, x0 + t * (x1 - x0), y0 + t * (y1 - y0)) == pytest.approx(0.5)


def _field(key):
    x, y = np.meshgrid(np.linspace(-5, 5, 81), np.linspace(-5, 5, 81), indexing="ij")
    return x, y, relief_height_mm(key, x, y)


def test_four_arrows_differ():
    fields = {key: _field(key)[2] for key in ARROW_KEYS}
    for a in ARROW_KEYS:
        assert fields[a].max() == pytest.approx(0.5, abs=0.01)
        for b in ARROW_KEYS:
            if a < b:
                assert np.abs(fields[a] - fields[b]).max() > 0.4, (a, b)


@pytest.mark.parametrize(
    ("key", "tip"),
    # UP points away from the typist (-x), DOWN towards (+x), LEFT to the typist's left (+y).
    [("UP", (-3.5, 0.0)), ("DOWN", (3.5, 0.0)), ("LEFT", (0.0, 3.5)), ("RIGHT", (0.0, -3.5))],
)
def test_arrow_points_in_its_direction(key, tip):
    segments = arrow_segments_mm(key)
    # The two chevron strokes start at the tip.
    np.testing.assert_allclose(segments[1, :2], tip, atol=1e-9)
    np.testing.assert_allclose(segments[2, :2], tip, atol=1e-9)
    # The head is closer to the tip than the tail: the chevron ends lie between tip and centre.
    for end in (segments[1, 2:], segments[2, 2:]):
        assert np.dot(end, tip) > 0


@pytest.mark.parametrize(("key", "quarter_turns"), [("LEFT", 1), ("DOWN", 2), ("RIGHT", 3)])
def test_arrows_are_rotations_of_up(key, quarter_turns):
    """On a square grid symmetric about 0, a 90 degree rotation of the points is a rot90 of the array."""
    _, _, up = _field("UP")
    _, _, rotated = _field(key)
    # relief_key(p) = relief_up(R^-1 p): rotating by +90 deg (x -> y) each quarter turn for LEFT.
    expected = np.rot90(up, k=-quarter_turns)
    np.testing.assert_allclose(rotated, expected, atol=1e-9)


def test_arrow_segments_of_non_arrow_raises():
    with pytest.raises(ValueError, match="not an arrow key"):
        arrow_segments_mm("A")


@pytest.mark.parametrize("field", ["dot_base_diameter_mm", "dot_height_mm", "dot_pitch_mm", "ridge_width_mm"])
@pytest.mark.parametrize("value", [0.0, -1.0])
def test_geometry_validation(field, value):
    with pytest.raises(ValueError, match=field):
        BrailleGeometry(**{field: value})
