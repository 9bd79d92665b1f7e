"""Where an environment's tactile images come from, for a batch of taps at once.

* :class:`DatasetBackend`: the paper's simulation by sampling. Discrete tasks
  return a random stored image of the key under the sensor (perturbed taps);
  continuous tasks return the stored grid sample nearest to the pose, with the
  key it actuated.
* :class:`RigBackend`: taps a :class:`~tactile_braille.rigs.base.Rig` at the
  exact pose: the live renderer (``VirtualRig``) or a real robot. Actuation is
  decided by the rig (the switch model on the virtual rig).

Keys are passed as *codes*: the index of the key in the keyboard layout, or
``-1`` for none.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tactile_braille.datasets.store import DatasetError, TactileDataset, load_dataset
from tactile_braille.envs.tasks import MOVE_TAP_DEPTH_MM, PRESS_DEPTH_MM, Task
from tactile_braille.keyboard.layout import NONE_KEY, KeyboardLayout
from tactile_braille.rigs.base import Rig
from tactile_braille.sensor.processing import process_frame


def _codes_from_dataset(dataset: TactileDataset, layout: KeyboardLayout, values: np.ndarray) -> np.ndarray:
    """Map a dataset's key indices to layout codes (-1 for NONE or unknown keys)."""
    table = np.array([layout.key(n).index if n in layout else -1 for n in dataset.key_names], dtype=np.int64)
    return table[values]


class DatasetBackend:
    """Tactile images sampled from a stored dataset.

    Args:
        task: the task played.
        dataset: a loaded dataset, a path, the name of a default dataset
            (:data:`~tactile_braille.datasets.cache.DEFAULT_DATASETS`, e.g.
            ``grid-alphabet-6mm``; a file of that name takes precedence), or
            ``None`` for the task's (``keys-train`` for discrete tasks,
            ``grid-<keys>`` for continuous ones). Default datasets are
            generated into the cache on first use.
        sensor: sensor preset of the default dataset.
        layout: the keyboard.
    """

    name = "dataset"

    def __init__(
        self,
        task: Task,
        dataset: TactileDataset | str | Path | None = None,
        sensor: str = "braille_331",
        layout: KeyboardLayout | None = None,
    ) -> None:
        self.task = task
        self.layout = layout or KeyboardLayout()
        from tactile_braille.datasets.cache import DEFAULT_DATASETS, default_dataset

        if dataset is None:
            name = f"grid-{task.keys}" if task.continuous else "keys-train"
            dataset = default_dataset(name, sensor=sensor, progress=False)
        elif isinstance(dataset, str | Path) and not Path(dataset).exists():
            if str(dataset) not in DEFAULT_DATASETS:
                raise DatasetError(
                    f"no dataset at {dataset}: give a dataset file or a default dataset's name "
                    f"({', '.join(DEFAULT_DATASETS)})"
                )
            dataset = default_dataset(str(dataset), sensor=sensor, progress=False)
        elif not isinstance(dataset, TactileDataset):
            dataset = load_dataset(dataset)
        self.dataset = dataset
        self.observations = dataset.observations
        if task.continuous:
            self._index_grid(dataset)
        else:
            self._index_keys(dataset)

    def describe(self) -> dict:
        """The world the images come from: the dataset (procedure, seed, generator), its rig's parameters,
        and its samples' digest (``samples_sha256``) unless it is a default dataset holding the reference
        generation's samples (:func:`~tactile_braille.datasets.cache.reference_samples`), which its
        parameters name exactly."""
        from tactile_braille.datasets.cache import reference_samples

        metadata = self.dataset.metadata
        world = {
            "backend": self.name,
            "dataset": str(self.dataset.path),
            "procedure": metadata.procedure,
            "seed": metadata.seed,
            "generator_version": metadata.generator_version,
            "rig": metadata.rig,
            "keyboard": metadata.keyboard,
            "sensor": metadata.sensor,
        }
        if not reference_samples(self.dataset):
            world["samples_sha256"] = self.dataset.samples_sha256
        return world

    # ---------------------------------------------------------- discrete
    def _index_keys(self, dataset: TactileDataset) -> None:
        if dataset.metadata.procedure.get("procedure") != "perturbed":
            raise DatasetError(f"{dataset.path}: a discrete task needs a perturbed-taps dataset")
        labels = dataset.label_names()
        needed = [*(k for k in self.task.key_grid.ravel() if k != NONE_KEY), NONE_KEY]
        missing = sorted(set(needed) - set(labels))
        if missing:
            raise DatasetError(f"{dataset.path} has no samples of {missing}")
        # rows_by_code[c + 1] lists the samples of layout key c (row 0: NONE).
        rows = [np.flatnonzero(labels == NONE_KEY)]
        rows += [np.flatnonzero(labels == key.name) for key in self.layout.keys]
        self._counts = np.array([len(r) for r in rows])
        self._table = np.zeros((len(rows), max(self._counts.max(), 1)), dtype=np.int64)
        for i, r in enumerate(rows):
            self._table[i, : len(r)] = r

    def discrete_taps(
        self,
        codes: np.ndarray,
        press: np.ndarray,
        positions_mm: np.ndarray,
        rng: np.random.Generator,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Images for taps on keys ``codes`` (pressing where ``press``); returns (images, pressed codes)."""
        slot = codes + 1
        picks = self._table[slot, (rng.random(len(codes)) * self._counts[slot]).astype(np.int64)]
        return self.observations[picks], np.where(press & (codes >= 0), codes, -1)

    # -------------------------------------------------------- continuous
    def _index_grid(self, dataset: TactileDataset) -> None:
        if dataset.metadata.procedure.get("procedure") != "grid":
            raise DatasetError(f"{dataset.path}: a continuous task needs a grid dataset")
        poses = dataset.poses
        axes = [np.unique(np.round(poses[:, i], 6)) for i in range(3)]
        if len(dataset) != np.prod([len(a) for a in axes]):
            raise DatasetError(f"{dataset.path}: the grid is incomplete ({len(dataset)} taps)")
        steps = [a[1] - a[0] if len(a) > 1 else 1.0 for a in axes]
        self._grid_start = np.array([a[0] for a in axes])
        self._grid_step = np.array(steps)
        self._grid_shape = np.array([len(a) for a in axes])
        order = np.lexsort((poses[:, 2], poses[:, 1], poses[:, 0]))  # x outer, y, depth inner
        self._grid_rows = order
        self._grid_pressed = _codes_from_dataset(dataset, self.layout, dataset.pressed)

    def nearest_samples(self, x_mm: np.ndarray, y_mm: np.ndarray, depth_mm: np.ndarray) -> np.ndarray:
        """Rows of the stored grid samples nearest to keyboard-frame poses (clamped to the grid)."""
        pose = np.stack(np.broadcast_arrays(x_mm, y_mm, depth_mm), axis=-1)
        cell = np.rint((pose - self._grid_start) / self._grid_step).astype(np.int64)
        cell = np.minimum(np.maximum(cell, 0), self._grid_shape - 1)
        flat = (cell[..., 0] * self._grid_shape[1] + cell[..., 1]) * self._grid_shape[2] + cell[..., 2]
        return self._grid_rows[flat]

    def pressed_codes(self, x_mm: np.ndarray, y_mm: np.ndarray, depth_mm: np.ndarray) -> np.ndarray:
        """Codes of the keys taps at these poses press (-1: none), without reading their images."""
        return self._grid_pressed[self.nearest_samples(x_mm, y_mm, depth_mm)]

    @property
    def grid_depths_mm(self) -> np.ndarray:
        """The depths the grid samples (a continuous tap presses what the nearest of them pressed)."""
        return self._grid_start[2] + self._grid_step[2] * np.arange(self._grid_shape[2])

    def continuous_taps(
        self, x_mm: np.ndarray, y_mm: np.ndarray, depth_mm: np.ndarray, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        """The stored samples nearest to the poses; returns (images, pressed codes)."""
        rows = self.nearest_samples(x_mm, y_mm, depth_mm)
        return self.observations[rows], self._grid_pressed[rows]


class RigBackend:
    """Tactile images from taps of a rig at the exact pose.

    Discrete moves tap at the cell's position with the paper's perturbations
    (x, y ~ U[-1, 1] mm, depth 5 mm + U[-1, 0], yaw ~ U[-10, 10] deg), a PRESS
    goes 8 mm down (with the same perturbations, so 7-8 mm), and NONE cells
    are tapped in the air (depth 0) and never press.
    Before every tap the rig is reseeded from the environment's generator,
    so the virtual rig is deterministic from the environment's seed.

    Args:
        rig: the rig to tap with.
        device: render a batch's taps at once with the batched renderer on
            this torch device (``"cpu"``, ``"cuda"``; the virtual rig only).
            None taps one at a time. Both draw the same randomness, so the
            same seed gives the same taps, their images equal in 99.4 % of
            pixels on average (each in at least 98 %).
        name: the backend its world record names: ``"rig"`` for a rig handed in, ``"render"`` for
            the virtual rig the ``render`` backend makes.
    """

    def __init__(self, rig: Rig, device: str | None = None, name: str = "rig") -> None:
        from tactile_braille.envs.core import OBSERVATION_SIZE_PX

        if rig.processing.size_px != OBSERVATION_SIZE_PX:
            raise ValueError(
                f"the environments take {OBSERVATION_SIZE_PX}x{OBSERVATION_SIZE_PX} observations; "
                f"this rig's processing makes {rig.processing.size_px}x{rig.processing.size_px}"
            )
        if device is not None:
            if not hasattr(rig, "observe_taps"):
                raise ValueError(
                    f"a {type(rig).__name__} cannot render batches; tap one at a time: device=None"
                )
            _check_device(device)
        self.rig, self.name = rig, name
        self.layout = rig.layout
        self.device = device

    def describe(self) -> dict:
        """The world the images come from: the rig's own description (and the generator, if simulated)."""
        from tactile_braille.datasets.collector import GENERATOR_VERSION

        description = self.rig.describe()
        world = {"backend": self.name, **description}
        if description.get("rig") == "virtual":
            world["generator_version"] = GENERATOR_VERSION
        return world

    def _observe(self, x, y, depth, yaw, seeds) -> tuple[np.ndarray, np.ndarray]:
        """Tap at every pose, the rig reseeded from ``seeds`` before each; returns (images, pressed codes)."""
        if self.device is not None:
            return self.rig.observe_taps(x, y, depth, yaw, seeds, device=self.device)
        images, pressed = [], []
        for tap_x, tap_y, tap_depth, tap_yaw, seed in zip(x, y, depth, yaw, seeds, strict=True):
            self.rig.reseed(int(seed))
            sample = self.rig.tap(tap_x, tap_y, tap_depth, tap_yaw)
            images.append(process_frame(sample.frame, self.rig.processing))
            pressed.append(
                self.layout.key(sample.pressed_key).index if sample.pressed_key is not None else -1
            )
        size = self.rig.processing.size_px
        return np.stack(images) if images else np.zeros((0, size, size), np.uint8), np.array(
            pressed, np.int64
        )

    def discrete_taps(
        self,
        codes: np.ndarray,
        press: np.ndarray,
        positions_mm: np.ndarray,
        rng: np.random.Generator,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Tap every cell; returns (images, pressed codes)."""
        poses = []
        for code, pressing, (x, y) in zip(codes, press, positions_mm, strict=True):
            dx, dy = rng.uniform(-1.0, 1.0, 2)
            depth = (PRESS_DEPTH_MM if pressing else MOVE_TAP_DEPTH_MM) + rng.uniform(-1.0, 0.0)
            if code < 0:
                depth = 0.0  # an off-key cell: the sensor touches nothing
            yaw = rng.uniform(-10.0, 10.0)
            poses.append((x + dx, y + dy, depth, yaw, rng.integers(2**63 - 1)))
        x, y, depth, yaw, seeds = (
            (np.array(column) for column in zip(*poses, strict=True)) if poses else [[]] * 5
        )
        images, pressed = self._observe(x, y, depth, yaw, seeds)
        return images, np.where(np.asarray(press, bool), pressed, -1)

    def continuous_taps(
        self, x_mm: np.ndarray, y_mm: np.ndarray, depth_mm: np.ndarray, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        """Tap at every pose; returns (images, pressed codes)."""
        seeds = [rng.integers(2**63 - 1) for _ in range(len(x_mm))]
        return self._observe(x_mm, y_mm, depth_mm, np.zeros(len(x_mm)), seeds)


def _check_device(device: str) -> None:
    """Refuse a torch device that is misspelt or absent here, before anything renders."""
    import torch

    try:
        kind = torch.device(device).type
    except RuntimeError as error:
        raise ValueError(f"render device {device!r} is not a torch device ({error})") from None
    if kind == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"render device {device!r}: this machine has no CUDA device; use 'cpu' or None")
