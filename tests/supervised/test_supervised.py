"""The supervised key classifier (learning, saving, reloading, bad inputs), the conv stack and fit loop."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from tactile_braille.agents.networks import GoalConditionedTrunk
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
from tactile_braille.supervised.classifier import KeyClassifier, images_to_tensor, select_classes
from tactile_braille.supervised.fit import fit_minibatches
from tactile_braille.supervised.networks import Encoder, conv_output_size, conv_stack
from tactile_braille.supervised.report import save_confusion_matrix, top_confusions
from tactile_braille.supervised.touch import TouchEncoder

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


def test_evaluate_classifier_scores_and_writes_the_classifier(trained, arrow_datasets, tmp_path):
    import json

    from tactile_braille.supervised.report import evaluate_classifier

    train, validation = arrow_datasets
    scored = evaluate_classifier(trained, validation, tmp_path / "run", train_path=train.path)
    assert scored.images == len(select_classes(validation, KEYS)[1]) == 80
    assert scored.matrix.sum() == 80 and np.trace(scored.matrix) == round(scored.accuracy * 80)
    assert scored.accuracy == pytest.approx(trained.history[trained.best_epoch]["val_accuracy"], abs=1e-6)
    metrics = json.loads((tmp_path / "run" / "classifier.json").read_text())["metrics"]
    assert metrics["val_accuracy"] == scored.accuracy and metrics["validation"] == str(validation.path)
    assert metrics["top_confusions"] == scored.mistakes
    assert (tmp_path / "run" / "confusion.png").stat().st_size > 1000
    model, _ = load_classifier(tmp_path / "run")
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


def test_the_conv_stack_gives_the_papers_feature_size_for_any_image_size():
    assert conv_output_size() == conv_output_size(100) == 64 * 9 * 9 == Encoder.output_size
    assert conv_output_size(84) == 64 * 7 * 7  # the Atari frames
    for size in (100, 84, 64):
        with torch.no_grad():
            assert conv_stack(batch_norm=True).eval()(torch.zeros(2, 1, size, size)).shape == (
                2,
                conv_output_size(size),
            )
    with pytest.raises(ValueError, match="too small"):
        conv_output_size(30)


def test_the_networks_keep_their_state_dict_keys():
    """Saved classifiers, run checkpoints and touch encoders name their convolutions as before."""
    conv = ["layers.0.weight", "layers.0.bias", "layers.2.weight", "layers.2.bias"]
    conv += ["layers.4.weight", "layers.4.bias"]
    assert list(Encoder().state_dict()) == conv
    norm = ["weight", "bias", "running_mean", "running_var", "num_batches_tracked"]
    assert list(KeyClassifier(4).state_dict()) == [
        "features.0.weight", "features.0.bias",
        *(f"features.2.{name}" for name in norm),
        "features.3.weight", "features.3.bias",
        *(f"features.5.{name}" for name in norm),
        "features.6.weight", "features.6.bias",
        *(f"features.8.{name}" for name in norm),
        "head.0.weight", "head.0.bias", "head.3.weight", "head.3.bias",
    ]  # fmt: skip
    assert list(TouchEncoder(3, features=4, hidden=8).state_dict()) == [
        "pose_mean", "pose_scale", *(f"encoder.{key}" for key in conv),
        "project.0.weight", "project.0.bias", "project.2.weight", "project.2.bias",
        "project.3.weight", "project.3.bias", "pose.weight", "pose.bias", "key.weight", "key.bias",
        "under.weight", "under.bias",
    ]  # fmt: skip
    assert list(GoalConditionedTrunk(3, (8,)).state_dict())[:6] == [f"encoder.{key}" for key in conv]


def test_fit_minibatches_visits_every_sample_once_an_epoch_and_may_stop_early():
    model = torch.nn.Linear(1, 1, bias=False)
    optimiser = torch.optim.SGD(model.parameters(), lr=0.0)
    schedule = torch.optim.lr_scheduler.LambdaLR(optimiser, lambda step: 1.0)
    batches: list[torch.Tensor] = []
    ends: list[tuple[int, float]] = []

    def loss(batch: torch.Tensor) -> torch.Tensor:
        batches.append(batch)
        return model.weight.sum() * 0 + float(len(batch))  # a batch's loss: its size

    def end_epoch(epoch: int, train_loss: float) -> bool:
        ends.append((epoch, train_loss))
        return epoch == 1

    generator = torch.Generator().manual_seed(0)
    epochs = fit_minibatches(model, 10, loss, optimiser, 5, 4, generator, schedule, end_epoch)
    assert epochs == 2 and [epoch for epoch, _ in ends] == [0, 1]
    assert [len(batch) for batch in batches] == [4, 4, 2] * 2
    for epoch in range(2):
        assert sorted(torch.cat(batches[3 * epoch : 3 * epoch + 3]).tolist()) == list(range(10))
    assert ends[0][1] == pytest.approx((4 * 4 + 4 * 4 + 2 * 2) / 10)  # batch losses weighted by size
    assert schedule.last_epoch == 6  # one scheduler step per optimiser step
    # The permutations are the generator's, drawn once an epoch.
    again = torch.Generator().manual_seed(0)
    assert torch.equal(torch.cat(batches[:3]), torch.randperm(10, generator=again))
    assert fit_minibatches(model, 10, loss, optimiser, 3, 4, generator) == 3  # no callback: all epochs
