"""Pictures and summaries of a key classifier's results."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tactile_braille.keyboard.braille import BRAILLE_DOTS


def top_confusions(matrix: np.ndarray, classes: tuple[str, ...], count: int = 10) -> list[dict]:
    """The most frequent mistakes, with the braille dots the two keys differ by."""
    mistakes = []
    for i, true in enumerate(classes):
        for j, predicted in enumerate(classes):
            if i != j and matrix[i, j]:
                entry = {"true": true, "predicted": predicted, "count": int(matrix[i, j])}
                if true in BRAILLE_DOTS and predicted in BRAILLE_DOTS:
                    entry["dots_differing"] = sorted(set(BRAILLE_DOTS[true]) ^ set(BRAILLE_DOTS[predicted]))
                mistakes.append(entry)
    return sorted(mistakes, key=lambda m: -m["count"])[:count]


def save_confusion_matrix(
    matrix: np.ndarray, classes: tuple[str, ...], output: str | Path, title: str
) -> Path:
    """Write the confusion matrix (rows: true key, columns: predicted) as a PNG."""
    from tactile_braille._figures import new_figure, save_figure

    fig, axes = new_figure(figsize=(8.5, 7.5))
    ax = axes[0, 0]
    shown = np.where(matrix > 0, matrix, np.nan)
    image = ax.imshow(shown, cmap="viridis", interpolation="nearest")
    ax.set_xticks(range(len(classes)), classes, rotation=90, fontsize=7)
    ax.set_yticks(range(len(classes)), classes, fontsize=7)
    ax.set_xlabel("predicted key")
    ax.set_ylabel("true key")
    for i, j in zip(*np.nonzero((matrix > 0) & ~np.eye(len(classes), dtype=bool)), strict=True):
        ax.text(j, i, str(matrix[i, j]), ha="center", va="center", fontsize=6, color="white")
    fig.colorbar(image, ax=ax, fraction=0.04)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, output)


@dataclass
class ClassifierEvaluation:
    """A trained classifier on a validation set: accuracy, confusion matrix and its largest mistakes."""

    accuracy: float
    images: int
    matrix: np.ndarray
    mistakes: list[dict]


def evaluate_classifier(result, validation, folder: str | Path, train_path=None) -> ClassifierEvaluation:
    """Score ``result`` (a :class:`~tactile_braille.supervised.classifier.TrainingResult`) on the
    ``validation`` dataset and write the classifier, its metrics and its confusion matrix to ``folder``."""
    from tactile_braille.supervised.classifier import (
        confusion_matrix,
        predict,
        save_classifier,
        select_classes,
    )

    classes = result.config.classes
    images, labels = select_classes(validation, classes)
    truth = np.asarray([classes[i] for i in labels])
    predicted = predict(result.model, images, classes)
    accuracy = float((predicted == truth).mean())
    matrix = confusion_matrix(truth, predicted, classes)
    mistakes = top_confusions(matrix, classes)
    metrics = {"val_accuracy": accuracy, "top_confusions": mistakes,
               "train": str(train_path), "validation": str(validation.path)}  # fmt: skip
    save_classifier(result, folder, metrics)
    save_confusion_matrix(matrix, classes, Path(folder) / "confusion.png",
                          f"validation accuracy {accuracy:.1%} ({len(truth)} images)")  # fmt: skip
    return ClassifierEvaluation(accuracy, len(truth), matrix, mistakes)
