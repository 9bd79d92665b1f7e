"""Helpers shared by the ``test_datasets_*`` modules (plain functions and classes, imported by name).

Kept apart from ``conftest.py`` so that the datasets tests do not touch the
suite-wide fixtures.
"""

from __future__ import annotations

import importlib
import shutil
from collections.abc import Callable
from pathlib import Path

import cv2
import h5py
import numpy as np

from tactile_braille.datasets.procedures import GridTaps, PerturbedTaps
from tactile_braille.datasets.store import TactileDataset, load_dataset
from tactile_braille.rigs.base import RigError
from tactile_braille.rigs.virtual import VirtualRig

# ``tactile_braille.datasets`` re-exports the function ``collect``, which shadows the
# submodule of the same name as an attribute of the package: ``import
# tactile_braille.datasets.collector as m`` (or monkeypatching by dotted name) gives the
# function. Go through the module registry to get the module itself.
collect_module = importlib.import_module("tactile_braille.datasets.collector")
cache_module = importlib.import_module("tactile_braille.datasets.cache")
collect = collect_module.collect

ARRAY_NAMES = ("observations", "poses", "labels", "pressed", "tap_index")

SMALL_PERTURBED = PerturbedTaps(keys="arrows", per_key=3)
"""15 taps: 3 on each arrow key and 3 NONE taps."""

SMALL_GRID = GridTaps(keys="arrows", spacing_mm=5, depth_step_mm=2)
"""5 x 9 x 4 = 180 taps over the arrows work frame, some of which press keys."""


def collect_to(path: Path, procedure, seed: int = 0, rig=None, shard_size: int = 4) -> TactileDataset:
    """Collect ``procedure`` on a virtual rig into ``path`` and load it back."""
    rig = rig if rig is not None else VirtualRig(seed=0)
    collect(rig, procedure, path, seed=seed, progress=False, shard_size=shard_size)
    return load_dataset(path)


def assert_same_arrays(a: TactileDataset, b: TactileDataset) -> None:
    for name in ARRAY_NAMES:
        left, right = getattr(a, name), getattr(b, name)
        assert left.dtype == right.dtype, name
        np.testing.assert_array_equal(left, right, err_msg=name)


class FaultyRig(VirtualRig):
    """A virtual rig whose ``fail_at``-th tap (counting from 1) raises a rig fault."""

    def __init__(self, fail_at: int, **kwargs) -> None:
        super().__init__(**kwargs)
        self.fail_at = fail_at
        self.calls = 0

    def tap(self, *args, **kwargs):
        self.calls += 1
        if self.calls >= self.fail_at:
            raise RigError(f"simulated fault at call {self.calls}")
        return super().tap(*args, **kwargs)


class CountingRig(VirtualRig):
    """A virtual rig that counts its taps."""

    def __init__(self, **kwargs) -> None:
        super().__init__(**kwargs)
        self.calls = 0

    def tap(self, *args, **kwargs):
        self.calls += 1
        return super().tap(*args, **kwargs)


def shard_indices(partial: Path) -> list[int]:
    """Tap indices held by the shards of an interrupted collection, sorted."""
    indices: list[int] = []
    for shard in sorted(partial.glob("shard-*.h5")):
        with h5py.File(shard, "r") as handle:
            indices.extend(int(i) for i in handle["tap_index"][()])
    return sorted(indices)


def mutated_copy(source: Path, target: Path, change: Callable[[h5py.File], None]) -> Path:
    """Copy a dataset file and apply ``change`` to the copy opened read-write."""
    shutil.copyfile(source, target)
    with h5py.File(target, "r+") as handle:
        change(handle)
    return target


def replace_array(name: str, transform: Callable[[np.ndarray], np.ndarray]) -> Callable[[h5py.File], None]:
    """A ``change`` for :func:`mutated_copy` replacing the array ``name`` by ``transform(array)``."""

    def change(handle: h5py.File) -> None:
        data = handle[name][()]
        del handle[name]
        handle.create_dataset(name, data=transform(data))

    return change


def write_video(path: Path, frames: list[np.ndarray], fps: float = 10.0) -> Path:
    """Write grey or BGR 480 x 640 frames as a colour mp4 (``mp4v``), as the original rig did."""
    path.parent.mkdir(parents=True, exist_ok=True)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (640, 480), True)
    assert writer.isOpened(), f"OpenCV cannot write mp4v videos here ({path})"
    try:
        for frame in frames:
            writer.write(cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR) if frame.ndim == 2 else frame)
    finally:
        writer.release()
    return path


def black_frame() -> np.ndarray:
    return np.zeros((480, 640, 3), dtype=np.uint8)
