"""The touch encoder (supervised/touch.py): its settings, shapes and readout, labelled taps, its fit and
refit, and the key locator (which task key is under the sensor)."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest
import torch

from replay_helpers import FEATURES, GOALS, Frames, as_images, replay_observation
from tactile_braille.agents.replay import FRAME_LABELS
from tactile_braille.keyboard.layout import ALPHABET_KEYS, ARROW_KEYS, KeyboardLayout
from tactile_braille.supervised.touch import (
    KeyLocator,
    LabelledTaps,
    TouchEncoder,
    TouchEncoderConfig,
    Transitions,
    fit_touch_encoder,
    fit_touch_odometry,
    hindsight_offsets,
)

pytestmark = pytest.mark.usefixtures("one_torch_thread")


# ---------------------------------------------------------------- the encoder
@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"features": 0}, "features"),
        ({"hidden": 0}, "hidden"),
        ({"epochs": 0}, "epochs"),
        ({"batch_size": 0}, "batch_size"),
        ({"learning_rate": 0.0}, "learning_rate"),
        ({"validation": 1.0}, "validation"),
        ({"validation": -0.1}, "validation"),
    ],
)
def test_touch_encoder_config_is_checked(changes, message):
    with pytest.raises(ValueError, match=message):
        TouchEncoderConfig(**changes)


def test_touch_encoder_shapes_and_image_layouts():
    torch.manual_seed(0)
    encoder = TouchEncoder(keys=3, features=8, hidden=16).eval()
    images = Frames()
    channels_last = np.stack([images() for _ in range(4)])  # (B, 100, 100, 1), as environments give them
    channels_first = np.moveaxis(channels_last, -1, 1)
    features = encoder.encode(channels_last)
    assert features.shape == (4, 8) and features.dtype == np.float32
    np.testing.assert_allclose(features, encoder.encode(channels_first), rtol=1e-5, atol=1e-6)
    assert not np.allclose(features[0], features[1])  # different taps, different features
    pose, logits = encoder(torch.as_tensor(channels_first))
    assert pose.shape == (4, 3) and logits.shape == (4, 3 + 1)  # the last class: no task key


# ---------------------------------------------------------------- labelled taps
def test_labelled_taps_from_observations_and_arrays():
    taps = LabelledTaps()
    images = Frames()
    given = [images() for _ in range(5)]

    def locate(pose_mm):  # stands in for a KeyLocator: key (x mod 4)
        return int(pose_mm[0]) % GOALS

    for image, achieved in zip(given, (None, 2, None, 0), strict=False):
        pose = np.array([1.0, -2.0, 3.0]) * (len(taps) + 1)
        taps.add_observation(
            replay_observation(image, 1, achieved),
            {"sensor_pose_mm": pose},
            locate if len(taps) % 2 else None,
        )
    taps.add(given[4][:, :, 0], np.array([9.0, 8.0, 7.0, 6.0]), pressed=3)  # a 2-D image, extra pose entries
    assert len(taps) == 5
    stacked, poses, pressed = taps.arrays()
    assert stacked.shape == (5, 1, 100, 100) and stacked.dtype == np.uint8
    np.testing.assert_array_equal(stacked, as_images(given))
    assert poses.shape == (5, 3) and poses.dtype == np.float32
    np.testing.assert_array_equal(poses[:4], np.array([1.0, -2.0, 3.0]) * np.arange(1, 5)[:, None])
    np.testing.assert_array_equal(poses[4], [9.0, 8.0, 7.0])
    assert pressed.tolist() == [-1, 2, -1, 0, 3] and pressed.dtype == np.int64
    assert taps.under == [-1, 2, -1, 0, -1]  # located at x = 2 and 4 mm; none without a locator
    again = LabelledTaps.from_arrays(stacked, poses, pressed, np.array(taps.under))
    for ours, theirs in zip(taps.arrays(), again.arrays(), strict=True):
        np.testing.assert_array_equal(ours, theirs)
        assert ours.dtype == theirs.dtype
    assert again.under == taps.under
    assert len(LabelledTaps.from_arrays(stacked[:0], poses[:0], pressed[:0], pressed[:0])) == 0


@pytest.mark.parametrize("short", ["images", "poses", "pressed", "under"])
def test_labelled_taps_refuse_arrays_that_differ_in_number(short):
    arrays = {
        "images": np.zeros((3, 1, 100, 100), np.uint8),
        "poses": np.zeros((3, 3), np.float32),
        "pressed": np.zeros(3, np.int64),
        "under": np.zeros(3, np.int64),
    }
    arrays[short] = arrays[short][:2]
    with pytest.raises(ValueError, match="differ in number"):
        LabelledTaps.from_arrays(**arrays)


def test_a_label_is_the_pose_the_pressed_key_and_the_key_under_the_sensor():
    label = LabelledTaps.label(np.array([1.5, -2.0, 3.25, 99.0]), pressed=2, under=-1)
    assert label.shape == (FRAME_LABELS,) and label.dtype == np.float32
    np.testing.assert_array_equal(label, [1.5, -2.0, 3.25, 2.0, -1.0])


# ---------------------------------------------------------------- the fit
SYNTHETIC_KEYS = 3


def synthetic_taps(count: int, seed: int, shuffle_labels: bool = False) -> LabelledTaps:
    """Clearly separable taps: a bright square whose place on a 6x6 grid (2 mm apart) is the pose (its
    column pair the key under the sensor), and a bar along the top whose place is the pressed key (none:
    no bar, and a shallower tap)."""
    rng = np.random.default_rng(seed)
    images, labels = [], []
    for _ in range(count):
        column, row = rng.integers(0, 6, 2)
        pressed = int(rng.integers(-1, SYNTHETIC_KEYS))
        image = np.zeros((100, 100, 1), np.uint8)
        image[20 + 10 * row : 32 + 10 * row, 20 + 10 * column : 32 + 10 * column] = 255
        if pressed >= 0:
            image[:10, 30 * pressed : 30 * pressed + 20] = 255
        images.append(image)
        labels.append(
            (np.array([2.0 * column, 2.0 * row, 3.0 if pressed >= 0 else 1.0]), pressed, column // 2)
        )
    if shuffle_labels:
        labels = [labels[i] for i in rng.permutation(count)]
    taps = LabelledTaps()
    for image, (pose, pressed, under) in zip(images, labels, strict=True):
        taps.add(image, pose, pressed, under)
    return taps


def test_fit_touch_encoder_learns_pose_and_key_of_separable_taps():
    torch.manual_seed(0)  # a fresh encoder's weights come from torch's global generator, as in a training run
    config = TouchEncoderConfig(features=16, hidden=64, epochs=12, batch_size=16, validation=0.25)
    model, metrics = fit_touch_encoder(synthetic_taps(200, 0), SYNTHETIC_KEYS, config, seed=0)
    _, control = fit_touch_encoder(
        synthetic_taps(200, 0, shuffle_labels=True), SYNTHETIC_KEYS, config, seed=0
    )
    assert set(metrics) == {
        "touch/taps", "touch/pose_error_mm", "touch/depth_error_mm", "touch/key_accuracy",
        "touch/under_accuracy",
    }  # fmt: skip
    assert metrics["touch/taps"] == 200
    # Fitted: almost every held-out key right, the pose within a grid step. Chance is about 1 in 4 for
    # the key, and about 5 mm for the pose (the control, whose labels do not match the images).
    assert metrics["touch/key_accuracy"] >= 0.9 and metrics["touch/under_accuracy"] >= 0.9, metrics
    assert metrics["touch/pose_error_mm"] < 2.0 and metrics["touch/depth_error_mm"] < 0.5, metrics
    assert control["touch/key_accuracy"] < 0.6 and control["touch/under_accuracy"] < 0.7, control
    assert control["touch/pose_error_mm"] > 3.5, control
    assert not model.training and not any(p.requires_grad for p in model.parameters())
    assert model.features_size == 16 and model.keys == SYNTHETIC_KEYS
    assert 3.0 < float(model.pose_mean[0]) < 7.0 and float(model.pose_scale[0]) > 1.0  # labels' statistics


def test_fit_touch_encoder_refuses_too_few_taps_and_unknown_keys():
    config = TouchEncoderConfig(features=4, hidden=8, epochs=1)
    with pytest.raises(ValueError, match="at least 10"):
        fit_touch_encoder(synthetic_taps(9, 0), SYNTHETIC_KEYS, config)
    taps = synthetic_taps(12, 0)
    taps.add(np.zeros((100, 100, 1), np.uint8), np.zeros(3), pressed=SYNTHETIC_KEYS)
    with pytest.raises(ValueError, match="labelled with key 3"):
        fit_touch_encoder(taps, SYNTHETIC_KEYS, config)


def test_fit_touch_encoder_keeps_a_tap_to_train_on_whatever_the_validation_share():
    config = TouchEncoderConfig(features=4, hidden=8, epochs=1, validation=0.95)
    model, metrics = fit_touch_encoder(synthetic_taps(10, 0), SYNTHETIC_KEYS, config)
    assert np.isfinite(model.pose_mean.numpy()).all()
    assert np.isfinite(metrics["touch/pose_error_mm"])


def test_a_refit_starts_from_the_given_encoders_weights():
    config = TouchEncoderConfig(features=4, hidden=8, epochs=1)
    torch.manual_seed(0)
    first, _ = fit_touch_encoder(synthetic_taps(20, 0), SYNTHETIC_KEYS, config)
    weights = copy.deepcopy(first.state_dict())
    # So small a step that a refit barely moves: its weights are those it started from.
    still = dataclasses.replace(config, learning_rate=1e-9)
    refit, metrics = fit_touch_encoder(synthetic_taps(30, 1), SYNTHETIC_KEYS, still, seed=1, init=first)
    fresh, _ = fit_touch_encoder(synthetic_taps(30, 1), SYNTHETIC_KEYS, still, seed=1)
    parameters = dict(first.named_parameters())
    assert refit is not first and metrics["touch/taps"] == 30
    for name, parameter in refit.named_parameters():
        torch.testing.assert_close(parameter, parameters[name], rtol=0, atol=1e-6, msg=name)
    assert not all(torch.allclose(p, parameters[name], atol=1e-3) for name, p in fresh.named_parameters())
    # The pose statistics are the new taps'; the encoder it started from is left as it was, frozen.
    assert not torch.equal(refit.pose_mean, first.pose_mean)
    assert all(torch.equal(first.state_dict()[name], value) for name, value in weights.items())
    assert not any(p.requires_grad for p in first.parameters())
    assert not refit.training and not any(p.requires_grad for p in refit.parameters())


# ---------------------------------------------------------------- touch odometry
def synthetic_steps(count: int, seed: int, shuffle_effects: bool = False) -> tuple[Transitions, np.ndarray]:
    """A random walk over a 6x6 grid of the squares of :func:`synthetic_taps` (a move of up to one
    cells each way, stopped at the edges), pressing the key of its column pair (a bar along the top)
    one step in five; and the cell of every frame, which the fit never sees."""
    rng = np.random.default_rng(seed)
    cell, cells, images, effects, pressed = rng.integers(0, 6, 2), [], [], [], []

    def tap(cell, press):
        image = np.zeros((100, 100, 1), np.uint8)
        column, row = cell
        image[20 + 10 * row : 32 + 10 * row, 20 + 10 * column : 32 + 10 * column] = 255
        if press:
            image[:10, 30 * (column // 2) : 30 * (column // 2) + 20] = 255
        images.append(image)
        cells.append(cell)

    tap(cell, False)
    for _ in range(count):
        press = rng.random() < 0.2
        move = np.zeros(2, np.int64) if press else rng.integers(-1, 2, 2)
        cell = np.clip(cell + move, 0, 5)
        tap(cell, press)
        effects.append([*move, float(press)])
        pressed.append(int(cell[0] // 2) if press else -1)
    effects = np.array(effects, np.float32)
    if shuffle_effects:
        effects = effects[rng.permutation(count)]
    pairs = np.stack([np.arange(count), np.arange(1, count + 1)], -1)
    steps = Transitions(np.moveaxis(np.stack(images), -1, 1), pairs, effects, np.array(pressed))
    return steps, np.array(cells, np.float32)


def _units(model, images: np.ndarray) -> np.ndarray:
    """The pose head's readout of images, in action units."""
    return model.read(images)[:, :3] * model.pose_scale.numpy() + model.pose_mean.numpy()


def test_touch_odometry_learns_where_each_tap_is_up_to_a_translation_and_where_each_key_was_pressed():
    torch.manual_seed(0)
    config = TouchEncoderConfig(features=16, hidden=64, epochs=20, batch_size=16, validation=0.2)
    steps, cells = synthetic_steps(300, 0)
    model, metrics = fit_touch_odometry(steps, SYNTHETIC_KEYS, config, seed=0)
    assert set(metrics) == {
        "touch/taps", "touch/aimed_steps", "touch/odometry_error", "touch/key_accuracy",
        "touch/outcome_accuracy", "touch/offset_error",
    }  # fmt: skip
    assert metrics["touch/taps"] == 301 and metrics["touch/aimed_steps"] > 250
    assert metrics["touch/key_accuracy"] >= 0.9 and metrics["touch/odometry_error"] < 0.6, metrics
    # The key a press will press, foreseen from the tap before it: here, the key under the sensor,
    # which the readout's last distribution gives (a press without a move).
    # Chance is a third at best; this short a fit foresees about 2 presses in 3.
    assert metrics["touch/outcome_accuracy"] >= 0.45, metrics
    under = model.read(steps.images)[:, 3 + SYNTHETIC_KEYS + 1 : 3 + 2 * (SYNTHETIC_KEYS + 1)].argmax(-1)
    assert (under == cells[:, 0] // 2).mean() >= 0.45
    # Coordinates: the cells, shifted by one translation (the odometry's free gauge), read off the
    # readout (within half a cell; a collapsed or untrained head is off by 1.5 cells); the readout
    # itself is standardised (centred on the frames, unit spread).
    readout = model.read(steps.images)
    np.testing.assert_allclose(readout[:, :3].mean(0), 0.0, atol=1e-3)
    np.testing.assert_allclose(readout[:, :3].std(0), 1.0, atol=0.01)
    offset = _units(model, steps.images)[:, :2] - cells
    assert np.median(np.abs(offset - np.median(offset, 0))) < 0.5, offset.std(0)
    # Hindsight offsets: where the next key pressed lies from each frame (its cells minus the frame's,
    # read off the readout's last 2 * keys numbers), within a cell or so (the spread of the cells
    # themselves is 1.7 cells).
    aimed, _ = hindsight_offsets(steps)
    known = np.flatnonzero(aimed >= 0)
    presses = np.flatnonzero(steps.pressed >= 0)
    pressed_at = cells[steps.pairs[presses[np.searchsorted(presses, known)], 1]]
    offsets = readout[:, -2 * SYNTHETIC_KEYS :].reshape(-1, SYNTHETIC_KEYS, 2)
    read = offsets[steps.pairs[known, 0], aimed[known]]
    error = np.linalg.norm(read - (pressed_at - cells[steps.pairs[known, 0]]), axis=-1)
    assert np.median(error) < 1.2 and metrics["touch/offset_error"] < 1.5, (np.median(error), metrics)
    assert (
        model.labels == "observation"
        and model.readout_size == 3 + 2 * (SYNTHETIC_KEYS + 1) + 2 * SYNTHETIC_KEYS
    )
    assert not model.training and not any(p.requires_grad for p in model.parameters())


def test_hindsight_offsets_sum_each_episodes_moves_to_its_press():
    # Episodes (frames): 0-1-2-3 presses key 1; 4-5-6 times out; 7-8 presses key 0 on its first step.
    pairs = np.array([[0, 1], [1, 2], [2, 3], [4, 5], [5, 6], [7, 8]])
    moves = np.array([[1, 0], [0, 2], [0.5, 0.5], [3, 3], [1, 1], [-1, 0]], np.float32)
    effects = np.concatenate([moves, np.zeros((6, 1), np.float32)], axis=1)
    pressed = np.array([-1, -1, 1, -1, -1, 0])
    steps = Transitions(np.zeros((9, 1, 100, 100), np.uint8), pairs, effects, pressed)
    aimed, offsets = hindsight_offsets(steps)
    assert aimed.tolist() == [1, 1, 1, -1, -1, 0]
    np.testing.assert_allclose(offsets[[0, 1, 2, 5]], [[1.5, 2.5], [0.5, 2.5], [0.5, 0.5], [-1, 0]])
    np.testing.assert_array_equal(offsets[3:5], 0.0)


def test_touch_odometry_skips_steps_after_a_reset_and_refuses_bad_steps():
    config = TouchEncoderConfig(features=4, hidden=8, epochs=1)
    steps, _ = synthetic_steps(30, 1)
    steps.effects[::3] = np.nan  # frames after a reset: no action led to them
    model, metrics = fit_touch_odometry(steps, SYNTHETIC_KEYS, config)
    assert np.isfinite(model.pose_mean.numpy()).all() and np.isfinite(metrics["touch/odometry_error"])
    with pytest.raises(ValueError, match="at least 10 steps"):
        fit_touch_odometry(synthetic_steps(9, 0)[0], SYNTHETIC_KEYS, config)
    wrong = Transitions(steps.images, steps.pairs, steps.effects, np.where(steps.pressed >= 0, 3, -1))
    with pytest.raises(ValueError, match="pressed key 3, but the task has 3 keys"):
        fit_touch_odometry(wrong, SYNTHETIC_KEYS, config)
    with pytest.raises(ValueError, match="differ in number"):
        Transitions(steps.images, steps.pairs, steps.effects[:-1], steps.pressed)
    with pytest.raises(ValueError, match="pairs index 31 frames"):
        Transitions(steps.images, steps.pairs + 1, steps.effects, steps.pressed)


# ---------------------------------------------------------------- the readout
# After the fits on purpose: fit_touch_encoder draws a fresh encoder's weights from torch's global
# generator, which this test reseeds and draws from; placed before them, it changed what they learnt.
def test_the_readout_is_the_standardised_pose_and_two_key_distributions():
    torch.manual_seed(0)
    encoder = TouchEncoder(GOALS, features=FEATURES, hidden=8).eval()
    images = np.random.default_rng(0).integers(0, 2, (5, 100, 100, 1), dtype=np.uint8) * 255
    readout = encoder.read(images)
    assert readout.shape == (5, encoder.readout_size) and encoder.readout_size == 3 + 2 * (GOALS + 1)
    with torch.no_grad():
        pose, pressed, under = encoder.heads(torch.as_tensor(np.moveaxis(images, -1, 1)))
    np.testing.assert_allclose(readout[:, :3], pose.numpy(), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(
        readout[:, 3 : 3 + GOALS + 1], pressed.softmax(-1).numpy(), rtol=1e-5, atol=1e-6
    )
    np.testing.assert_allclose(readout[:, 3 + GOALS + 1 :], under.softmax(-1).numpy(), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(readout[:, 3:].reshape(5, 2, GOALS + 1).sum(-1), 1.0, rtol=1e-5)


# ---------------------------------------------------------------- the key under the sensor
def test_a_key_locator_maps_each_keys_centre_to_it():
    layout = KeyboardLayout()
    for keys in (ARROW_KEYS, ALPHABET_KEYS):
        locate = KeyLocator(layout, keys)
        assert [locate((*layout.centre_mm(key), 2.0)) for key in keys] == list(range(len(keys)))


@pytest.mark.parametrize("pitch_mm", [18.0, 19.0, 20.0])
@pytest.mark.parametrize(
    ("near", "far"), [("LEFT", "DOWN"), ("DOWN", "LEFT"), ("UP", "DOWN"), ("DOWN", "UP")]
)
def test_a_point_between_two_keys_belongs_to_the_key_whose_cell_holds_it(pitch_mm, near, far):
    layout = KeyboardLayout(pitch_mm=pitch_mm)
    locate = KeyLocator(layout, ARROW_KEYS)
    a, b = np.array(layout.centre_mm(near)), np.array(layout.centre_mm(far))
    assert np.linalg.norm(b - a) == pytest.approx(pitch_mm)  # neighbours, in a row or across rows
    towards = (b - a) / pitch_mm
    edge = a + towards * pitch_mm / 2  # where the two keys' cells meet
    assert locate(edge - 0.1 * towards) == ARROW_KEYS.index(near)
    assert locate(edge + 0.1 * towards) == ARROW_KEYS.index(far)


def test_a_key_locator_finds_no_task_key_off_them():
    layout = KeyboardLayout()
    locate = KeyLocator(layout, ARROW_KEYS)
    for point in ((500.0, 500.0), (-100.0, 0.0), layout.centre_mm("END"), layout.centre_mm("Q")):
        assert locate(point) == -1, point
    up = np.array(layout.centre_mm("UP"))
    assert locate(up + np.array([-9.6, 0.0])) == -1  # ENTER, in the row above UP
    assert locate(up + np.array([0.0, 9.6])) == -1  # RIGHTSHIFT's cell


def test_space_has_a_cell_as_wide_as_its_bar():
    layout = KeyboardLayout()
    locate = KeyLocator(layout, ALPHABET_KEYS)
    space = ALPHABET_KEYS.index("SPACE")
    x, y = layout.centre_mm("SPACE")
    half_mm = 6.25 * 19.0 / 2  # 59.375 mm either side of its centre, as far as LEFTALT and RIGHTALT
    for along in (0.0, 40.0, half_mm - 0.5, -(half_mm - 0.5)):
        assert locate((x, y + along)) == space, along
        assert locate((x - 9.0, y + along)) == space, along  # just below the Z row
    assert locate((x, y + half_mm + 0.5)) == -1  # LEFTALT, not a task key
    assert locate((x, y - half_mm - 0.5)) == -1  # RIGHTALT
    assert locate((x - 10.0, y)) == ALPHABET_KEYS.index("B")  # the key above its centre


def test_an_encoder_takes_the_labels_a_run_can_be_set_to_and_refuses_others():
    from tactile_braille.agents.config import TOUCH_LABELS as SETTINGS
    from tactile_braille.supervised.touch import TOUCH_LABELS

    assert SETTINGS == TOUCH_LABELS  # the torch-free settings spell out the encoder's choices
    with pytest.raises(ValueError, match="labels must be one of"):
        TouchEncoder(GOALS, features=4, hidden=8, labels="pose")
