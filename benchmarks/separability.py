"""Can a simple classifier tell the 31 keys apart from rendered tactile images?

Renders 100 training and 50 validation taps per key (alphabet, SPACE, arrows)
on the virtual rig with the paper's perturbations (x, y ~ U[-1, 1] mm, depth
offset ~ U[-1, 0] mm, yaw ~ U[-10, 10] deg, plus the sensor's nuisances) and
reports the validation accuracy of 1-nearest-neighbour and nearest-centroid
classifiers on the processed 100x100 images. A well-posed task sits far above
chance (1/31 = 3.2 %) and below 100 % (the CNN of the supervised issue is
what should get close to the paper's ~99 %).

    python benchmarks/separability.py [--train 100 --val 50 --seed 0]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from tactile_braille.keyboard.layout import ALL_TASK_KEYS
from tactile_braille.rigs.virtual import VirtualRig
from tactile_braille.sensor.config import sensor_preset
from tactile_braille.sensor.processing import process_frame

TAP_DEPTH_MM = 5.0


def collect(rig: VirtualRig, per_key: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    images, labels = [], []
    for label, key in enumerate(ALL_TASK_KEYS):
        x, y = rig.layout.centre_mm(key)
        for _ in range(per_key):
            dx, dy = rng.uniform(-1, 1, 2)
            dz = rng.uniform(-1, 0)
            yaw = rng.uniform(-10, 10)
            frame = rig.tap(x + dx, y + dy, TAP_DEPTH_MM + dz, yaw).frame
            images.append(process_frame(frame).ravel() > 0)
            labels.append(label)
    return np.array(images, dtype=np.float32), np.array(labels)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--train", type=int, default=100)
    parser.add_argument("--val", type=int, default=50)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--sensor", default="braille_331", help="sensor preset")
    parser.add_argument(
        "--set", action="append", default=[], metavar="FIELD=VALUE", help="override a numeric sensor field"
    )
    args = parser.parse_args()
    overrides = {field: float(value) for field, value in (item.split("=", 1) for item in args.set)}
    sensor = sensor_preset(args.sensor, **overrides)
    rng = np.random.default_rng(args.seed)
    start = time.perf_counter()
    train_x, train_y = collect(VirtualRig(sensor, seed=args.seed), args.train, rng)
    val_x, val_y = collect(VirtualRig(sensor, seed=args.seed + 1), args.val, rng)
    print(f"rendered {len(train_x) + len(val_x)} taps in {time.perf_counter() - start:.1f} s")

    # 1-NN on binary images: squared distance = |a| + |b| - 2 a.b
    distance = (val_x.sum(1)[:, None] + train_x.sum(1)[None, :]) - 2 * val_x @ train_x.T
    nn_accuracy = float((train_y[distance.argmin(1)] == val_y).mean())
    centroids = np.stack([train_x[train_y == k].mean(0) for k in range(len(ALL_TASK_KEYS))])
    centroid_distance = ((val_x[:, None, :] - centroids[None]) ** 2).sum(-1)
    centroid_accuracy = float((centroid_distance.argmin(1) == val_y).mean())
    chance = 1 / len(ALL_TASK_KEYS)
    print(f"31-key validation accuracy, 1-nearest-neighbour: {nn_accuracy:.1%} (chance {chance:.1%})")
    print(f"31-key validation accuracy, nearest centroid:    {centroid_accuracy:.1%}")


if __name__ == "__main__":
    main()
