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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--taps", type=int, default=2000)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    rig = VirtualRig(seed=0)
    rng = np.random.default_rng(1)
    centres = np.array([rig.layout.centre_mm(k) for k in ALPHABET_KEYS])
    poses = centres[rng.integers(len(centres), size=args.taps)] + rng.uniform(-3, 3, (args.taps, 2))
    depths = rng.uniform(3.5, 8.0, args.taps)
    rig.tap(*poses[0], depths[0])  # build the rasters and caches outside the timing

    start = time.perf_counter()
    frames = [rig.tap(x, y, d).frame for (x, y), d in zip(poses, depths, strict=True)]
    render_s = time.perf_counter() - start
    start = time.perf_counter()
    for frame in frames:
        process_frame(frame)
    process_s = time.perf_counter() - start

    n = args.taps
    print(f"taps: {n} on one core (OpenCV threads: {cv2.getNumThreads()})")
    print(f"render (switch + contact + pins + 640x480 frame): {n / render_s:8.0f} frames/s")
    print(f"process (crop, area resize, adaptive threshold):  {n / process_s:8.0f} frames/s")
    total = n / (render_s + process_s)
    print(f"rendered-and-processed observations:            {total:8.0f} obs/s (target >= 1000)")
    print(f"share of time in processing: {process_s / (render_s + process_s):.1%}")


if __name__ == "__main__":
    main()
