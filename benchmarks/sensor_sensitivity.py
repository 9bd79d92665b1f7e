"""How the sensor model's skin parameters change the supervised key accuracy, side by side.

For each (skin smoothing, pin lever) pair, collects 100 train and 50
validation perturbed taps per key on the virtual rig with that sensor and
trains the paper's CNN for a few epochs (no augmentation), printing the best
validation accuracy over the 31 keys. This is how the sensor defaults were set
(docs/results.md); it takes about a minute and a half per pair.

    python benchmarks/sensor_sensitivity.py [--pairs 0.6,2.5 0.8,6.0] [--epochs 14]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import torch

from tactile_braille.datasets import PerturbedTaps, collect, load_dataset
from tactile_braille.rigs.virtual import VirtualRig
from tactile_braille.sensor.config import sensor_preset
from tactile_braille.supervised import ClassifierConfig, train_classifier


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", nargs="+", default=["0.6,2.5", "0.6,4.0", "0.6,6.0", "0.8,6.0"])
    parser.add_argument("--epochs", type=int, default=14)
    args = parser.parse_args()
    torch.set_num_threads(2)
    print(f"{'skin smoothing mm':>18s} {'pin lever mm':>13s} {'best validation accuracy':>25s}")
    for pair in args.pairs:
        smoothing, lever = (float(v) for v in pair.split(","))
        sensor = sensor_preset("braille_331", skin_smoothing_mm=smoothing, pin_length_mm=lever)
        with tempfile.TemporaryDirectory() as folder:
            train_path = collect(VirtualRig(sensor), PerturbedTaps("all", 100, "train"),
                                 Path(folder) / "train.h5", progress=False)  # fmt: skip
            validation_path = collect(VirtualRig(sensor), PerturbedTaps("all", 50, "validation"),
                                      Path(folder) / "validation.h5", seed=1, progress=False)  # fmt: skip
            result = train_classifier(load_dataset(train_path), load_dataset(validation_path),
                                      ClassifierConfig(max_epochs=args.epochs))  # fmt: skip
        best = max(entry["val_accuracy"] for entry in result.history)
        print(f"{smoothing:18.2f} {lever:13.2f} {best:25.1%}")


if __name__ == "__main__":
    main()
