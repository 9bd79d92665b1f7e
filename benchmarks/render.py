"""Rendered-and-processed tactile observations per second on one core.

Renders random taps over the alphabet keys with the virtual rig's TacTip
(contact, skin, pins, 640x480 camera frame with noise) and runs the shared
image processing on each frame, then reports the rate for each stage side by
side. Target: at least 1,000 observations per second on one core.

    python benchmarks/render.py [--taps 2000]
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import cv2
import numpy as np

from tactile_braille.keyboard.layout import ALPHABET_KEYS
from tactile_braille.rigs.virtual import VirtualRig
from tactile_braille.sensor.processing import process_frame


def measure(sensor: str, taps: int) -> tuple[float, float]:
    """Seconds spent rendering and processing ``taps`` random taps."""
    rig = VirtualRig(sensor=sensor, seed=0)
    rng = np.random.default_rng(1)
    centres = np.array([rig.layout.centre_mm(k) for k in ALPHABET_KEYS])
    poses = centres[rng.integers(len(centres), size=taps)] + rng.uniform(-3, 3, (taps, 2))
    depths = rng.uniform(3.5, 8.0, taps)
    rig.tap(*poses[0], depths[0])  # build the rasters and caches outside the timing
    render_s = process_s = 0.0
    for (x, y), depth in zip(poses, depths, strict=True):
        start = time.perf_counter()
        frame = rig.tap(x, y, depth).frame
        middle = time.perf_counter()
        process_frame(frame, rig.sensor.config.processing)
        render_s += middle - start
        process_s += time.perf_counter() - middle
    return render_s, process_s


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--taps", type=int, default=2000)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    n = args.taps
    print(f"taps: {n} per sensor on one core (OpenCV threads: {cv2.getNumThreads()})")
    print(f"{'sensor':12s} {'render/s':>9s} {'process/s':>10s} {'obs/s':>7s} {'processing share':>17s}")
    for sensor in ("braille_331", "tactip_127"):
        render_s, process_s = measure(sensor, n)
        total = n / (render_s + process_s)
        share = process_s / (render_s + process_s)
        print(f"{sensor:12s} {n / render_s:9.0f} {n / process_s:10.0f} {total:7.0f} {share:17.1%}")
    print("target: >= 1000 rendered-and-processed observations per second (braille_331)")


if __name__ == "__main__":
    main()
