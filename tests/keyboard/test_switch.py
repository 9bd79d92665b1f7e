"""The tap-to-actuation switch model."""

from __future__ import annotations

import dataclasses
import itertools
import json

import numpy as np
import pytest

from tactile_braille.keyboard.layout import ALL_TASK_KEYS, ALPHABET_KEYS
from tactile_braille.keyboard.switch import FITTED_TRAVEL_OFFSETS_MM, SwitchModel


def _pressed(switch, layout, x, y, depth):
    x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
    return switch.pressed_key_index(layout, x, y, np.full(x.shape, depth, dtype=float))


def _name(layout, index):
    return None if index < 0 else layout.keys[int(index)].name


@pytest.mark.parametrize("key", ALL_TASK_KEYS)
def test_shallow_tap_at_key_top_presses_nothing(layout, switch, key):
    x, y = layout.centre_mm(key)
    assert _pressed(switch, layout, x, y, 3.5) == -1  # just touching the key top


@pytest.mark.parametrize("key", ALL_TASK_KEYS)
def test_deep_tap_at_key_centre_presses_that_key(layout, switch, key):
    x, y = layout.centre_mm(key)
    assert _name(layout, _pressed(switch, layout, x, y, 8.0)) == key


def test_no_press_anywhere_short_of_the_actuation_travel(layout, switch):
    """Nothing registers until the dome has pushed a key by more than its actuation travel."""
    x_min, x_max, y_min, y_max = layout.bounds_mm
    rng = np.random.default_rng(1)
    x = rng.uniform(x_min, x_max, 5000)
    y = rng.uniform(y_min, y_max, 5000)
    earliest = switch.actuation_travel_mm - switch.travel_offsets(layout).max()
    depth = switch.clearance_mm + earliest - 0.05
    assert (_pressed(switch, layout, x, y, depth) == -1).all()
    assert (_pressed(switch, layout, x, y, 0.0) == -1).all()


@pytest.mark.parametrize("key", ["G", "Q", "T", "UP"])  # offsets -0.2, +0.25, -0.45 and none
def test_centre_press_starts_just_past_the_keys_own_travel(layout, switch, key):
    x, y = layout.centre_mm(key)
    offset = dict(switch.travel_offsets_mm).get(key, 0.0)
    onset = switch.clearance_mm + switch.actuation_travel_mm - offset
    assert _pressed(switch, layout, x, y, onset - 0.01) == -1
    assert _name(layout, _pressed(switch, layout, x, y, onset + 0.01)) == key


def test_fitted_offsets_name_alphabet_keys_within_the_switch_tolerance():
    offsets = dict(FITTED_TRAVEL_OFFSETS_MM)
    assert offsets, "the calibrated model carries per-key offsets"
    assert set(offsets) <= set(ALPHABET_KEYS)
    assert all(0 < abs(value) <= 0.5 for value in offsets.values())
    assert SwitchModel().travel_offsets_mm == FITTED_TRAVEL_OFFSETS_MM


def test_an_offset_moves_only_its_own_key(layout):
    level = SwitchModel(travel_offsets_mm=())
    shifted = SwitchModel(travel_offsets_mm={"H": 0.3})
    rng = np.random.default_rng(3)
    x = rng.uniform(-10, 50, 2000)
    y = rng.uniform(-200, 10, 2000)
    depth = rng.uniform(4.0, 9.0, 2000)
    before = level.actuation_margin_mm(layout, x, y, depth)
    after = shifted.actuation_margin_mm(layout, x, y, depth)
    reachable = np.isfinite(before)
    assert np.array_equal(reachable, np.isfinite(after))
    moved = np.zeros(len(layout))
    moved[layout.key("H").index] = 0.3
    assert reachable[:, layout.key("H").index].any()
    assert np.allclose((after - moved)[reachable], before[reachable])


def test_offsets_given_as_mapping_or_pairs_are_the_same_model():
    assert SwitchModel(travel_offsets_mm={"A": 0.1, "B": -0.2}) == SwitchModel(
        travel_offsets_mm=(("A", 0.1), ("B", -0.2))
    )
    # as a JSON round trip of the rig's description gives them back
    assert SwitchModel(travel_offsets_mm=[["A", 0.1]]).travel_offsets_mm == (("A", 0.1),)


def test_switch_rebuilds_from_its_stored_description():
    switch = SwitchModel()
    stored = json.loads(json.dumps(dataclasses.asdict(switch)))
    assert SwitchModel(**stored) == switch


@pytest.mark.parametrize(
    ("offsets", "message"),
    [
        ({"A": 0.7}, "within"),
        ({"A": -0.61}, "within"),
        ((("A", 0.1), ("A", 0.2)), "names A more than once"),
        ({"NOT_A_KEY": 0.1}, "does not have"),
        ("AB", "pairs"),
        ([("A", "deep")], "pairs"),
        ({"A": float("nan")}, "within"),
    ],
)
def test_invalid_travel_offsets_raise(offsets, message):
    with pytest.raises(ValueError, match=message):
        SwitchModel(travel_offsets_mm=offsets)


def test_offsets_have_one_spelling():
    """Order and explicit zeros do not make another switch (a run's world compares them)."""
    assert SwitchModel(travel_offsets_mm={"B": -0.2, "A": 0.1, "C": 0.0}) == SwitchModel(
        travel_offsets_mm=(("A", 0.1), ("B", -0.2))
    )
    assert SwitchModel(travel_offsets_mm=(pair for pair in [("A", 0.1)])).travel_offsets_mm == (("A", 0.1),)


def test_an_offset_cannot_make_a_key_register_before_it_is_touched():
    with pytest.raises(ValueError, match="less than actuation_travel_mm"):
        SwitchModel(actuation_travel_mm=0.3, travel_offsets_mm={"A": 0.4})


def test_monotone_in_depth_on_random_positions(layout, switch):
    """Once a tap at (x, y) presses a key at depth d, every deeper tap presses the same key."""
    rng = np.random.default_rng(1234)
    gx, gy = layout.centre_mm("G")
    x = rng.uniform(gx - 40, gx + 40, 400)
    y = rng.uniform(gy - 120, gy + 120, 400)
    depths = np.arange(3.0, 10.01, 0.25)
    presses = np.stack([_pressed(switch, layout, x, y, d) for d in depths])  # (n_depths, n_points)
    assert (presses >= 0).any() and (presses < 0).any()
    for j in range(presses.shape[1]):
        column = presses[:, j]
        pressed = np.flatnonzero(column >= 0)
        if pressed.size:
            first = pressed[0]
            assert (column[first:] == column[first]).all(), (x[j], y[j], column)


@pytest.mark.parametrize(("left", "right"), [("G", "H"), ("Q", "W"), ("Z", "X"), ("K", "L"), ("O", "P")])
@pytest.mark.parametrize("depth", [5.5, 6.0, 6.5, 7.0, 8.0])
def test_between_two_keys_presses_nothing_or_a_neighbour(layout, switch, left, right, depth):
    (x0, y0), (x1, y1) = layout.centre_mm(left), layout.centre_mm(right)
    for t in np.linspace(0.3, 0.7, 9):
        index = _pressed(switch, layout, x0 + t * (x1 - x0), y0 + t * (y1 - y0), depth)
        assert _name(layout, index) in (None, left, right)


def test_tap_in_the_gap_does_not_press_at_moderate_depth(layout, switch):
    gx, gy = layout.centre_mm("G")
    assert _pressed(switch, layout, gx, gy - 9.5, 5.5) == -1


def _footprint(layout, switch, key, depth):
    cx, cy = layout.centre_mm(key)
    x, y = np.meshgrid(np.linspace(cx - 12, cx + 12, 49), np.linspace(cy - 12, cy + 12, 49), indexing="ij")
    return _pressed(switch, layout, x, y, depth) == layout.key(key).index


@pytest.mark.parametrize("key", ["G", "A", "UP"])
def test_footprint_grows_with_depth(layout, switch, key):
    depths = [5.5, 6.0, 6.5, 7.0, 8.0]
    footprints = [_footprint(layout, switch, key, d) for d in depths]
    areas = [int(f.sum()) for f in footprints]
    assert areas[0] > 0
    assert all(a < b for a, b in itertools.pairwise(areas)), areas
    # Nested: every position that actuates at a shallow depth also actuates deeper.
    for shallow, deep in itertools.pairwise(footprints):
        assert not (shallow & ~deep).any()


def test_deep_footprint_covers_most_of_the_key_but_stays_on_it(layout, switch):
    area_per_cell = (24 / 48) ** 2
    area = _footprint(layout, switch, "G", 10.0).sum() * area_per_cell
    assert 0.6 * 19 * 19 < area <= 1.1 * 19 * 19


def test_arrays_broadcast_and_shape(layout, switch):
    x = np.zeros((3, 4))
    y = np.zeros((3, 4))
    depth = np.full((3, 4), 8.0)
    assert switch.pressed_key_index(layout, x, y, depth).shape == (3, 4)
    assert switch.actuation_margin_mm(layout, x, y, depth).shape == (3, 4, len(layout))
    assert switch.distance_to_key_tops_mm(layout, x, y).shape == (3, 4, len(layout))


def test_margin_is_minus_inf_out_of_reach(layout, switch):
    margin = switch.actuation_margin_mm(layout, np.array(0.0), np.array(0.0), np.array(8.0))
    p_index = layout.key("P").index
    q_index = layout.key("Q").index
    assert margin[p_index] == -np.inf
    assert np.isfinite(margin[q_index]) and margin[q_index] > 0


def test_distance_to_key_top_is_zero_at_centre(layout, switch):
    x, y = layout.centre_mm("F")
    distance = switch.distance_to_key_tops_mm(layout, np.array(x), np.array(y))
    assert distance[layout.key("F").index] == 0.0
    assert distance[layout.key("G").index] > 0.0


def test_deeper_clearance_needs_deeper_tap(layout):
    x, y = layout.centre_mm("A")
    high = SwitchModel(clearance_mm=5.0)
    assert _pressed(high, layout, x, y, 6.0) == -1
    assert _name(layout, _pressed(SwitchModel(), layout, x, y, 6.0)) == "A"


@pytest.mark.parametrize(
    "kwargs",
    [
        {"dome_radius_mm": 0.0},
        {"dome_contact_radius_mm": -1.0},
        {"actuation_travel_mm": 0.0},
        {"dome_contact_radius_mm": 20.0},  # exceeds the dome radius
        {"stabiliser_fraction": 1.5},
        {"stabiliser_fraction": -0.1},
        {"keycap_top_inset_x_mm": -1.0},
        {"keycap_top_inset_y_mm": -1.0},
        {"keycap_corner_radius_mm": -1.0},
        {"rocking_x": -0.1},
        {"rocking_y": -0.1},
        {"rocking_exponent": -1.0},
        {"dome_radius_mm": float("nan")},
    ],
)
def test_invalid_parameters_raise(kwargs):
    with pytest.raises(ValueError):
        SwitchModel(**kwargs)
