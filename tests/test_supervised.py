"""The supervised key classifier: learning, saving, reloading, bad inputs."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from tactile_braille.datasets import PerturbedTaps, collect, load_dataset
from tactile_braille.rigs.virtual import VirtualRig
from tactile_braille.supervised import (
    ClassifierConfig,
    confusion_matrix,
    load_classifier,
    predict,
    save_classifier,
    train_classifier,
)
from tactile_braille.supervised.classifier import images_to_tensor, select_classes
from tactile_braille.supervised.report import save_confusion_matrix, top_confusions

KEYS = ("UP", "DOWN", "LEFT", "RIGHT")


@pytest.fixture(scope="module")
def arrow_datasets(tmp_path_factory):
    folder = tmp_path_factory.mktemp("supervised")
    train = collect(
        VirtualRig(), PerturbedTaps(keys="arrows", per_key=40), folder / "train.h5", progress=False
    )
    validation = collect(
        VirtualRig(), PerturbedTaps(keys="arrows", per_key=20, split="validation"), folder / "val.h5",
        seed=1, progress=False,
    )  # fmt: skip
    return load_dataset(train), load_dataset(validation)


@pytest.fixture(scope="module")
def trained(arrow_datasets):
    torch.set_num_threads(1)
    config = ClassifierConfig(classes=KEYS, max_epochs=8, patience=8, max_shift=0.0, max_zoom=0.0)
    return train_classifier(*arrow_datasets, config)


def test_short_training_beats_chance_by_a_wide_margin(trained, arrow_datasets):
    _, validation = arrow_datasets
    images, labels = select_classes(validation, KEYS)
    predicted = predict(trained.model, images, KEYS)
    accuracy = (predicted == np.asarray(KEYS)[labels]).mean()
    assert accuracy >= 0.7  # chance is 0.25
    assert len(trained.history) >= 1
    assert trained.history[trained.best_epoch]["val_accuracy"] == pytest.approx(accuracy, abs=1e-6)


def test_saved_model_reloads_with_identical_predictions(trained, arrow_datasets, tmp_path):
    _, validation = arrow_datasets
    folder = save_classifier(trained, tmp_path / "run", {"val_accuracy": 1.0})
    model, config = load_classifier(folder)
    assert config == trained.config
    images, _ = select_classes(validation, KEYS)
    np.testing.assert_array_equal(predict(model, images, KEYS), predict(trained.model, images, KEYS))


def test_load_from_a_folder_without_a_model_raises(tmp_path):
    with pytest.raises(ValueError, match="does not hold a saved classifier"):
        load_classifier(tmp_path)


@pytest.mark.parametrize(
    ("images", "message"),
    [
        (np.zeros((2, 64, 64), np.uint8), "shape"),
        (np.zeros((100, 100), np.uint8), "shape"),
        (np.zeros((2, 100, 100, 3), np.uint8), "shape"),
        (np.zeros((2, 100, 100), np.float32), "uint8"),
    ],
)
def test_bad_images_raise_clear_errors(images, message):
    with pytest.raises(ValueError, match=message):
        images_to_tensor(images)


def test_images_with_a_channel_axis_are_accepted():
    assert images_to_tensor(np.zeros((3, 100, 100, 1), np.uint8)).shape == (3, 1, 100, 100)


def test_unknown_classes_raise(arrow_datasets):
    train, validation = arrow_datasets
    with pytest.raises(ValueError, match=r"no samples of the classes \['A'\]"):
        train_classifier(train, validation, ClassifierConfig(classes=("UP", "A"), max_epochs=1))


def test_config_validation():
    with pytest.raises(ValueError, match="distinct"):
        ClassifierConfig(classes=("UP", "UP"))
    with pytest.raises(ValueError, match="max_epochs"):
        ClassifierConfig(max_epochs=0)


def test_confusion_matrix_and_top_confusions(tmp_path):
    classes = ("B", "L", "UP")
    matrix = confusion_matrix(np.array(["B", "B", "L", "UP"]), np.array(["B", "L", "L", "UP"]), classes)
    np.testing.assert_array_equal(matrix, [[1, 1, 0], [0, 1, 0], [0, 0, 1]])
    (mistake,) = top_confusions(matrix, classes)
    assert mistake == {"true": "B", "predicted": "L", "count": 1, "dots_differing": [3]}
    with pytest.raises(ValueError, match="outside the classes"):
        confusion_matrix(np.array(["Q"]), np.array(["B"]), classes)
    path = save_confusion_matrix(matrix, classes, tmp_path / "cm.png", "test")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
