"""A tactile dataset is one compressed HDF5 file, written so that nothing is lost on a crash.

Layout of a finished file (``FORMAT_NAME``, ``FORMAT_VERSION``)::

    /observations  uint8  (N, S, S)  processed tactile images, 0 or 255
    /poses         float64 (N, 4)    x_mm, y_mm, depth_mm, yaw_deg (keyboard frame)
    /labels        int16  (N,)       index into key_names: the key aimed at,
                                     or for grids the key that actuated
    /pressed       int16  (N,)       index into key_names of the key that actuated
    /tap_index     int64  (N,)       position of the tap in its procedure
    attrs: format, format_version, key_names, procedure, keyboard, sensor, rig,
           seed, generator_version, created_utc (JSON strings where structured),
           samples_sha256 (:func:`samples_digest` of the arrays, taken when the
           file was written and checked whenever it is read)

Crash safety. While a collection runs, samples go to *shards*: small HDF5
files in ``<path>.partial/``, each written to a temporary name and renamed
into place when complete, so a shard either exists whole or not at all. A
killed collection (Ctrl-C, ``kill -9``, a robot fault) keeps every finished
shard; ``resume`` skips the taps they hold. When every tap is done the shards
are merged, in tap order, into ``<path>`` through a temporary file and an
atomic rename: a reader never sees a half-written dataset.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import hashlib
import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from tactile_braille._io import atomic_path, exclusive_lock

FORMAT_NAME = "tactile_braille.dataset"
FORMAT_VERSION = 1
_ARRAYS = ("observations", "poses", "labels", "pressed", "tap_index")
_DTYPES = {
    "observations": np.uint8,
    "poses": np.float64,
    "labels": np.int16,
    "pressed": np.int16,
    "tap_index": np.int64,
}
_MANIFEST = "manifest.json"


class DatasetError(ValueError):
    """A dataset file is missing, corrupt, truncated, foreign or not what was expected."""


class ResumeMismatchError(DatasetError):
    """An interrupted collection was started with other settings than the one resuming it."""


@dataclass(frozen=True)
class DatasetMetadata:
    """What a dataset is: how, with what and from what it was collected.

    Attributes:
        key_names: vocabulary of ``labels`` and ``pressed``.
        procedure: the collection procedure's description.
        keyboard: keyboard and switch parameters of the rig.
        sensor: sensor parameters of the rig.
        rig: rig name (``"virtual"``, ``"ur5"``, ``"original-release"``).
        seed: seed of the collection.
        generator_version: version of the code that generated the samples.
    """

    key_names: tuple[str, ...]
    procedure: dict
    keyboard: dict
    sensor: dict
    rig: str
    seed: int
    generator_version: str

    def __post_init__(self) -> None:
        # Normalise to what a JSON round trip gives (tuples become lists), so
        # that metadata compares equal to itself after storage.
        for name in ("procedure", "keyboard", "sensor"):
            object.__setattr__(self, name, json.loads(json.dumps(getattr(self, name), sort_keys=True)))
        object.__setattr__(self, "key_names", tuple(self.key_names))

    def to_attrs(self) -> dict[str, object]:
        return {
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION,
            "key_names": json.dumps(list(self.key_names)),
            "procedure": json.dumps(self.procedure, sort_keys=True),
            "keyboard": json.dumps(self.keyboard, sort_keys=True),
            "sensor": json.dumps(self.sensor, sort_keys=True),
            "rig": self.rig,
            "seed": int(self.seed),
            "generator_version": self.generator_version,
        }

    @classmethod
    def from_attrs(cls, attrs, source: object) -> DatasetMetadata:
        if attrs.get("format") != FORMAT_NAME:
            raise DatasetError(f"{source} is not a tactile_braille dataset (format={attrs.get('format')!r})")
        try:
            version = int(attrs.get("format_version", -1))
        except (TypeError, ValueError):
            raise DatasetError(
                f"{source} has a malformed format_version {attrs.get('format_version')!r}"
            ) from None
        if version != FORMAT_VERSION:
            raise DatasetError(
                f"{source} has format version {version}; this code reads version {FORMAT_VERSION}"
            )
        try:
            return cls(
                key_names=tuple(json.loads(attrs["key_names"])),
                procedure=json.loads(attrs["procedure"]),
                keyboard=json.loads(attrs["keyboard"]),
                sensor=json.loads(attrs["sensor"]),
                rig=str(attrs["rig"]),
                seed=int(attrs["seed"]),
                generator_version=str(attrs["generator_version"]),
            )
        except (KeyError, ValueError, TypeError) as error:
            raise DatasetError(f"{source} has missing or malformed metadata: {error}") from None

    def as_json(self) -> dict:
        return json.loads(json.dumps(self.to_attrs()))


def samples_digest(arrays: dict[str, np.ndarray]) -> str:
    """SHA-256 of a dataset's samples: each array's name, dtype, shape and bytes (C order), in the
    layout's order; the metadata aside (the fingerprint records it separately)."""
    digest = hashlib.sha256()
    for name in _ARRAYS:
        data = np.ascontiguousarray(arrays[name], dtype=np.dtype(_DTYPES[name]).newbyteorder("<"))
        digest.update(f"{name}:{data.dtype.str}:{data.shape};".encode())
        digest.update(data.tobytes())
    return digest.hexdigest()


def _write_arrays(
    path: Path, arrays: dict[str, np.ndarray], metadata: DatasetMetadata, compress: bool
) -> None:
    """Write a complete file to a temporary name, flush it to disk, rename it into place."""
    arrays = {name: np.asarray(arrays[name], dtype=_DTYPES[name]) for name in _ARRAYS}
    with atomic_path(path, fsync=True) as temporary, h5py.File(temporary, "w") as handle:
        handle.attrs.update(metadata.to_attrs())
        handle.attrs["created_utc"] = dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")
        handle.attrs["samples_sha256"] = samples_digest(arrays)
        for name in _ARRAYS:
            data = arrays[name]
            options = {}
            if compress and len(data):
                chunk_rows = max(1, min(len(data), 32 if name == "observations" else 65536))
                options = {"compression": "gzip", "compression_opts": 4, "shuffle": True}
                options["chunks"] = (chunk_rows, *data.shape[1:])
            handle.create_dataset(name, data=data, **options)


def _read_arrays(path: Path) -> tuple[DatasetMetadata, dict[str, np.ndarray], str]:
    """A file's metadata, arrays and samples digest, checked against the digest it recorded (a file
    written before digests were recorded has its digest taken now)."""
    try:
        handle = h5py.File(path, "r")
    except FileNotFoundError:
        raise DatasetError(f"no dataset at {path}") from None
    except OSError as error:
        raise DatasetError(f"{path} is not a readable HDF5 file (corrupt or truncated?): {error}") from None
    with handle:
        metadata = DatasetMetadata.from_attrs(handle.attrs, path)
        arrays = {}
        for name in _ARRAYS:
            if name not in handle:
                raise DatasetError(f"{path} lacks the array {name!r}")
            dataset = handle[name]
            if not isinstance(dataset, h5py.Dataset):
                raise DatasetError(f"{path}: {name!r} is not an array")
            if dataset.dtype != _DTYPES[name]:
                raise DatasetError(
                    f"{path}: {name} has dtype {dataset.dtype}, expected {np.dtype(_DTYPES[name])}"
                )
            try:
                arrays[name] = dataset[()]
            except OSError as error:
                raise DatasetError(f"{path}: cannot read {name} (corrupt or truncated?): {error}") from None
        recorded = handle.attrs.get("samples_sha256")
    _validate_arrays(arrays, metadata, path)
    digest = samples_digest(arrays)
    if recorded is not None and recorded != digest:
        raise DatasetError(
            f"{path}: its samples differ from those it held when it was written (digest {digest[:12]}, "
            f"recorded {str(recorded)[:12]}): it was changed or damaged; collect it again (a default "
            "dataset: delete the file and it is generated again)"
        )
    return metadata, arrays, digest


def _validate_arrays(arrays: dict[str, np.ndarray], metadata: DatasetMetadata, source: object) -> None:
    count = len(arrays["tap_index"])
    observations = arrays["observations"]
    if observations.ndim != 3 or observations.shape[1] != observations.shape[2]:
        raise DatasetError(f"{source}: observations have shape {observations.shape}, expected (N, S, S)")
    expected = {"observations": (count, *observations.shape[1:]), "poses": (count, 4)}
    expected.update({name: (count,) for name in ("labels", "pressed")})
    for name, shape in expected.items():
        if arrays[name].shape != shape:
            raise DatasetError(f"{source}: {name} has shape {arrays[name].shape}, expected {shape}")
    for name in ("labels", "pressed"):
        values = arrays[name]
        if count and (values.min() < 0 or values.max() >= len(metadata.key_names)):
            raise DatasetError(f"{source}: {name} index a key outside key_names")
    if count and not np.isfinite(arrays["poses"]).all():
        raise DatasetError(f"{source}: poses contain NaN or infinite values")
    if len(np.unique(arrays["tap_index"])) != count:
        raise DatasetError(f"{source}: duplicate tap indices")


def _short(value, width: int = 40) -> str:
    text = json.dumps(value)
    return text if len(text) <= width else text[: width - 3] + "..."


def partial_path(path: str | Path) -> Path:
    """The folder that holds the shards of an unfinished collection into ``path``."""
    path = Path(path)
    return path.with_name(path.name + ".partial")


class DatasetWriter:
    """Append samples to a dataset under construction; finalise it atomically.

    Args:
        path: the dataset file to produce.
        metadata: what the dataset is; on ``resume`` it must equal the
            interrupted collection's.
        total: number of taps of the procedure.
        resume: continue an interrupted collection instead of refusing to.
        shard_size: samples per shard (the most a crash can lose).
        restart: discard an interrupted collection (its ``.partial`` folder) and start again.
    """

    def __init__(
        self,
        path: str | Path,
        metadata: DatasetMetadata,
        total: int,
        resume: bool = False,
        shard_size: int = 256,
        restart: bool = False,
    ) -> None:
        self.path = Path(path)
        self.metadata = metadata
        self.total = int(total)
        self.shard_size = int(shard_size)
        self.partial = partial_path(self.path)
        if self.path.exists():
            raise FileExistsError(f"{self.path} exists already; remove it or choose another output")
        manifest = self.partial / _MANIFEST
        existed = self.partial.exists()
        self._lock = contextlib.ExitStack()  # one writer per dataset, held until finalize or exit
        self._lock.enter_context(exclusive_lock(self.partial / ".lock", f"the dataset {self.path}"))
        if self.path.exists():  # another writer finished it while this one waited for the lock
            with contextlib.suppress(OSError):  # our lock file, in a folder that writer removed
                (self.partial / ".lock").unlink()
                self.partial.rmdir()
            self._lock.close()
            raise FileExistsError(f"{self.path} exists already; remove it or choose another output")
        try:
            if restart and existed:  # the lock is held: no other writer is using what goes
                for item in self.partial.iterdir():
                    if item.name != ".lock":
                        if item.is_dir():
                            shutil.rmtree(item)
                        else:
                            item.unlink()
            self._open_partial(existed and manifest.exists() and not restart, resume)
        except BaseException:
            self._lock.close()
            raise
        for stale in self.partial.glob(".*.tmp"):
            stale.unlink()  # a writer killed mid-write left it
        self._done = self._indices_on_disk()
        self._buffer: dict[str, list] = {name: [] for name in _ARRAYS}

    def _open_partial(self, resuming: bool, resume: bool) -> None:
        """Check an interrupted collection's manifest against this one, or start one."""
        manifest = self.partial / _MANIFEST
        if resuming:
            if not resume:
                raise FileExistsError(
                    f"an interrupted collection is in {self.partial}; pass resume=True (--resume) "
                    "to continue it or delete that folder"
                )
            recorded = json.loads(manifest.read_text())
            wanted = {"metadata": self.metadata.as_json(), "total": self.total}
            if recorded != wanted:
                flat = [{"total": m["total"], **m["metadata"]} for m in (recorded, wanted)]
                differ = sorted(
                    k for k in flat[0].keys() | flat[1].keys() if flat[0].get(k) != flat[1].get(k)
                )
                shown = "; ".join(
                    f"{k}: {_short(flat[0].get(k))} -> {_short(flat[1].get(k))}" for k in differ[:3]
                )
                raise ResumeMismatchError(
                    f"cannot resume {self.partial}: it was started with other settings ({shown}"
                    f"{f'; and {len(differ) - 3} more' if len(differ) > 3 else ''}); resume with those, "
                    "or delete that folder"
                )
        else:
            self.partial.mkdir(parents=True, exist_ok=True)
            temporary = self.partial / f".{_MANIFEST}.tmp"
            temporary.write_text(json.dumps({"metadata": self.metadata.as_json(), "total": self.total}))
            os.replace(temporary, manifest)

    def _shards(self) -> list[Path]:
        return sorted(self.partial.glob("shard-*.h5"))

    def _indices_on_disk(self) -> set[int]:
        done: set[int] = set()
        for shard in self._shards():
            try:
                with h5py.File(shard, "r") as handle:
                    done.update(int(i) for i in handle["tap_index"][()])
            except (OSError, KeyError):
                shard.unlink()  # cannot happen with atomic renames, but never trust a broken shard
        return done

    @property
    def done(self) -> int:
        """Taps stored so far (on disk or buffered)."""
        return len(self._done) + len(self._buffer["tap_index"])

    def pending(self) -> list[int]:
        """Indices of the taps still to make, in order."""
        return [i for i in range(self.total) if i not in self._done]

    def add(self, tap_index: int, observation: np.ndarray, pose, label: int, pressed: int) -> None:
        """Buffer one sample; full buffers are written out as a shard."""
        if tap_index in self._done or not 0 <= tap_index < self.total:
            raise ValueError(f"tap {tap_index} is already stored or out of range")
        for name, value in zip(_ARRAYS, (observation, pose, label, pressed, tap_index), strict=True):
            self._buffer[name].append(value)
        if len(self._buffer["tap_index"]) >= self.shard_size:
            self.flush()

    def flush(self) -> None:
        """Write buffered samples as one shard (atomically)."""
        indices = self._buffer["tap_index"]
        if not indices:
            return
        arrays = {name: np.asarray(values) for name, values in self._buffer.items()}
        _write_arrays(self.partial / f"shard-{min(indices):09d}.h5", arrays, self.metadata, compress=False)
        self._done.update(int(i) for i in indices)
        self._buffer = {name: [] for name in _ARRAYS}

    def finalize(self) -> Path:
        """Merge the shards into the dataset file and remove the partial folder."""
        self.flush()
        if len(self._done) != self.total:
            raise RuntimeError(f"only {len(self._done)} of {self.total} taps are stored; nothing finalised")
        parts = [_read_arrays(shard)[1] for shard in self._shards()]
        merged = {name: np.concatenate([part[name] for part in parts]) for name in _ARRAYS}
        order = np.argsort(merged["tap_index"], kind="stable")
        merged = {name: values[order] for name, values in merged.items()}
        _validate_arrays(merged, self.metadata, self.path)
        _write_arrays(self.path, merged, self.metadata, compress=True)
        shutil.rmtree(self.partial)
        self.close()
        return self.path

    def close(self) -> None:
        """Let another writer continue this dataset (the process's exit does it too)."""
        self._lock.close()


@dataclass(frozen=True)
class TactileDataset:
    """A loaded dataset, held in memory for fast random access.

    Attributes:
        path: where it was read from.
        metadata: its metadata.
        samples_sha256: :func:`samples_digest` of the arrays (checked against the file's record).
        observations, poses, labels, pressed, tap_index: the arrays.
    """

    path: Path
    metadata: DatasetMetadata
    samples_sha256: str
    observations: np.ndarray
    poses: np.ndarray
    labels: np.ndarray
    pressed: np.ndarray
    tap_index: np.ndarray

    def __len__(self) -> int:
        return len(self.tap_index)

    @property
    def key_names(self) -> tuple[str, ...]:
        return self.metadata.key_names

    def label_names(self) -> np.ndarray:
        """``labels`` as key names."""
        return np.asarray(self.key_names)[self.labels]

    def pressed_names(self) -> np.ndarray:
        """``pressed`` as key names."""
        return np.asarray(self.key_names)[self.pressed]


def load_dataset(
    path: str | Path,
    expect_keyboard: dict | None = None,
    expect_sensor: dict | None = None,
    expect_procedure: str | None = None,
) -> TactileDataset:
    """Read and validate a dataset file.

    Args:
        path: the HDF5 file.
        expect_keyboard, expect_sensor: parameters the caller relies on; any
            difference raises :class:`DatasetError` naming the fields.
        expect_procedure: ``"perturbed"`` or ``"grid"``.

    Raises:
        DatasetError: missing, corrupt, truncated, foreign or mismatched file.
    """
    path = Path(path)
    metadata, arrays, digest = _read_arrays(path)
    for what, expected, actual in (
        ("keyboard", expect_keyboard, metadata.keyboard),
        ("sensor", expect_sensor, metadata.sensor),
    ):
        if expected is not None:
            expected = json.loads(json.dumps(expected))
            differing = sorted(k for k in set(expected) | set(actual) if expected.get(k) != actual.get(k))
            if differing:
                details = ", ".join(
                    f"{k}: file {actual.get(k)!r} vs expected {expected.get(k)!r}" for k in differing
                )
                raise DatasetError(f"{path} was collected with a different {what} ({details})")
    if expect_procedure is not None and metadata.procedure.get("procedure") != expect_procedure:
        raise DatasetError(
            f"{path} holds a {metadata.procedure.get('procedure')!r} dataset, expected {expect_procedure!r}"
        )
    return TactileDataset(path=path, metadata=metadata, samples_sha256=digest, **arrays)
