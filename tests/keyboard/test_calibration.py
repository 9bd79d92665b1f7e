"""The real activation maps and the calibrated switch model's agreement with them."""

from __future__ import annotations

import gzip
from importlib import resources

import numpy as np
import pytest

from tactile_braille.keyboard.calibration import (
    CALIBRATED_FRAMES,
    MAP_NAMES,
    RIG_TAP_OFFSET_MM,
    ActivationMap,
    Agreement,
    FrameTransform,
    agreement,
    fit_travel_offsets,
    held_out_agreement,
    load_activation_map,
    predict_activation_map,
)
from tactile_braille.keyboard.layout import NONE_KEY, key_set
from tactile_braille.keyboard.switch import SwitchModel

EXPECTED_TAPS = {"alphabet": 8967, "arrows": 11193}


@pytest.fixture(scope="module")
def maps():
    return {name: load_activation_map(name) for name in MAP_NAMES}


@pytest.fixture(scope="module")
def predictions(maps):
    return {name: predict_activation_map(m) for name, m in maps.items()}


def test_map_names():
    assert MAP_NAMES == ("alphabet", "arrows")


@pytest.mark.parametrize("name", MAP_NAMES)
def test_load_activation_map(maps, name):
    activation_map = maps[name]
    n = EXPECTED_TAPS[name]
    assert activation_map.name == name
    assert len(activation_map) == n
    for array in (activation_map.x_mm, activation_map.y_mm, activation_map.depth_mm):
        assert array.shape == (n,)
        assert np.isfinite(array).all()
    labels = set(activation_map.pressed.tolist())
    assert labels <= {NONE_KEY, *key_set(name)}
    assert NONE_KEY in labels
    assert len(labels) > 2  # several keys actually registered


@pytest.mark.parametrize("name", MAP_NAMES)
def test_depth_includes_the_rigs_constant_offset(maps, name):
    """The recorded tap_depth runs 0..6 mm; the rig added 2 mm to every tap."""
    depth = maps[name].depth_mm
    assert RIG_TAP_OFFSET_MM == 2.0
    assert depth.min() == pytest.approx(2.0)
    assert depth.max() == pytest.approx(8.0)


def test_each_map_saw_every_key_of_its_set_register(maps):
    assert set(maps["alphabet"].pressed.tolist()) == {NONE_KEY, *key_set("alphabet")}
    assert set(maps["arrows"].pressed.tolist()) == {NONE_KEY, "UP", "DOWN", "LEFT", "RIGHT"}


@pytest.mark.parametrize("name", MAP_NAMES)
def test_load_from_explicit_plain_csv_path(maps, tmp_path, name):
    """A plain (not gzipped) targets_video.csv given by path loads the same taps."""
    source = resources.files("tactile_braille.keyboard").joinpath(
        f"reference/{name}_grid_targets_video.csv.gz"
    )
    plain = tmp_path / "targets_video.csv"
    plain.write_bytes(gzip.decompress(source.read_bytes()))
    loaded = load_activation_map(name, plain)
    np.testing.assert_array_equal(loaded.x_mm, maps[name].x_mm)
    np.testing.assert_array_equal(loaded.y_mm, maps[name].y_mm)
    np.testing.assert_array_equal(loaded.depth_mm, maps[name].depth_mm)
    np.testing.assert_array_equal(loaded.pressed, maps[name].pressed)


def test_foreign_csv_raises(tmp_path):
    foreign = tmp_path / "other.csv"
    foreign.write_text("time,value\n0.0,1\n0.1,2\n")
    with pytest.raises(ValueError, match=r"not a grid targets_video\.csv"):
        load_activation_map("alphabet", foreign)


def test_empty_csv_raises(tmp_path):
    empty = tmp_path / "empty.csv"
    empty.write_text("obj_pose,tap_depth,pressed_buttons\n")
    with pytest.raises(ValueError):
        load_activation_map("arrows", empty)


def test_unknown_map_name_raises():
    with pytest.raises(ValueError, match="unknown activation map 'digits'"):
        load_activation_map("digits")


def test_agreement_identical_is_perfect():
    outcomes = np.array(["NONE", "A", "B", "NONE", "SPACE"])
    result = agreement(outcomes, outcomes.copy())
    assert result == Agreement(overall=1.0, actuated=1.0, taps=5)


def test_agreement_handcrafted():
    observed = np.array(["NONE", "A", "B", "NONE", "NONE", "C"])
    predicted = np.array(["NONE", "A", "NONE", "C", "NONE", "D"])
    result = agreement(observed, predicted)
    assert result.taps == 6
    assert result.overall == pytest.approx(3 / 6)  # taps 0, 1, 4
    # Taps where either actuated: 1, 2, 3, 5; only tap 1 agrees.
    assert result.actuated == pytest.approx(1 / 4)


def test_agreement_all_none_counts_actuated_as_perfect():
    result = agreement(np.array(["NONE"] * 3), np.array(["NONE"] * 3))
    assert result.overall == 1.0
    assert result.actuated == 1.0


def test_agreement_accepts_lists():
    assert agreement(["A", "NONE"], ["B", "NONE"]).overall == pytest.approx(0.5)


def test_agreement_shape_mismatch_raises():
    with pytest.raises(ValueError, match="shape mismatch"):
        agreement(np.array(["A", "B"]), np.array(["A"]))


@pytest.mark.parametrize("name", MAP_NAMES)
def test_never_press_baseline_is_poor_on_actuated_taps(maps, name):
    baseline = agreement(maps[name].pressed, np.full(len(maps[name]), NONE_KEY))
    assert baseline.actuated == 0.0
    assert 0.8 < baseline.overall < 0.9


@pytest.mark.parametrize("name", MAP_NAMES)
def test_predictions_use_only_heard_keys(predictions, name):
    labels = set(predictions[name].tolist())
    assert labels <= {NONE_KEY, *key_set(name)}
    assert predictions[name].shape == (EXPECTED_TAPS[name],)


@pytest.mark.parametrize("name", MAP_NAMES)
def test_calibrated_model_reproduces_the_real_maps(maps, predictions, name):
    result = agreement(maps[name].pressed, predictions[name])
    baseline = agreement(maps[name].pressed, np.full(len(maps[name]), NONE_KEY))
    assert result.taps == EXPECTED_TAPS[name]
    assert result.overall >= 0.97  # the targets
    assert result.actuated >= 0.85
    assert result.overall > baseline.overall + 0.07


def test_per_key_offsets_lift_the_alphabet_on_taps_they_were_not_fitted_on(maps):
    """Two-fold cross-validation: offsets fitted on one half of the taps predict the other half."""
    level = agreement(
        maps["alphabet"].pressed,
        predict_activation_map(maps["alphabet"], SwitchModel(travel_offsets_mm=())),
    )
    held_out = held_out_agreement(maps["alphabet"])
    assert level.actuated < 0.85 <= held_out.actuated
    assert held_out.overall > level.overall


def _synthetic_map(activation_map, switch):
    """The real map's taps, labelled by ``switch`` instead of the robot."""
    return ActivationMap(
        name=activation_map.name,
        x_mm=activation_map.x_mm,
        y_mm=activation_map.y_mm,
        depth_mm=activation_map.depth_mm,
        pressed=predict_activation_map(activation_map, switch),
    )


def test_fit_travel_offsets_recovers_planted_offsets(maps):
    planted = {"A": 0.3, "K": -0.2, "SPACE": 0.1, "Q": -0.4}
    truth = _synthetic_map(maps["alphabet"], SwitchModel(travel_offsets_mm=planted))
    fitted = fit_travel_offsets(truth, SwitchModel(travel_offsets_mm={"B": 0.5}))  # replaced, not added to
    # a 1 mm depth grid pins an offset down only to the interval that changes no tap outcome
    predicted = predict_activation_map(truth, SwitchModel(travel_offsets_mm=fitted))
    assert agreement(truth.pressed, predicted).overall == 1.0
    assert set(fitted) == set(planted)
    for key, value in planted.items():
        assert np.sign(fitted[key]) == np.sign(value)


def test_fit_travel_offsets_on_a_level_map_finds_none(maps):
    truth = _synthetic_map(maps["arrows"], SwitchModel(travel_offsets_mm=()))
    assert fit_travel_offsets(truth) == {}


def test_fit_travel_offsets_uses_only_the_given_taps(maps):
    truth = _synthetic_map(maps["alphabet"], SwitchModel(travel_offsets_mm={"A": 0.3}))
    a_taps = np.flatnonzero(truth.pressed == "A")
    elsewhere = np.setdiff1d(np.arange(len(truth)), np.flatnonzero(np.isin(truth.pressed, ["A"])))
    level = predict_activation_map(truth, SwitchModel(travel_offsets_mm=()))
    changed = np.flatnonzero(level != truth.pressed)
    assert len(changed) and set(truth.pressed[changed]) == {"A"}
    assert "A" in fit_travel_offsets(truth, taps=np.union1d(a_taps, changed))
    assert fit_travel_offsets(truth, taps=np.setdiff1d(elsewhere, changed)) == {}


def test_fit_and_cross_validation_reject_bad_arguments(maps):
    with pytest.raises(ValueError, match="step_mm"):
        fit_travel_offsets(maps["arrows"], step_mm=0.0)
    with pytest.raises(ValueError, match="switch tolerance"):
        fit_travel_offsets(maps["arrows"], limit_mm=1.0)
    with pytest.raises(ValueError, match="folds"):
        held_out_agreement(maps["arrows"], folds=1)


@pytest.mark.parametrize("name", MAP_NAMES)
def test_a_misplaced_frame_agrees_much_worse(maps, predictions, name):
    """The fitted frame matters: shifting the map by half a key ruins the actuated agreement."""
    frame = CALIBRATED_FRAMES[name]
    shifted = FrameTransform(
        frame.offset_x_mm,
        frame.offset_y_mm + 9.5,
        frame.yaw_deg,
        frame.clearance_mm,
        frame.tilt_x,
        frame.tilt_y,
    )
    good = agreement(maps[name].pressed, predictions[name])
    bad = agreement(maps[name].pressed, predict_activation_map(maps[name], frame=shifted))
    assert bad.actuated < good.actuated - 0.2


def test_frame_transform_geometry():
    frame = FrameTransform(offset_x_mm=10.0, offset_y_mm=-5.0, yaw_deg=90.0, clearance_mm=4.0, tilt_x=0.1)
    x, y = frame.to_keyboard(np.array([1.0]), np.array([0.0]))
    np.testing.assert_allclose([x[0], y[0]], [10.0, -4.0], atol=1e-12)
    np.testing.assert_allclose(frame.clearance_at_mm(np.array([2.0]), np.array([0.0])), [4.2])
    identity = FrameTransform(0.0, 0.0)
    x, y = identity.to_keyboard(np.array([3.0, -1.0]), np.array([2.0, 5.0]))
    np.testing.assert_allclose(x, [3.0, -1.0])
    np.testing.assert_allclose(y, [2.0, 5.0])
