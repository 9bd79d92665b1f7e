"""Rendered-and-processed tactile observations per second: the single-tap renderer and the batched one.

Renders random taps over the alphabet keys (3.5-8 mm deep, yaw within 10
degrees, with the sensor's nuisances) with the virtual rig and processes each
frame, then the same taps with the batched renderer
(:mod:`tactile_braille.sensor.batched`), and prints side by side, in one run:

* the single-tap reference (OpenCV; render and processing apart), one core;
* the batched renderer on the CPU, with its per-tap stages in OpenCV and in
  torch, one thread, with the share of pixels equal to the reference's;
* on a CUDA machine, the batched renderer at batch 4,096 (target: 100,000
  observations per second).

Targets: the single-tap renderer >= 1,000 observations per second on one core
(331-pin tip); the batched one >= 5x that on the CPU.

    python benchmarks/render.py [--taps 1000] [--gpu-batch 4096] [--figure docs/images/batched_renderer.png]

``--figure`` also draws four taps, from a light touch to a deep press, as the
reference and the batched renderer see them, and where they differ.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import cv2
import numpy as np
import torch

from tactile_braille.keyboard.layout import ALPHABET_KEYS
from tactile_braille.rigs.virtual import VirtualRig
from tactile_braille.sensor.processing import process_frame


def random_taps(rig: VirtualRig, taps: int, seed: int = 1):
    """(x, y, depth, yaw, seeds) of ``taps`` random taps over the alphabet keys."""
    rng = np.random.default_rng(seed)
    centres = np.array([rig.layout.centre_mm(k) for k in ALPHABET_KEYS])
    poses = centres[rng.integers(len(centres), size=taps)] + rng.uniform(-3, 3, (taps, 2))
    return poses[:, 0], poses[:, 1], rng.uniform(3.5, 8.0, taps), rng.uniform(-10, 10, taps), np.arange(taps)


def single_tap(rig: VirtualRig, x, y, depth, yaw, seeds) -> tuple[float, float, np.ndarray]:
    """Seconds rendering and processing each tap with the reference, and its observations."""
    render_s = process_s = 0.0
    images = []
    for tap in zip(x, y, depth, yaw, seeds, strict=True):
        start = time.perf_counter()
        rig.reseed(int(tap[-1]))
        frame = rig.tap(*tap[:-1]).frame
        middle = time.perf_counter()
        images.append(process_frame(frame, rig.sensor.config.processing))
        render_s += middle - start
        process_s += time.perf_counter() - middle
    return render_s, process_s, np.stack(images)


def batched(rig: VirtualRig, taps, device: str, kernels: str, repeats: int = 1) -> tuple[float, np.ndarray]:
    """Seconds per call of the batched renderer on ``taps`` (best of ``repeats``), and its observations."""
    rig.observe_taps(*(a[:8] for a in taps), device=device, kernels=kernels)  # tables, warm-up: not timed
    best = float("inf")
    for _ in range(repeats):
        if device.startswith("cuda"):
            torch.cuda.synchronize()
        start = time.perf_counter()
        images, _ = rig.observe_taps(*taps, device=device, kernels=kernels)  # host arrays: the copy back too
        best = min(best, time.perf_counter() - start)
    return best, images


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--taps", type=int, default=1000, help="taps per sensor on the CPU")
    parser.add_argument("--gpu-batch", type=int, default=4096, help="batch size on a CUDA device")
    parser.add_argument("--figure", help="also draw reference, batched and differences for four taps (PNG)")
    args = parser.parse_args()
    if args.figure:
        draw_comparison(args.figure)
    cv2.setNumThreads(1)
    torch.set_num_threads(1)
    n = args.taps
    print(f"taps: {n} per sensor, one core (OpenCV threads {cv2.getNumThreads()}, torch threads 1)")
    header = f"{'sensor':12s} {'renderer':34s} {'obs/s':>8s} {'x single':>9s} {'pixels equal':>13s}"
    print(header)
    for sensor in ("braille_331", "tactip_127"):
        rig = VirtualRig(sensor=sensor, seed=0)
        taps = random_taps(rig, n)
        rig.tap(taps[0][0], taps[1][0], 5.0)  # rasters and caches outside the timing
        render_s, process_s, reference = single_tap(rig, *taps)
        single = n / (render_s + process_s)
        share = process_s / (render_s + process_s)
        print(
            f"{sensor:12s} {f'single tap (processing {share:.0%})':34s} {single:8.0f} {1.0:9.2f} {'-':>13s}"
        )
        for kernels in ("opencv", "torch"):
            seconds, images = batched(rig, taps, "cpu", kernels)
            equal = (images == reference).mean()
            label = f"batched, cpu, {kernels} kernels"
            print(f"{sensor:12s} {label:34s} {n / seconds:8.0f} {n / seconds / single:9.2f} {equal:13.4f}")
        if torch.cuda.is_available():
            big = random_taps(rig, args.gpu_batch, seed=2)
            seconds, images = batched(rig, big, "cuda", "torch", repeats=5)
            equal = (images[:n] == single_tap(rig, *(a[:n] for a in big))[2]).mean()
            label = f"batched, {torch.cuda.get_device_name()} x{args.gpu_batch}"
            rate = args.gpu_batch / seconds
            print(f"{sensor:12s} {label[:34]:34s} {rate:8.0f} {rate / single:9.2f} {equal:13.4f}")
        else:
            print(f"{sensor:12s} {'batched, cuda':34s} {'(no CUDA device here)':>32s}")
    print("targets: single tap >= 1,000 obs/s (braille_331); batched on the CPU >= 5x single;")
    print("         on CUDA >= 100,000 obs/s at batch 4,096; pixels equal to the reference >= 0.995")


def draw_comparison(output: str) -> None:
    """Four taps on A (light to deep) by the reference and the batched renderer, and their differences."""
    from tactile_braille._figures import new_figure, save_figure

    rig = VirtualRig(seed=0)
    x, y = rig.layout.centre_mm("A")
    depths = np.array([4.0, 5.5, 7.0, 8.5])
    taps = (np.full(4, x + 0.8), np.full(4, y - 0.5), depths, np.full(4, 4.0), np.arange(4))
    reference = single_tap(rig, *taps)[2]
    images, _ = rig.observe_taps(*taps)
    fig, axes = new_figure(3, 4, figsize=(8.4, 6.6))
    for column, depth in enumerate(depths):
        differ = images[column] != reference[column]
        overlay = np.stack([reference[column]] * 3, axis=-1) // 2
        overlay[differ] = (255, 40, 40)
        rows = (reference[column], images[column], overlay)
        titles = (f"reference, {depth:.1f} mm", "batched", f"{differ.mean():.2%} of pixels differ")
        for row, (image, title) in enumerate(zip(rows, titles, strict=True)):
            axes[row, column].imshow(image, cmap="gray", vmin=0, vmax=255)
            axes[row, column].set_title(title, fontsize=9)
            axes[row, column].axis("off")
    fig.suptitle(
        "A tap on A (0.8 mm, -0.5 mm off its centre, yaw 4 deg): single-tap reference, batched renderer"
    )
    fig.tight_layout()
    print(f"figure: {save_figure(fig, output)}")


if __name__ == "__main__":
    main()
