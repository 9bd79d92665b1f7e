"""Robustness of the supervised key classifier, side by side in one run.

Trains the paper's CNN once on the cached ``keys-train`` (early stopping on
``keys-validation``), then measures its accuracy over the 31 keys on fresh
live renders (new poses, new sensor noise) while varying one thing at a time:
the perturbation size of the taps, and the camera's pixel noise.

    python benchmarks/classifier_robustness.py [--epochs 60] [--per-key 30]
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np
import torch

from tactile_braille.datasets import PerturbedTaps, default_dataset
from tactile_braille.keyboard.layout import ALL_TASK_KEYS
from tactile_braille.rigs.virtual import VirtualRig
from tactile_braille.sensor.config import sensor_preset
from tactile_braille.sensor.processing import process_frame
from tactile_braille.supervised import ClassifierConfig, predict, train_classifier


def live_accuracy(model, config, rig: VirtualRig, procedure: PerturbedTaps, seed: int) -> float:
    """Accuracy on live renders of ``procedure`` (key classes only)."""
    images, labels = [], []
    for index in range(len(procedure)):
        tap = procedure.tap(index, rig.layout)
        if tap.label not in config.classes:
            continue
        rig.reseed([seed, index])
        frame = rig.tap(tap.x_mm, tap.y_mm, tap.depth_mm, tap.yaw_deg).frame
        images.append(process_frame(frame, rig.processing))
        labels.append(tap.label)
    return float((predict(model, np.stack(images), config.classes) == np.array(labels)).mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--epochs", type=int, default=60)
    parser.add_argument("--per-key", type=int, default=30)
    args = parser.parse_args()
    torch.set_num_threads(2)
    start = time.perf_counter()
    config = ClassifierConfig(max_epochs=args.epochs, classes=ALL_TASK_KEYS)
    result = train_classifier(default_dataset("keys-train"), default_dataset("keys-validation"), config)
    best = result.history[result.best_epoch]
    print(f"trained in {time.perf_counter() - start:.0f} s; validation accuracy {best['val_accuracy']:.1%} "
          f"at epoch {result.best_epoch}")  # fmt: skip

    base = PerturbedTaps(keys="all", per_key=args.per_key, split="validation", seed=12345, include_none=False)
    print("\naccuracy on live renders at new poses, by perturbation size (x, y range; yaw range)")
    for factor in (0.5, 1.0, 2.0, 3.0):
        procedure = dataclasses.replace(base, position_range_mm=1.0 * factor, yaw_range_deg=10.0 * factor)
        accuracy = live_accuracy(result.model, config, VirtualRig(), procedure, seed=7)
        print(f"  +-{factor:.1f} mm, +-{10 * factor:4.0f} deg: {accuracy:6.1%}")
    print("\naccuracy on live renders at new poses, by camera pixel noise (trained at std 6)")
    for noise in (0.0, 6.0, 12.0, 24.0):
        sensor = sensor_preset("braille_331")
        sensor = dataclasses.replace(
            sensor, nuisance=dataclasses.replace(sensor.nuisance, pixel_noise_std=noise)
        )
        accuracy = live_accuracy(result.model, config, VirtualRig(sensor), base, seed=8)
        print(f"  pixel noise std {noise:4.0f}: {accuracy:6.1%}")


if __name__ == "__main__":
    main()
