"""Collection procedures: which taps a collection makes, independent of the rig."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from tactile_braille.datasets.procedures import NONE_TAP_OFFSET_MM, GridTaps, PerturbedTaps, TapSpec
from tactile_braille.keyboard.calibration import CALIBRATED_FRAMES, RIG_TAP_OFFSET_MM
from tactile_braille.keyboard.layout import ALL_TASK_KEYS, ARROW_KEYS, NONE_KEY, KeyboardLayout
from tactile_braille.rigs.virtual import VirtualRig


@pytest.fixture(scope="module")
def kb() -> KeyboardLayout:
    return KeyboardLayout()


def all_taps(procedure, layout) -> list[TapSpec]:
    return [procedure.tap(i, layout) for i in range(len(procedure))]


# --- PerturbedTaps -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("keys", "per_key", "include_none", "expected"),
    [
        ("arrows", 3, True, (4 + 1) * 3),
        ("arrows", 3, False, 4 * 3),
        ("alphabet", 2, True, (27 + 1) * 2),
        ("all", 100, True, (31 + 1) * 100),
        ("all", 50, True, 1600),
    ],
)
def test_perturbed_length_is_classes_times_per_key(keys, per_key, include_none, expected):
    procedure = PerturbedTaps(keys=keys, per_key=per_key, include_none=include_none)
    assert len(procedure) == expected
    assert len(procedure.labels) * per_key == expected


def test_perturbed_labels_are_the_key_set_then_none():
    assert PerturbedTaps(keys="arrows").labels == (*ARROW_KEYS, NONE_KEY)
    assert PerturbedTaps(keys="all").labels == (*ALL_TASK_KEYS, NONE_KEY)
    assert PerturbedTaps(keys="arrows", include_none=False).labels == ARROW_KEYS


def test_perturbed_taps_are_grouped_by_label_and_indexed(kb):
    procedure = PerturbedTaps(keys="arrows", per_key=3)
    taps = all_taps(procedure, kb)
    assert [tap.index for tap in taps] == list(range(15))
    assert [tap.label for tap in taps] == [label for label in (*ARROW_KEYS, NONE_KEY) for _ in range(3)]


def test_perturbed_tap_is_deterministic_and_independent_of_order(kb):
    procedure = PerturbedTaps(keys="arrows", per_key=5)
    forward = all_taps(procedure, kb)
    backward = [procedure.tap(i, kb) for i in reversed(range(len(procedure)))][::-1]
    assert forward == backward
    # An equal procedure (e.g. rebuilt after a crash) gives the same taps.
    assert all_taps(PerturbedTaps(keys="arrows", per_key=5), kb) == forward


def test_perturbation_bounds_are_respected(kb):
    procedure = PerturbedTaps(keys="arrows", per_key=60)
    taps = all_taps(procedure, kb)
    q_x, q_y = kb.centre_mm("Q")
    dx, dy, depth, yaw = [], [], [], []
    for tap in taps:
        if tap.label == NONE_KEY:
            cx, cy = q_x + NONE_TAP_OFFSET_MM[0], q_y + NONE_TAP_OFFSET_MM[1]
        else:
            cx, cy = kb.centre_mm(tap.label)
        dx.append(tap.x_mm - cx)
        dy.append(tap.y_mm - cy)
        if tap.label == NONE_KEY:
            assert tap.depth_mm == 0.0  # NONE taps are made in the air
        else:
            depth.append(tap.depth_mm)
        yaw.append(tap.yaw_deg)
    dx, dy, depth, yaw = map(np.asarray, (dx, dy, depth, yaw))
    assert np.abs(dx).max() <= 1.0
    assert np.abs(dy).max() <= 1.0
    assert depth.min() >= 4.0
    assert depth.max() <= 5.0
    assert np.abs(yaw).max() <= 10.0
    # ... and the perturbations do fill their ranges (not all zero).
    assert np.abs(dx).max() > 0.8
    assert np.abs(dy).max() > 0.8
    assert depth.min() < 4.2
    assert depth.max() > 4.8
    assert np.abs(yaw).max() > 8.0
    assert len(np.unique(np.round(yaw, 9))) == procedure.per_key  # one draw per repetition


def test_perturbation_ranges_are_configurable(kb):
    procedure = PerturbedTaps(
        keys="arrows", per_key=40, depth_mm=6.0, position_range_mm=0.25, depth_range_mm=(-0.5, 0.5),
        yaw_range_deg=2.0,
    )  # fmt: skip
    taps = [tap for tap in all_taps(procedure, kb) if tap.label == "UP"]
    cx, cy = kb.centre_mm("UP")
    assert max(abs(tap.x_mm - cx) for tap in taps) <= 0.25
    assert max(abs(tap.y_mm - cy) for tap in taps) <= 0.25
    assert all(5.5 <= tap.depth_mm <= 6.5 for tap in taps)
    assert any(tap.depth_mm > 6.0 for tap in taps)
    assert max(abs(tap.yaw_deg) for tap in taps) <= 2.0


def test_none_taps_are_made_in_the_air_where_the_original_made_them(kb):
    procedure = PerturbedTaps(keys="arrows", per_key=4)
    q_x, q_y = kb.centre_mm("Q")
    none_taps = [tap for tap in all_taps(procedure, kb) if tap.label == NONE_KEY]
    assert len(none_taps) == 4
    for tap in none_taps:
        assert abs(tap.x_mm - (q_x - 20.0)) <= 1.0
        assert abs(tap.y_mm - (q_y - 20.0)) <= 1.0
        assert tap.depth_mm == 0.0


def test_none_taps_touch_nothing(kb):
    rig = VirtualRig(seed=None)
    procedure = PerturbedTaps(keys="arrows", per_key=2)
    air = rig.tap(0.0, 0.0, 0.0).frame
    for tap in all_taps(procedure, kb):
        if tap.label == NONE_KEY:
            sample = rig.tap(tap.x_mm, tap.y_mm, tap.depth_mm, 0.0)
            assert sample.pressed_key is None
            np.testing.assert_array_equal(sample.frame, air)


def test_every_key_gets_the_same_perturbation_list(kb):
    """As in the original release: the i-th repetition of every key is perturbed alike."""
    procedure = PerturbedTaps(keys="arrows", per_key=4)
    offsets = {}
    for tap in all_taps(procedure, kb):
        if tap.label == NONE_KEY:
            continue
        cx, cy = kb.centre_mm(tap.label)
        offsets.setdefault(tap.label, []).append((tap.x_mm - cx, tap.y_mm - cy, tap.depth_mm, tap.yaw_deg))
    reference = np.array(offsets["UP"])
    for label in ARROW_KEYS:
        np.testing.assert_allclose(np.array(offsets[label]), reference, atol=1e-9)


def test_splits_and_seeds_draw_different_perturbations(kb):
    train = all_taps(PerturbedTaps(keys="arrows", per_key=3, split="train"), kb)
    validation = all_taps(PerturbedTaps(keys="arrows", per_key=3, split="validation"), kb)
    reseeded = all_taps(PerturbedTaps(keys="arrows", per_key=3, seed=1), kb)
    assert [t.label for t in train] == [t.label for t in validation] == [t.label for t in reseeded]
    for other in (validation, reseeded):
        assert all(a.x_mm != b.x_mm and a.yaw_deg != b.yaw_deg for a, b in zip(train, other, strict=True))


@pytest.mark.parametrize("index", [-1, 15, 1000])
def test_perturbed_out_of_range_index_raises_index_error(kb, index):
    with pytest.raises(IndexError, match="out of range"):
        PerturbedTaps(keys="arrows", per_key=3).tap(index, kb)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"keys": "digits"}, "unknown key set"),
        ({"per_key": 0}, "per_key"),
        ({"per_key": -3}, "per_key"),
        ({"split": "test"}, "split"),
        ({"position_range_mm": -1.0}, "position_range_mm must be a bound >= 0, got -1.0"),
        ({"yaw_range_deg": float("nan")}, "yaw_range_deg must be a bound >= 0, got nan"),
        ({"depth_range_mm": (0.0, -1.0)}, r"depth_range_mm must be \(low, high\) with low <= high"),
    ],
)
def test_perturbed_invalid_arguments_raise_value_error(kwargs, match):
    with pytest.raises(ValueError, match=match):
        PerturbedTaps(**kwargs)


def test_perturbed_describe_is_json_and_complete():
    procedure = PerturbedTaps(keys="arrows", per_key=3, split="validation", seed=4)
    description = json.loads(json.dumps(procedure.describe()))
    assert description["procedure"] == "perturbed" == procedure.name
    assert description["keys"] == "arrows"
    assert description["per_key"] == 3
    assert description["split"] == "validation"
    assert description["seed"] == 4
    assert description["depth_range_mm"] == [-1.0, 0.0]
    assert description != PerturbedTaps(keys="arrows", per_key=3, split="validation", seed=5).describe()


# --- GridTaps ------------------------------------------------------------------------------------


def test_grid_defaults_are_the_papers():
    alphabet, arrows = GridTaps(keys="alphabet"), GridTaps(keys="arrows")
    assert len(alphabet) == 21 * 61 * 7 == 8967
    assert len(arrows) == 21 * 41 * 13 == 11193
    xs, ys, depths = alphabet.axes
    np.testing.assert_allclose(xs, np.arange(-30, 31, 3.0))
    np.testing.assert_allclose(ys, np.arange(-90, 91, 3.0))
    np.testing.assert_allclose(depths, np.arange(0, 7, 1.0))
    xs, ys, depths = arrows.axes
    np.testing.assert_allclose(xs, np.arange(-20, 1, 1.0))
    np.testing.assert_allclose(ys, np.arange(-20, 21, 1.0))
    np.testing.assert_allclose(depths, np.arange(0, 6.25, 0.5))
    assert GridTaps() == alphabet
    assert (arrows.spacing_mm, arrows.depth_step_mm) == (1.0, 0.5)
    assert (arrows.x_range_mm, arrows.y_range_mm) == ((-20.0, 0.0), (-20.0, 20.0))


def test_grid_order_is_x_outer_then_y_then_depth(kb):
    procedure = GridTaps(
        keys="arrows", spacing_mm=5, depth_step_mm=2, x_range_mm=(-10, 0), y_range_mm=(-5, 5)
    )
    assert len(procedure) == 3 * 3 * 4
    frame = CALIBRATED_FRAMES["arrows"]
    expected = [
        (x + frame.offset_x_mm, y + frame.offset_y_mm, depth + RIG_TAP_OFFSET_MM)
        for x, y, depth in itertools.product([-10.0, -5.0, 0.0], [-5.0, 0.0, 5.0], [0.0, 2.0, 4.0, 6.0])
    ]
    taps = all_taps(procedure, kb)
    np.testing.assert_allclose([(t.x_mm, t.y_mm, t.depth_mm) for t in taps], expected, atol=1e-9)
    assert [t.index for t in taps] == list(range(len(procedure)))
    assert all(t.yaw_deg == 0.0 and t.label == "" for t in taps)


def test_grid_depths_include_the_rig_offset(kb):
    procedure = GridTaps(keys="alphabet")
    depths = [procedure.tap(i, kb).depth_mm for i in range(7)]
    np.testing.assert_allclose(depths, np.arange(7) + 2.0)
    assert RIG_TAP_OFFSET_MM == 2.0
    last = procedure.tap(len(procedure) - 1, kb)
    frame = CALIBRATED_FRAMES["alphabet"]
    assert last.x_mm == pytest.approx(30.0 + frame.offset_x_mm)
    assert last.y_mm == pytest.approx(90.0 + frame.offset_y_mm)
    assert last.depth_mm == pytest.approx(8.0)


def test_grid_positions_sit_in_the_calibrated_frame_on_the_keys(kb):
    """The arrows grid covers the arrow block of the layout."""
    procedure = GridTaps(keys="arrows")
    xs, ys = set(), set()
    for i in range(0, len(procedure), 13):
        tap = procedure.tap(i, kb)
        xs.add(tap.x_mm)
        ys.add(tap.y_mm)
    for key in ARROW_KEYS:
        x, y = kb.centre_mm(key)
        assert min(xs) - 1 <= x <= max(xs) + 1
        assert min(ys) - 1 <= y <= max(ys) + 1


def test_grid_labels_are_its_keys_and_none():
    assert GridTaps(keys="arrows").labels == (*ARROW_KEYS, NONE_KEY)
    assert GridTaps(keys="alphabet").labels[-1] == NONE_KEY
    assert len(GridTaps(keys="alphabet").labels) == 28


@pytest.mark.parametrize("index", [-1, 36])
def test_grid_out_of_range_index_raises_index_error(kb, index):
    procedure = GridTaps(
        keys="arrows", spacing_mm=5, depth_step_mm=2, x_range_mm=(-10, 0), y_range_mm=(-5, 5)
    )
    with pytest.raises(IndexError, match="out of range"):
        procedure.tap(index, kb)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"keys": "all"}, "grid keys"),
        ({"keys": "arrows", "spacing_mm": -1.0}, "spacing_mm"),
        ({"keys": "arrows", "depth_step_mm": -0.5}, "depth_step_mm"),
        ({"keys": "arrows", "x_range_mm": (0.0, -5.0)}, "x_range_mm"),
        ({"keys": "arrows", "y_range_mm": (5.0, -5.0)}, "y_range_mm"),
    ],
)
def test_grid_invalid_arguments_raise_value_error(kwargs, match):
    with pytest.raises(ValueError, match=match):
        GridTaps(**kwargs)


@pytest.mark.parametrize("name", ["spacing_mm", "depth_step_mm"])
def test_grid_zero_step_raises_value_error(name):
    with pytest.raises(ValueError, match=name):
        GridTaps(keys="arrows", **{name: 0.0})


def test_grid_describe_is_json_and_resolved():
    procedure = GridTaps(keys="arrows", spacing_mm=5)
    description = json.loads(json.dumps(procedure.describe()))
    assert description == {
        "procedure": "grid",
        "keys": "arrows",
        "spacing_mm": 5,
        "depth_step_mm": 0.5,
        "x_range_mm": [-20.0, 0.0],
        "y_range_mm": [-20.0, 20.0],
        "max_tap_depth_mm": 6.0,
    }
    assert procedure.name == "grid"
