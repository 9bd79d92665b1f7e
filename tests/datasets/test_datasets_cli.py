"""The ``collect``, ``import``, ``data`` and ``show DATASET`` commands."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from conftest_datasets import FaultyRig, black_frame, cache_module, collect, write_video
from tactile_braille.cli import build_parser, main
from tactile_braille.datasets.collector import dataset_metadata
from tactile_braille.datasets.procedures import PerturbedTaps
from tactile_braille.datasets.store import load_dataset
from tactile_braille.keyboard.layout import NONE_KEY
from tactile_braille.rigs.base import RigError
from tactile_braille.rigs.virtual import VirtualRig

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
COLLECT_ARROWS = ["collect", "--procedure", "perturbed", "--keys", "arrows", "--per-key", "2"]


@pytest.fixture(autouse=True)
def _isolated_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("TACTILE_BRAILLE_DATA", str(tmp_path / "cache"))


def test_collect_defaults():
    args = build_parser().parse_args(["collect", "--output", "x.h5"])
    assert (args.procedure, args.keys, args.rig, args.sensor) == (
        "perturbed",
        "all",
        "virtual",
        "braille_331",
    )
    assert (args.seed, args.resume, args.per_key, args.split) == (0, False, 100, "train")
    assert args.spacing_mm is None and args.depth_step_mm is None


def test_collect_writes_a_loadable_dataset_and_refuses_to_overwrite(tmp_path, capsys):
    output = tmp_path / "arrows.h5"
    assert main([*COLLECT_ARROWS, "--output", str(output)]) == 0
    assert f"wrote {output}: 10 taps" in capsys.readouterr().out
    dataset = load_dataset(output, expect_procedure="perturbed")
    assert len(dataset) == 10
    assert list(dataset.label_names()[::2]) == ["UP", "DOWN", "LEFT", "RIGHT", NONE_KEY]
    assert dataset.metadata == dataset_metadata(VirtualRig(), PerturbedTaps(keys="arrows", per_key=2), 0)
    assert [p.name for p in tmp_path.iterdir() if p.name != "cache"] == ["arrows.h5"]

    before, stat = output.read_bytes(), output.stat()
    assert main([*COLLECT_ARROWS, "--output", str(output)]) == 2
    err = capsys.readouterr().err
    assert "tactile-braille: error:" in err
    assert "exists already" in err
    assert output.read_bytes() == before
    assert output.stat().st_mtime_ns == stat.st_mtime_ns


def test_collect_seed_and_split_reach_the_procedure(tmp_path):
    output = tmp_path / "validation.h5"
    argv = [*COLLECT_ARROWS, "--split", "validation", "--seed", "4", "--output", str(output)]
    assert main(argv) == 0
    metadata = load_dataset(output).metadata
    assert metadata.seed == 4
    assert metadata.procedure["seed"] == 4
    assert metadata.procedure["split"] == "validation"


def test_collect_grid(tmp_path, capsys):
    output = tmp_path / "grid.h5"
    argv = ["collect", "--procedure", "grid", "--keys", "arrows", "--spacing-mm", "5", "--depth-step-mm", "2"]
    assert main([*argv, "--output", str(output)]) == 0
    dataset = load_dataset(output, expect_procedure="grid")
    assert len(dataset) == 5 * 9 * 4
    assert dataset.metadata.procedure["spacing_mm"] == 5
    np.testing.assert_array_equal(dataset.labels, dataset.pressed)

    png = tmp_path / "grid.png"
    assert main(["show", str(output), "--output", str(png)]) == 0
    assert png.read_bytes().startswith(PNG_SIGNATURE)
    assert f"({len(dataset)} taps in {output})" in capsys.readouterr().out


def test_collect_resume_flag(tmp_path, capsys):
    output = tmp_path / "resumed.h5"
    procedure = PerturbedTaps(keys="arrows", per_key=2, seed=0)  # what the CLI builds for COLLECT_ARROWS
    with pytest.raises(RigError):
        collect(FaultyRig(fail_at=5, seed=0), procedure, output, seed=0, progress=False, shard_size=2)
    assert main([*COLLECT_ARROWS, "--output", str(output)]) == 2
    assert "--resume" in capsys.readouterr().err
    assert main([*COLLECT_ARROWS, "--output", str(output), "--resume"]) == 0
    reference = tmp_path / "reference.h5"
    collect(VirtualRig(seed=0), procedure, reference, seed=0, progress=False)
    np.testing.assert_array_equal(load_dataset(output).observations, load_dataset(reference).observations)
    # Other settings cannot resume an interrupted collection (DatasetError is reported, exit 2).
    with pytest.raises(RigError):
        collect(FaultyRig(fail_at=5, seed=0), procedure, tmp_path / "other.h5", progress=False, shard_size=2)
    argv = [*COLLECT_ARROWS, "--seed", "1", "--output", str(tmp_path / "other.h5"), "--resume"]
    assert main(argv) == 2
    assert "cannot resume" in capsys.readouterr().err


def test_show_dataset_writes_a_png(tmp_path, capsys):
    output = tmp_path / "arrows.h5"
    assert main([*COLLECT_ARROWS, "--output", str(output)]) == 0
    png = tmp_path / "figures" / "arrows.png"
    assert main(["show", str(output), "--output", str(png)]) == 0
    data = png.read_bytes()
    assert data.startswith(PNG_SIGNATURE)
    assert len(data) > 5_000
    assert f"wrote {png} (10 taps in {output})" in capsys.readouterr().out
    assert [p.name for p in png.parent.iterdir()] == ["arrows.png"]


@pytest.mark.parametrize("content", [None, b"not an hdf5 file"])
def test_show_bad_dataset_exits_2(tmp_path, capsys, content):
    path = tmp_path / "bad.h5"
    if content is not None:
        path.write_bytes(content)
    png = tmp_path / "bad.png"
    assert main(["show", str(path), "--output", str(png)]) == 2
    err = capsys.readouterr().err
    assert "tactile-braille: error:" in err
    assert ("no dataset at" if content is None else "not a readable HDF5 file") in err
    assert not png.exists()


def test_import_command(tmp_path, capsys):
    rig = VirtualRig(seed=None)
    x, y = rig.layout.centre_mm("DOWN")
    frame = rig.tap(x, y, 5.0).frame
    write_video(tmp_path / "videos" / "video_1.mp4", [black_frame(), frame, black_frame()])
    columns = ["sensor_video", "obj_id", "obj_lbl", "obj_pose", "pose_id"] + [
        f"pose_{i}" for i in range(1, 7)
    ]
    csv_path = tmp_path / "targets_video.csv"
    with open(csv_path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(columns)
        writer.writerow(["video_1.mp4", 1, "DOWN", f"[{x}, {y}, 0, 0, 0, 0]", 1, 0, 0, 0, 0, 0, 0])
    output = tmp_path / "imported.h5"
    assert main(["import", str(csv_path), "--output", str(output)]) == 0
    assert f"wrote {output}" in capsys.readouterr().out
    dataset = load_dataset(output)
    assert list(dataset.label_names()) == ["DOWN"]
    assert main(["import", str(csv_path), "--output", str(output)]) == 2
    assert "exists already" in capsys.readouterr().err
    (tmp_path / "videos" / "video_1.mp4").unlink()
    assert main(["import", str(csv_path), "--output", str(tmp_path / "again.h5")]) == 2
    assert "video_1.mp4" in capsys.readouterr().err


def test_data_command_generates_then_reuses(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(cache_module, "DEFAULT_DATASETS", {"tiny": PerturbedTaps(keys="arrows", per_key=2)})
    assert main(["data"]) == 0
    out = capsys.readouterr().out
    path = tmp_path / "cache" / "tiny__braille_331__seed0.h5"
    assert "tiny" in out
    assert "10 taps" in out
    assert str(path) in out
    mtime = path.stat().st_mtime_ns
    assert main(["data"]) == 0
    assert path.stat().st_mtime_ns == mtime
    assert main(["data", "--seed", "2"]) == 0
    assert (tmp_path / "cache" / "tiny__braille_331__seed2.h5").exists()
