"""Supervised key classification from single tactile images."""

from tactile_braille.supervised.classifier import (
    ClassifierConfig,
    KeyClassifier,
    TrainingResult,
    confusion_matrix,
    load_classifier,
    predict,
    save_classifier,
    train_classifier,
)

__all__ = [
    "ClassifierConfig",
    "KeyClassifier",
    "TrainingResult",
    "confusion_matrix",
    "load_classifier",
    "predict",
    "save_classifier",
    "train_classifier",
]
