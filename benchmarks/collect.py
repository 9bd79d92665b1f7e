"""Collection and read rates of tactile datasets, side by side.

Collects a perturbed-tap dataset from the virtual rig into a temporary HDF5
file (render + process + store, with the crash-safe shard writer), then times
random-access reads of single samples three ways: from the loaded in-memory
dataset, from the open HDF5 file (one h5py read per sample), and a batch of
256 random samples from memory.

    python benchmarks/collect.py [--per-key 40]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import cv2
import h5py
import numpy as np

from tactile_braille.datasets import PerturbedTaps, collect, load_dataset
from tactile_braille.rigs.virtual import VirtualRig


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--per-key", type=int, default=40)
    parser.add_argument("--reads", type=int, default=20000)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    procedure = PerturbedTaps(keys="all", per_key=args.per_key)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "bench.h5"
        rig = VirtualRig()
        start = time.perf_counter()
        collect(rig, procedure, path, progress=False)
        collect_s = time.perf_counter() - start
        size_mb = path.stat().st_size / 1e6

        start = time.perf_counter()
        dataset = load_dataset(path)
        load_s = time.perf_counter() - start
        rng = np.random.default_rng(0)
        picks = rng.integers(len(dataset), size=args.reads)

        start = time.perf_counter()
        for i in picks:
            dataset.observations[i].copy()
        memory_s = time.perf_counter() - start

        file_reads = min(args.reads, 2000)
        with h5py.File(path, "r") as handle:
            observations = handle["observations"]
            start = time.perf_counter()
            for i in picks[:file_reads]:
                observations[int(i)]
            file_s = time.perf_counter() - start

        batches = args.reads // 256
        start = time.perf_counter()
        for _ in range(batches):
            dataset.observations[rng.integers(len(dataset), size=256)]
        batch_s = time.perf_counter() - start

    n = len(procedure)
    print(
        f"collect from the virtual rig: {n / collect_s:8.0f} samples/s ({n} taps, {size_mb:.1f} MB on disk)"
    )
    print(f"load and validate the file:   {n / load_s:8.0f} samples/s")
    print(f"random single reads, memory:  {args.reads / memory_s:8.0f} samples/s")
    print(f"random single reads, HDF5:    {file_reads / file_s:8.0f} samples/s "
          f"({(args.reads / memory_s) / (file_reads / file_s):.0f}x slower than memory)")  # fmt: skip
    print(f"random batches of 256, memory:{batches * 256 / batch_s:8.0f} samples/s")


if __name__ == "__main__":
    main()
