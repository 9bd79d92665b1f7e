"""The default datasets cache: generated on first use, reused after, regenerated when stale."""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from conftest_datasets import FaultyRig, assert_same_arrays, cache_module, collect, collect_module
from tactile_braille._io import LockedError, exclusive_lock
from tactile_braille.datasets.cache import data_dir, default_dataset, default_dataset_path
from tactile_braille.datasets.procedures import PerturbedTaps
from tactile_braille.datasets.store import DatasetError, load_dataset, partial_path
from tactile_braille.rigs.base import RigError
from tactile_braille.rigs.virtual import VirtualRig

TINY = PerturbedTaps(keys="arrows", per_key=2)


@pytest.fixture
def cache(tmp_path, monkeypatch) -> Path:
    directory = tmp_path / "cache"
    monkeypatch.setenv("TACTILE_BRAILLE_DATA", str(directory))
    monkeypatch.setattr(cache_module, "DEFAULT_DATASETS", {"tiny": TINY})
    return directory


def _forbid_collect(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("the cached dataset should have been reused")

    monkeypatch.setattr(cache_module, "collect", refuse)


def _bump_generator_version(monkeypatch, version: str = "9.9.9+test") -> str:
    monkeypatch.setattr(cache_module, "GENERATOR_VERSION", version)
    monkeypatch.setattr(collect_module, "GENERATOR_VERSION", version)
    return version


def test_data_dir_follows_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("TACTILE_BRAILLE_DATA", str(tmp_path / "data"))
    assert data_dir() == tmp_path / "data"
    monkeypatch.delenv("TACTILE_BRAILLE_DATA")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert data_dir() == tmp_path / "xdg" / "tactile_braille"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert data_dir() == tmp_path / "home" / ".cache" / "tactile_braille"


def test_default_dataset_path_names_dataset_sensor_and_seed(cache):
    assert default_dataset_path("tiny") == cache / "tiny__braille_331__seed0.h5"
    assert default_dataset_path("tiny", sensor="tactip_127", seed=3) == cache / "tiny__tactip_127__seed3.h5"


def test_unknown_name_raises_value_error_listing_names(cache):
    for call in (default_dataset_path, default_dataset):
        with pytest.raises(ValueError, match=r"unknown default dataset 'nope'.*\['tiny'\]"):
            call("nope")
    assert not cache.exists() or not any(cache.iterdir())


def test_the_papers_datasets_are_registered():
    names = sorted(cache_module.DEFAULT_DATASETS)
    assert names == ["grid-alphabet", "grid-alphabet-6mm", "grid-arrows", "keys-train", "keys-validation"]
    assert len(cache_module.DEFAULT_DATASETS["keys-train"]) == 3200
    assert len(cache_module.DEFAULT_DATASETS["keys-validation"]) == 1600


def test_first_call_generates_second_call_reuses(cache, monkeypatch, capsys):
    path = default_dataset_path("tiny")
    assert not path.exists()
    first = default_dataset("tiny", progress=False)
    assert path.exists()
    assert len(first) == len(TINY) == 10
    assert first.metadata == collect_module.dataset_metadata(VirtualRig(), TINY, 0)
    assert list(first.label_names()[::2]) == ["UP", "DOWN", "LEFT", "RIGHT", "NONE"]
    assert "regenerating" not in capsys.readouterr().err
    assert sorted(p.name for p in cache.iterdir()) == [path.name]

    before = path.stat()
    _forbid_collect(monkeypatch)
    second = default_dataset("tiny", progress=False)
    after = path.stat()
    assert (after.st_ino, after.st_mtime_ns, after.st_size) == (
        before.st_ino,
        before.st_mtime_ns,
        before.st_size,
    )
    assert_same_arrays(second, first)
    assert capsys.readouterr().err == ""


def test_generation_is_deterministic_from_the_seed(cache, tmp_path):
    dataset = default_dataset("tiny", progress=False)
    reference = tmp_path / "reference.h5"
    collect(VirtualRig(seed=0), TINY, reference, seed=0, progress=False)
    assert_same_arrays(dataset, load_dataset(reference))
    other = default_dataset("tiny", seed=1, progress=False)
    assert other.path == cache / "tiny__braille_331__seed1.h5"
    # The seed picks the perturbed poses as well as the sensor noise.
    assert not np.array_equal(other.poses, dataset.poses)
    assert not np.array_equal(other.observations, dataset.observations)


def test_other_generator_version_regenerates_with_a_message(cache, monkeypatch, capsys):
    old = default_dataset("tiny", progress=False)
    path = default_dataset_path("tiny")
    capsys.readouterr()
    version = _bump_generator_version(monkeypatch)

    new = default_dataset("tiny", progress=False)
    err = capsys.readouterr().err
    assert f"regenerating stale cached dataset {path}" in err
    assert f"generator version {old.metadata.generator_version} != {version}" in err
    assert new.metadata.generator_version == version
    assert load_dataset(path).metadata.generator_version == version
    assert_same_arrays(new, old)  # the samples themselves did not change here

    # Regenerated once, then reused.
    _forbid_collect(monkeypatch)
    assert default_dataset("tiny", progress=False).metadata.generator_version == version
    assert capsys.readouterr().err == ""


def test_other_procedure_regenerates(cache, monkeypatch, capsys):
    default_dataset("tiny", progress=False)
    capsys.readouterr()
    monkeypatch.setattr(cache_module, "DEFAULT_DATASETS", {"tiny": PerturbedTaps(keys="arrows", per_key=3)})
    dataset = default_dataset("tiny", progress=False)
    assert len(dataset) == 15
    assert "different procedure, keyboard or sensor parameters" in capsys.readouterr().err


@pytest.mark.parametrize("damage", ["random", "truncate"])
def test_corrupt_cached_file_is_regenerated(cache, capsys, damage):
    original = default_dataset("tiny", progress=False)
    path = default_dataset_path("tiny")
    if damage == "random":
        path.write_bytes(os.urandom(2048))
    else:
        with open(path, "r+b") as handle:
            handle.truncate(path.stat().st_size // 2)
    capsys.readouterr()

    regenerated = default_dataset("tiny", progress=False)
    err = capsys.readouterr().err
    assert "regenerating stale cached dataset" in err
    assert "not a readable HDF5 file" in err
    assert_same_arrays(regenerated, original)
    assert_same_arrays(load_dataset(path), original)


def test_interrupted_generation_is_resumed(cache, monkeypatch, capsys):
    path = default_dataset_path("tiny")
    path.parent.mkdir(parents=True)
    with pytest.raises(RigError):
        collect(FaultyRig(fail_at=6, seed=0), TINY, path, seed=0, progress=False, shard_size=2)
    partial = path.with_name(path.name + ".partial")
    assert partial.exists()

    calls = []
    real_collect = cache_module.collect

    def spy(rig, procedure, output, **kwargs):
        calls.append(kwargs)
        return real_collect(rig, procedure, output, **kwargs)

    monkeypatch.setattr(cache_module, "collect", spy)
    dataset = default_dataset("tiny", progress=False)
    assert calls and calls[0]["resume"] is True
    assert not partial.exists()
    reference = cache.parent / "reference.h5"
    collect(VirtualRig(seed=0), TINY, reference, seed=0, progress=False)
    assert_same_arrays(dataset, load_dataset(reference))


def test_stale_interrupted_generation_is_regenerated(cache, monkeypatch, capsys):
    path = default_dataset_path("tiny")
    path.parent.mkdir(parents=True)
    with pytest.raises(RigError):
        collect(FaultyRig(fail_at=6, seed=0), TINY, path, seed=0, progress=False, shard_size=2)
    partial = path.with_name(path.name + ".partial")
    assert partial.exists()
    capsys.readouterr()
    version = _bump_generator_version(monkeypatch)
    dataset = default_dataset("tiny", progress=False)
    assert "stale interrupted generation" in capsys.readouterr().err
    assert dataset.metadata.generator_version == version
    assert load_dataset(path).metadata.generator_version == version
    assert len(dataset) == len(TINY)
    np.testing.assert_array_equal(dataset.tap_index, np.arange(len(TINY)))
    assert not partial.exists()


class _Holder:
    """Another writer: holds the tiny dataset's generation lock in a thread until told to let go."""

    def __init__(self):
        self.holding, self.let_go, self.released = threading.Event(), threading.Event(), False
        lock = partial_path(default_dataset_path("tiny")) / ".lock"
        self.thread = threading.Thread(target=self._hold, args=(lock,), daemon=True)
        self.thread.start()
        assert self.holding.wait(10)

    def _hold(self, lock):
        with exclusive_lock(lock, f"the dataset {default_dataset_path('tiny')}"):
            self.holding.set()
            self.let_go.wait(10)
            self.released = True

    def release(self):
        self.let_go.set()
        self.thread.join(10)


def test_a_generation_in_progress_elsewhere_is_waited_for_not_failed(cache, monkeypatch, capsys):
    # Two runs started side by side on a fresh cache: the second waits for the first's generation.
    monkeypatch.setattr(cache_module, "_LOCK_POLL_S", 0.01)
    holder = _Holder()
    attempts = []
    real_collect = cache_module.collect

    def spy(*args, **kwargs):
        if len(attempts) == 2:
            holder.release()  # the other writer ends (here without a file: it died, say)
        attempts.append(holder.released)
        return real_collect(*args, **kwargs)

    monkeypatch.setattr(cache_module, "collect", spy)
    dataset = default_dataset("tiny", progress=False)
    assert attempts == [False, False, True]  # refused twice, then generated
    assert len(dataset) == len(TINY)
    err = capsys.readouterr().err
    assert err.count("waiting for it") == 1
    assert f"the dataset {default_dataset_path('tiny')} is being written by process {os.getpid()}" in err
    assert not partial_path(default_dataset_path("tiny")).exists()


def test_the_wait_for_another_generation_is_bounded(cache, monkeypatch):
    monkeypatch.setattr(cache_module, "_LOCK_POLL_S", 0.01)
    holder = _Holder()
    try:
        with pytest.raises(LockedError, match=r"being written by process \d+.*\(waited 0.05 s for it\)"):
            default_dataset("tiny", progress=False, wait_s=0.05)
        assert not default_dataset_path("tiny").exists()
    finally:
        holder.release()


@pytest.mark.parametrize("wait_s", [-1.0, float("nan")])
def test_a_wait_that_is_not_a_duration_is_refused_before_anything_is_written(cache, wait_s):
    with pytest.raises(ValueError, match="wait_s must be a number of seconds >= 0"):
        default_dataset("tiny", progress=False, wait_s=wait_s)
    assert not cache.exists()


def test_side_by_side_generations_make_one_file_and_both_load_it(cache, monkeypatch):
    monkeypatch.setattr(cache_module, "_LOCK_POLL_S", 0.01)
    taps = []

    class SlowRig(VirtualRig):
        def tap(self, *args, **kwargs):
            taps.append(threading.get_ident())
            time.sleep(0.02)  # long enough that the second caller finds the first one writing
            return super().tap(*args, **kwargs)

    monkeypatch.setattr(cache_module, "VirtualRig", SlowRig)
    results, errors = [], []

    def load():
        try:
            results.append(default_dataset("tiny", progress=False))
        except BaseException as error:  # reported by the assertion below
            errors.append(error)

    threads = [threading.Thread(target=load) for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(60)
    assert errors == [] and len(results) == 2
    assert len(taps) == len(TINY)  # one generation, not two
    assert_same_arrays(results[0], results[1])
    assert sorted(p.name for p in cache.iterdir()) == [default_dataset_path("tiny").name]


def test_an_environment_takes_a_default_dataset_by_name(cache):
    import gymnasium as gym

    import tactile_braille  # noqa: F401 - registers the environments

    env = gym.make("tactile_braille/DiscreteArrows-v0", dataset="tiny")  # generated on first use
    assert env.unwrapped.world["dataset"] == str(default_dataset_path("tiny"))
    assert env.unwrapped.world["procedure"]["per_key"] == TINY.per_key == 2
    with pytest.raises(DatasetError, match=r"no dataset at tinny: give a dataset file or .* name \(tiny\)"):
        gym.make("tactile_braille/DiscreteArrows-v0", dataset="tinny")
