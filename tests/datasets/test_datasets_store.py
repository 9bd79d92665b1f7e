"""The HDF5 dataset store: round trips through collect, determinism, and clear errors on bad files."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import shutil

import h5py
import numpy as np
import pytest

from conftest_datasets import (
    ARRAY_NAMES,
    SMALL_GRID,
    SMALL_PERTURBED,
    CountingRig,
    FaultyRig,
    assert_same_arrays,
    collect,
    collect_to,
    mutated_copy,
    replace_array,
    shard_indices,
)
from tactile_braille.datasets.collector import GENERATOR_VERSION, dataset_metadata
from tactile_braille.datasets.procedures import PerturbedTaps
from tactile_braille.datasets.store import (
    FORMAT_NAME,
    FORMAT_VERSION,
    DatasetError,
    DatasetWriter,
    ResumeMismatchError,
    TactileDataset,
    load_dataset,
    samples_digest,
)
from tactile_braille.keyboard.layout import NONE_KEY
from tactile_braille.rigs.base import RigError
from tactile_braille.rigs.virtual import VirtualRig
from tactile_braille.sensor.processing import process_frame


@pytest.fixture(autouse=True)
def _isolated_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("TACTILE_BRAILLE_DATA", str(tmp_path / "cache"))


@pytest.fixture(scope="module")
def store_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("store")


@pytest.fixture(scope="module")
def perturbed_path(store_dir):
    path = store_dir / "perturbed.h5"
    collect(VirtualRig(seed=0), SMALL_PERTURBED, path, seed=0, progress=False, shard_size=4)
    return path


@pytest.fixture(scope="module")
def perturbed(perturbed_path) -> TactileDataset:
    return load_dataset(perturbed_path)


@pytest.fixture(scope="module")
def grid(store_dir) -> TactileDataset:
    path = store_dir / "grid.h5"
    collect(VirtualRig(seed=0), SMALL_GRID, path, seed=3, progress=False, shard_size=16)
    return load_dataset(path)


# --- round trip ----------------------------------------------------------------------------------


def test_round_trip_arrays_have_the_documented_shapes_and_dtypes(perturbed):
    n = len(SMALL_PERTURBED)
    assert len(perturbed) == n == 15
    assert perturbed.observations.shape == (n, 100, 100)
    assert perturbed.observations.dtype == np.uint8
    assert set(np.unique(perturbed.observations)) == {0, 255}
    assert perturbed.poses.shape == (n, 4)
    assert perturbed.poses.dtype == np.float64
    assert perturbed.labels.shape == perturbed.pressed.shape == (n,)
    assert perturbed.labels.dtype == perturbed.pressed.dtype == np.int16
    assert perturbed.tap_index.dtype == np.int64
    np.testing.assert_array_equal(perturbed.tap_index, np.arange(n))


def test_round_trip_metadata_equals_dataset_metadata(perturbed, perturbed_path):
    rig = VirtualRig(seed=0)
    expected = dataset_metadata(rig, SMALL_PERTURBED, 0)
    assert perturbed.metadata == expected
    assert perturbed.metadata != dataset_metadata(rig, SMALL_PERTURBED, 1)
    assert perturbed.metadata.rig == "virtual"
    assert perturbed.metadata.generator_version == GENERATOR_VERSION
    assert perturbed.key_names == (*(key.name for key in rig.layout.keys), NONE_KEY)
    assert perturbed.path == perturbed_path
    with h5py.File(perturbed_path, "r") as handle:
        assert handle.attrs["format"] == FORMAT_NAME
        assert int(handle.attrs["format_version"]) == FORMAT_VERSION
        assert json.loads(handle.attrs["procedure"])["procedure"] == "perturbed"
        assert "created_utc" in handle.attrs


def test_round_trip_leaves_only_the_finished_file(perturbed_path, perturbed):
    assert sorted(p.name for p in perturbed_path.parent.iterdir() if p.name.startswith("perturbed")) == [
        "perturbed.h5"
    ]
    assert not perturbed_path.with_name("perturbed.h5.partial").exists()


def test_perturbed_labels_are_the_aimed_keys_and_poses_the_procedures(perturbed):
    rig = VirtualRig(seed=0)
    specs = [SMALL_PERTURBED.tap(i, rig.layout) for i in range(len(SMALL_PERTURBED))]
    assert list(perturbed.label_names()) == [spec.label for spec in specs]
    assert list(perturbed.label_names()[::3]) == ["UP", "DOWN", "LEFT", "RIGHT", NONE_KEY]
    np.testing.assert_array_equal(
        perturbed.poses, [[spec.x_mm, spec.y_mm, spec.depth_mm, spec.yaw_deg] for spec in specs]
    )
    # The nominal 5 mm (at most) stops short of actuation.
    assert set(perturbed.pressed_names()) == {NONE_KEY}


def test_observations_are_the_processed_frames_of_reseeded_taps(perturbed):
    """Tap i is made with the rig reseeded from (seed, i): it can be remade alone."""
    rig = VirtualRig(seed=123)
    for index in (0, 7, 14):
        x, y, depth, yaw = perturbed.poses[index]
        rig.reseed([0, index])
        sample = rig.tap(x, y, depth, yaw)
        np.testing.assert_array_equal(
            perturbed.observations[index], process_frame(sample.frame, rig.processing)
        )
    # Without the reseed the nuisances differ, and so does the observation.
    rig.reseed([0, 99])
    x, y, depth, yaw = perturbed.poses[7]
    assert not np.array_equal(perturbed.observations[7], process_frame(rig.tap(x, y, depth, yaw).frame))


def test_grid_taps_record_the_key_the_switch_model_actuates(grid):
    rig = VirtualRig(seed=0)
    x, y, depth = grid.poses[:, 0], grid.poses[:, 1], grid.poses[:, 2]
    margin = rig.switch.actuation_margin_mm(rig.layout, x, y, depth)
    best = np.argmax(margin, axis=-1)
    names = np.array([key.name for key in rig.layout.keys])
    expected = np.where(margin[np.arange(len(best)), best] >= 0, names[best], NONE_KEY)
    np.testing.assert_array_equal(grid.pressed_names(), expected)
    # The grid is informative: some taps press arrow keys, some press nothing.
    pressed = set(grid.pressed_names())
    assert NONE_KEY in pressed
    assert len(pressed & {"UP", "DOWN", "LEFT", "RIGHT"}) >= 2
    # For grids the label is whatever actuated.
    np.testing.assert_array_equal(grid.labels, grid.pressed)


def test_grid_pressed_matches_direct_taps_at_the_stored_pose(grid):
    rig = VirtualRig(seed=0)
    actuated = np.flatnonzero(grid.pressed_names() != NONE_KEY)
    idle = np.flatnonzero(grid.pressed_names() == NONE_KEY)
    for index in [*actuated[:3], *idle[:2], actuated[-1]]:
        sample = rig.tap(*grid.poses[index])
        assert (sample.pressed_key or NONE_KEY) == grid.pressed_names()[index]


def test_grid_poses_follow_the_procedure(grid):
    layout = VirtualRig(seed=0).layout
    expected = [
        [spec.x_mm, spec.y_mm, spec.depth_mm, spec.yaw_deg]
        for spec in (SMALL_GRID.tap(i, layout) for i in range(len(SMALL_GRID)))
    ]
    np.testing.assert_array_equal(grid.poses, expected)
    assert grid.metadata.procedure == SMALL_GRID.describe()
    assert grid.metadata.seed == 3
    assert len(grid) == 180


# --- determinism ---------------------------------------------------------------------------------


def test_same_seed_gives_identical_datasets(tmp_path, perturbed):
    again = collect_to(tmp_path / "again.h5", SMALL_PERTURBED, seed=0, shard_size=5)
    assert_same_arrays(again, perturbed)
    assert again.metadata == perturbed.metadata


def test_rig_constructor_seed_does_not_matter_only_the_collection_seed(tmp_path, perturbed):
    other = collect_to(tmp_path / "other_rig.h5", SMALL_PERTURBED, seed=0, rig=VirtualRig(seed=77))
    assert_same_arrays(other, perturbed)


def test_other_collection_seed_changes_the_noise_not_the_poses(tmp_path, perturbed):
    other = collect_to(tmp_path / "seed1.h5", SMALL_PERTURBED, seed=1)
    # The procedure (and its own seed) fixes the poses ...
    np.testing.assert_array_equal(other.poses, perturbed.poses)
    np.testing.assert_array_equal(other.labels, perturbed.labels)
    # ... the collection seed the sensor nuisances.
    differing = [
        not np.array_equal(a, b) for a, b in zip(other.observations, perturbed.observations, strict=True)
    ]
    assert sum(differing) >= len(differing) - 1
    assert other.metadata.seed == 1
    assert other.metadata != perturbed.metadata


def test_other_procedure_seed_changes_the_poses(tmp_path, perturbed):
    other = collect_to(tmp_path / "pseed.h5", dataclasses.replace(SMALL_PERTURBED, seed=1), seed=0)
    np.testing.assert_array_equal(other.labels, perturbed.labels)
    assert not np.any(np.all(other.poses == perturbed.poses, axis=1))
    assert other.metadata.procedure["seed"] == 1


def test_noiseless_rig_ignores_the_collection_seed(tmp_path):
    procedure = PerturbedTaps(keys="arrows", per_key=1)
    a = collect_to(tmp_path / "a.h5", procedure, seed=0, rig=VirtualRig(seed=None))
    b = collect_to(tmp_path / "b.h5", procedure, seed=5, rig=VirtualRig(seed=None))
    np.testing.assert_array_equal(a.observations, b.observations)


# --- rig faults and resume in-process ------------------------------------------------------------


def test_rig_fault_keeps_every_sample_made_and_resume_completes(tmp_path, perturbed):
    output = tmp_path / "fault.h5"
    with pytest.raises(RigError, match="simulated fault"):
        collect(FaultyRig(fail_at=8, seed=0), SMALL_PERTURBED, output, seed=0, progress=False, shard_size=4)
    partial = output.with_name("fault.h5.partial")
    assert not output.exists()
    # Taps 0..6 were made; the buffered ones (4..6) are flushed on the way out.
    assert shard_indices(partial) == list(range(7))
    assert (partial / "manifest.json").exists()

    with pytest.raises(FileExistsError, match="resume"):
        collect(VirtualRig(seed=0), SMALL_PERTURBED, output, seed=0, progress=False, shard_size=4)
    with pytest.raises(ResumeMismatchError, match="other settings"):
        collect(VirtualRig(seed=0), SMALL_PERTURBED, output, seed=1, resume=True, progress=False)
    with pytest.raises(DatasetError, match="other settings"):
        collect(
            VirtualRig(seed=0), PerturbedTaps(keys="arrows", per_key=4), output, resume=True, progress=False
        )
    assert shard_indices(partial) == list(range(7))  # refusals touch nothing

    rig = CountingRig(seed=0)
    collect(rig, SMALL_PERTURBED, output, seed=0, resume=True, progress=False, shard_size=4)
    assert rig.calls == len(SMALL_PERTURBED) - 7  # only the missing taps were made
    assert not partial.exists()
    assert_same_arrays(load_dataset(output), perturbed)

    with pytest.raises(FileExistsError, match="exists already"):
        collect(VirtualRig(seed=0), SMALL_PERTURBED, output, seed=0, resume=True, progress=False)


def test_resume_drops_a_broken_shard_and_ignores_temporary_files(tmp_path, perturbed):
    output = tmp_path / "broken.h5"
    with pytest.raises(RigError):
        collect(FaultyRig(fail_at=13, seed=0), SMALL_PERTURBED, output, seed=0, progress=False, shard_size=4)
    partial = output.with_name("broken.h5.partial")
    assert shard_indices(partial) == list(range(12))
    # A shard cut short (as a disk fault would leave it) and a stray temporary file.
    shard = partial / "shard-000000004.h5"
    size = shard.stat().st_size
    with open(shard, "r+b") as handle:
        handle.truncate(size // 2)
    (partial / ".shard-000000008.h5.tmp-99999").write_bytes(os.urandom(512))

    rig = CountingRig(seed=0)
    collect(rig, SMALL_PERTURBED, output, seed=0, resume=True, progress=False, shard_size=4)
    assert rig.calls == len(SMALL_PERTURBED) - 8  # taps 4..7 were remade
    assert_same_arrays(load_dataset(output), perturbed)
    assert not partial.exists()


def test_resume_true_without_an_interrupted_collection_starts_fresh(tmp_path, perturbed):
    dataset = collect_to(tmp_path / "fresh.h5", SMALL_PERTURBED, seed=0)
    assert_same_arrays(dataset, perturbed)
    output = tmp_path / "fresh2.h5"
    collect(VirtualRig(seed=0), SMALL_PERTURBED, output, seed=0, resume=True, progress=False)
    assert_same_arrays(load_dataset(output), perturbed)


def test_collecting_into_a_finished_file_raises_and_keeps_it(perturbed_path):
    before = perturbed_path.read_bytes()
    with pytest.raises(FileExistsError, match="exists already"):
        collect(VirtualRig(seed=0), SMALL_PERTURBED, perturbed_path, seed=0, progress=False)
    assert perturbed_path.read_bytes() == before
    assert not perturbed_path.with_name(perturbed_path.name + ".partial").exists()


# --- the writer directly -------------------------------------------------------------------------


def _sample(index: int) -> tuple:
    observation = np.where(np.arange(100 * 100).reshape(100, 100) % (index + 2) == 0, 255, 0).astype(np.uint8)
    return observation, (float(index), -float(index), 5.0, 0.5 * index), index % 3, 0


def test_writer_merges_shards_in_tap_order(tmp_path):
    metadata = dataset_metadata(VirtualRig(seed=0), SMALL_PERTURBED, 0)
    writer = DatasetWriter(tmp_path / "w.h5", metadata, total=7, shard_size=2)
    for index in (6, 2, 4, 0, 5, 1, 3):
        writer.add(index, *_sample(index))
    assert writer.done == 7
    assert writer.pending() == [3]  # 3 is still buffered, the rest is on disk
    path = writer.finalize()
    dataset = load_dataset(path)
    np.testing.assert_array_equal(dataset.tap_index, np.arange(7))
    for index in range(7):
        observation, pose, label, pressed = _sample(index)
        np.testing.assert_array_equal(dataset.observations[index], observation)
        np.testing.assert_array_equal(dataset.poses[index], pose)
        assert dataset.labels[index] == label
        assert dataset.pressed[index] == pressed
    assert [p.name for p in tmp_path.iterdir()] == ["w.h5"]


def test_writer_rejects_duplicates_out_of_range_and_early_finalise(tmp_path):
    metadata = dataset_metadata(VirtualRig(seed=0), SMALL_PERTURBED, 0)
    writer = DatasetWriter(tmp_path / "w.h5", metadata, total=3, shard_size=1)
    writer.add(0, *_sample(0))
    with pytest.raises(ValueError, match="already stored or out of range"):
        writer.add(0, *_sample(0))
    for bad in (-1, 3):
        with pytest.raises(ValueError, match="out of range"):
            writer.add(bad, *_sample(0))
    with pytest.raises(RuntimeError, match="1 of 3"):
        writer.finalize()
    assert not (tmp_path / "w.h5").exists()


def test_one_writer_per_dataset_and_a_short_mismatch_message(tmp_path):
    from tactile_braille._io import LockedError

    metadata = dataset_metadata(VirtualRig(seed=0), SMALL_PERTURBED, 0)
    writer = DatasetWriter(tmp_path / "w.h5", metadata, total=2, shard_size=1)
    writer.add(0, *_sample(0))
    with pytest.raises(LockedError, match=f"the dataset {tmp_path / 'w.h5'} is being written by process"):
        DatasetWriter(tmp_path / "w.h5", metadata, total=2, resume=True)
    writer.close()  # as if the first writer had stopped: another may go on with it
    other = dataclasses.replace(metadata, seed=5)
    with pytest.raises(ResumeMismatchError) as refused:
        DatasetWriter(tmp_path / "w.h5", other, total=2, resume=True)
    assert "seed: 0 -> 5" in str(refused.value) and len(str(refused.value)) < 300
    again = DatasetWriter(tmp_path / "w.h5", metadata, total=2, resume=True)  # the refusal let go
    again.add(1, *_sample(1))
    assert again.finalize().exists()


def test_a_writer_that_gets_the_lock_after_another_finished_refuses(tmp_path, monkeypatch):
    # Two generations side by side: the second looks for the file, the first finishes it and lets go
    # of the lock, the second takes the lock. It must refuse, not write the dataset again.
    from tactile_braille.datasets import store as store_module

    metadata = dataset_metadata(VirtualRig(seed=0), SMALL_PERTURBED, 0)
    path = tmp_path / "w.h5"
    real_lock = store_module.exclusive_lock

    @contextlib.contextmanager
    def lock_after_the_other_finished(*args, **kwargs):
        monkeypatch.setattr(store_module, "exclusive_lock", real_lock)
        first = DatasetWriter(path, metadata, total=1, shard_size=1)
        first.add(0, *_sample(0))
        first.finalize()
        with real_lock(*args, **kwargs):
            yield

    monkeypatch.setattr(store_module, "exclusive_lock", lock_after_the_other_finished)
    with pytest.raises(FileExistsError, match="exists already"):
        DatasetWriter(path, metadata, total=1, shard_size=1)
    assert [p.name for p in tmp_path.iterdir()] == ["w.h5"]  # no partial folder left behind
    np.testing.assert_array_equal(load_dataset(path).observations[0], _sample(0)[0])


# --- loading bad files ---------------------------------------------------------------------------


def test_missing_file_raises_dataset_error(tmp_path):
    missing = tmp_path / "nowhere" / "missing.h5"
    with pytest.raises(DatasetError, match="no dataset at") as info:
        load_dataset(missing)
    assert str(missing) in str(info.value)


def test_dataset_errors_are_value_errors():
    assert issubclass(DatasetError, ValueError)
    assert issubclass(ResumeMismatchError, DatasetError)


@pytest.mark.parametrize("content", [os.urandom(4096), b"", b"\x89HDF\r\n\x1a\n" + bytes(200)])
def test_corrupt_file_raises_dataset_error(tmp_path, content):
    path = tmp_path / "corrupt.h5"
    path.write_bytes(content)
    with pytest.raises(DatasetError, match="not a readable HDF5 file"):
        load_dataset(path)


def test_directory_raises_dataset_error(tmp_path):
    with pytest.raises(DatasetError, match="not a readable HDF5 file"):
        load_dataset(tmp_path)


@pytest.mark.parametrize("fraction", [0.5, 0.97])
def test_truncated_file_raises_dataset_error(tmp_path, perturbed_path, fraction):
    path = tmp_path / "truncated.h5"
    shutil.copyfile(perturbed_path, path)
    with open(path, "r+b") as handle:
        handle.truncate(int(path.stat().st_size * fraction))
    with pytest.raises(DatasetError, match="truncated"):
        load_dataset(path)


def test_corrupt_compressed_data_raises_dataset_error(tmp_path, perturbed_path):
    path = tmp_path / "bitrot.h5"
    shutil.copyfile(perturbed_path, path)
    with h5py.File(path, "r") as handle:
        chunk = handle["observations"].id.get_chunk_info(0)
    with open(path, "r+b") as handle:
        handle.seek(chunk.byte_offset + chunk.size // 3)
        handle.write(np.random.default_rng(0).integers(0, 256, 256, dtype=np.uint8).tobytes())
    with pytest.raises(DatasetError, match="cannot read observations"):
        load_dataset(path)


def test_foreign_hdf5_file_raises_dataset_error(tmp_path):
    path = tmp_path / "foreign.h5"
    with h5py.File(path, "w") as handle:
        handle.create_dataset("images", data=np.zeros((3, 8, 8), np.uint8))
        handle.attrs["author"] = "someone else"
    with pytest.raises(DatasetError, match="not a tactile_braille dataset"):
        load_dataset(path)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda h: h.attrs.__setitem__("format", "other.format"), "not a tactile_braille dataset"),
        (lambda h: h.attrs.__setitem__("format_version", FORMAT_VERSION + 1), "format version 2"),
        (lambda h: h.attrs.__setitem__("format_version", 0), "format version 0"),
        (lambda h: h.attrs.__delitem__("format_version"), "format version -1"),
        (lambda h: h.attrs.__delitem__("rig"), "missing or malformed metadata"),
        (lambda h: h.attrs.__setitem__("procedure", "{not json"), "missing or malformed metadata"),
        (lambda h: h.attrs.__setitem__("seed", "zero"), "missing or malformed metadata"),
    ],
    ids=["format", "version+1", "version0", "no-version", "no-rig", "bad-json", "bad-seed"],
)
def test_bad_attributes_raise_dataset_error(tmp_path, perturbed_path, change, match):
    path = mutated_copy(perturbed_path, tmp_path / "bad.h5", change)
    with pytest.raises(DatasetError, match=match):
        load_dataset(path)


def test_non_numeric_format_version_raises_dataset_error(tmp_path, perturbed_path):
    path = mutated_copy(
        perturbed_path, tmp_path / "bad.h5", lambda h: h.attrs.__setitem__("format_version", "one")
    )
    with pytest.raises(DatasetError, match="malformed format_version 'one'"):
        load_dataset(path)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (replace_array("observations", lambda a: a.astype(np.float32)), "observations has dtype float32"),
        (replace_array("poses", lambda a: a.astype(np.float32)), "poses has dtype float32"),
        (replace_array("labels", lambda a: a.astype(np.int64)), "labels has dtype int64"),
        (replace_array("tap_index", lambda a: a.astype(np.int32)), "tap_index has dtype int32"),
        (replace_array("observations", lambda a: a[:, :, :50]), r"observations have shape \(15, 100, 50\)"),
        (replace_array("observations", lambda a: a[:, 0]), "observations have shape"),
        (replace_array("observations", lambda a: a[:-1]), r"observations has shape \(14, 100, 100\)"),
        (replace_array("poses", lambda a: a[:, :3]), r"poses has shape \(15, 3\), expected \(15, 4\)"),
        (replace_array("labels", lambda a: a[:-2]), r"labels has shape \(13,\)"),
        (replace_array("pressed", lambda a: a.reshape(15, 1)), "pressed has shape"),
        (replace_array("labels", lambda a: np.full_like(a, 999)), "labels index a key outside key_names"),
        (replace_array("pressed", lambda a: np.full_like(a, -1)), "pressed index a key outside key_names"),
        (
            replace_array("poses", lambda a: np.where(np.arange(a.size).reshape(a.shape) == 5, np.nan, a)),
            "NaN",
        ),
        (replace_array("tap_index", lambda a: np.zeros_like(a)), "duplicate tap indices"),
        (lambda h: h.__delitem__("pressed"), "lacks the array 'pressed'"),
    ],
)
def test_wrong_arrays_raise_dataset_error(tmp_path, perturbed_path, change, match):
    path = mutated_copy(perturbed_path, tmp_path / "bad.h5", change)
    with pytest.raises(DatasetError, match=match):
        load_dataset(path)


def test_group_in_place_of_an_array_raises_dataset_error(tmp_path, perturbed_path):
    def change(handle):
        del handle["observations"]
        handle.create_group("observations")

    path = mutated_copy(perturbed_path, tmp_path / "bad.h5", change)
    with pytest.raises(DatasetError, match="'observations' is not an array"):
        load_dataset(path)


def test_every_array_is_checked(tmp_path, perturbed_path):
    for name in ARRAY_NAMES:
        path = mutated_copy(
            perturbed_path, tmp_path / f"no-{name}.h5", lambda h, name=name: h.__delitem__(name)
        )
        with pytest.raises(DatasetError, match=f"lacks the array '{name}'"):
            load_dataset(path)


def test_the_samples_digest_is_recorded_when_written_and_checked_when_read(tmp_path, perturbed_path):
    """A file's samples are digested once, when it is written; a change to them afterwards, however it
    was made (here frames mirrored through h5py, the file's record left as it was), is refused on open."""
    dataset = load_dataset(perturbed_path)
    with h5py.File(perturbed_path, "r") as handle:
        assert (
            handle.attrs["samples_sha256"]
            == dataset.samples_sha256
            == samples_digest({name: getattr(dataset, name) for name in ARRAY_NAMES})
        )
    mirror = replace_array("observations", lambda a: a[:, :, ::-1])
    mirrored = mutated_copy(perturbed_path, tmp_path / "mirrored.h5", mirror)
    with pytest.raises(DatasetError, match=r"its samples differ from those it held when it was written"):
        load_dataset(mirrored)
    # A file written before digests were recorded has its digest taken when it is read.
    unrecorded = mutated_copy(
        perturbed_path, tmp_path / "old.h5", lambda h: h.attrs.__delitem__("samples_sha256")
    )
    assert load_dataset(unrecorded).samples_sha256 == dataset.samples_sha256


# --- expectations --------------------------------------------------------------------------------


def test_matching_expectations_load(perturbed_path):
    rig = VirtualRig(seed=0)
    description = rig.describe()
    dataset = load_dataset(
        perturbed_path,
        expect_keyboard=description["keyboard"],
        # Tuples (as in the dataclass) compare equal to the lists stored as JSON.
        expect_sensor=dataclasses.asdict(rig.sensor.config),
        expect_procedure="perturbed",
    )
    assert len(dataset) == len(SMALL_PERTURBED)


def test_keyboard_mismatch_names_the_field(perturbed_path):
    keyboard = VirtualRig(seed=0).describe()["keyboard"]
    with pytest.raises(DatasetError, match="different keyboard") as info:
        load_dataset(perturbed_path, expect_keyboard={**keyboard, "pitch_mm": keyboard["pitch_mm"] + 0.5})
    message = str(info.value)
    assert "pitch_mm: file 19.0 vs expected 19.5" in message
    assert "switch" not in message
    switch = {**keyboard["switch"], "clearance_mm": 4.0}
    with pytest.raises(DatasetError, match="switch"):
        load_dataset(perturbed_path, expect_keyboard={**keyboard, "switch": switch})


def test_sensor_mismatch_names_the_fields(perturbed_path):
    sensor = VirtualRig(seed=0).describe()["sensor"]
    changed = {**sensor, "pin_level": sensor["pin_level"] - 10, "name": "other"}
    with pytest.raises(DatasetError, match="different sensor") as info:
        load_dataset(perturbed_path, expect_sensor=changed)
    message = str(info.value)
    assert "pin_level" in message
    assert "'other'" in message
    assert "background_level" not in message
    # A field missing from the expectation is a difference too.
    reduced = {k: v for k, v in sensor.items() if k != "nuisance"}
    with pytest.raises(DatasetError, match="nuisance"):
        load_dataset(perturbed_path, expect_sensor=reduced)


def test_other_sensor_preset_is_a_mismatch(perturbed_path):
    other = VirtualRig(sensor="tactip_127", seed=0).describe()["sensor"]
    with pytest.raises(DatasetError, match="different sensor"):
        load_dataset(perturbed_path, expect_sensor=other)


def test_procedure_mismatch(perturbed_path, grid):
    with pytest.raises(DatasetError, match="'perturbed' dataset, expected 'grid'"):
        load_dataset(perturbed_path, expect_procedure="grid")
    assert len(load_dataset(grid.path, expect_procedure="grid")) == len(SMALL_GRID)
    with pytest.raises(DatasetError, match="'grid' dataset, expected 'perturbed'"):
        load_dataset(grid.path, expect_procedure="perturbed")
