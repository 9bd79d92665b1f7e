"""Default datasets, generated on first use into a cache directory and reused after.

The cache lives in ``$TACTILE_BRAILLE_DATA``, or else
``$XDG_CACHE_HOME/tactile_braille`` (``~/.cache/tactile_braille``). A cached
file made by another generator version, or for another keyboard or sensor, is
stale: it is regenerated (with a message), never silently reused.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import sys
import time
from pathlib import Path

from tactile_braille._io import LockedError
from tactile_braille.datasets.collector import GENERATOR_VERSION, collect, dataset_metadata
from tactile_braille.datasets.procedures import SPLIT_SEED_OFFSET, GridTaps, PerturbedTaps, Procedure
from tactile_braille.datasets.store import (
    DatasetError,
    ResumeMismatchError,
    TactileDataset,
    load_dataset,
    partial_path,
)
from tactile_braille.rigs.virtual import VirtualRig

DEFAULT_DATASETS: dict[str, Procedure] = {
    "keys-train": PerturbedTaps(keys="all", per_key=100, split="train"),
    "keys-validation": PerturbedTaps(keys="all", per_key=50, split="validation"),
    "grid-alphabet": GridTaps(keys="alphabet"),
    "grid-arrows": GridTaps(keys="arrows"),
    "grid-alphabet-6mm": GridTaps(keys="alphabet", spacing_mm=6.0),
}
"""The paper's data, by name: perturbed taps on the 31 keys + NONE (100 train,
50 validation per class), the two dense grids of the continuous tasks, and the
6 mm alphabet grid of the paper's preliminary transfer result (its Discussion:
policies trained on it sped up learning on the 3 mm grid; ``train --init-from``)."""


def data_dir() -> Path:
    """The cache directory (not created here; a generation creates it)."""
    configured = os.environ.get("TACTILE_BRAILLE_DATA")
    if configured:
        return Path(configured).expanduser()
    cache_home = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(cache_home) / "tactile_braille"


def default_dataset_path(name: str, sensor: str = "braille_331", seed: int = 0) -> Path:
    """Where the default dataset ``name`` is cached."""
    if name not in DEFAULT_DATASETS:
        raise ValueError(f"unknown default dataset {name!r}; choose one of {sorted(DEFAULT_DATASETS)}")
    return data_dir() / f"{name}__{sensor}__seed{seed}.h5"


def default_dataset(
    name: str,
    sensor: str = "braille_331",
    seed: int = 0,
    progress: bool = True,
    wait_s: float = 3600.0,
) -> TactileDataset:
    """Load the default dataset ``name``, generating it on the virtual rig if needed.

    Generation is deterministic from ``seed``; an interrupted generation is
    resumed on the next call. Where another process is generating it (two
    runs started side by side on a fresh cache), this one waits for that
    generation, up to ``wait_s`` seconds, and then loads its file (or resumes
    it, if that process died): a ``LockedError`` only after the wait.
    """
    path = default_dataset_path(name, sensor, seed)
    if not wait_s >= 0:
        raise ValueError(f"wait_s must be a number of seconds >= 0, got {wait_s!r}")
    deadline = time.monotonic() + wait_s
    announced = False
    while True:
        try:
            return _cached_or_generated(path, name, sensor, seed, progress)
        except LockedError as error:
            if time.monotonic() >= deadline:
                raise LockedError(f"{error} (waited {wait_s:g} s for it)") from None
            if not announced:
                print(f"tactile_braille: {error}; waiting for it", file=sys.stderr)
                announced = True
            time.sleep(_LOCK_POLL_S)
        except FileExistsError:
            if not path.exists():
                raise
            # another process finished the file between our look and our lock: load it


_LOCK_POLL_S = 0.5
"""How often a process waiting for another's generation looks again."""


def _cached_or_generated(path: Path, name: str, sensor: str, seed: int, progress: bool) -> TactileDataset:
    """The cached file at ``path`` if it is what ``name`` makes, else a fresh generation into it."""
    procedure = DEFAULT_DATASETS[name]
    collection_seed = seed
    if isinstance(procedure, PerturbedTaps):
        procedure = dataclasses.replace(procedure, seed=seed)  # the seed picks the poses too
        # Each split draws its own sensor noise, not the other split's.
        collection_seed = seed + SPLIT_SEED_OFFSET[procedure.split]
    rig = VirtualRig(sensor=sensor)
    expected = dataset_metadata(rig, procedure, collection_seed)
    if path.exists():
        try:
            dataset = load_dataset(path)
            if dataset.metadata == expected:
                return dataset
            reason = (
                f"generator version {dataset.metadata.generator_version} != {GENERATOR_VERSION}"
                if dataset.metadata.generator_version != GENERATOR_VERSION
                else "different procedure, keyboard or sensor parameters"
            )
        except DatasetError as error:
            reason = str(error)
        print(f"tactile_braille: regenerating stale cached dataset {path} ({reason})", file=sys.stderr)
        path.unlink()
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        collect(rig, procedure, path, seed=collection_seed, resume=True, progress=progress)
    except ResumeMismatchError as error:
        # An interrupted generation by another version or with other settings.
        print(f"tactile_braille: discarding a stale interrupted generation ({error})", file=sys.stderr)
        shutil.rmtree(partial_path(path))
        collect(rig, procedure, path, seed=collection_seed, resume=False, progress=progress)
    return load_dataset(path)
