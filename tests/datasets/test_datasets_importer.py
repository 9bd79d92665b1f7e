"""Importing the original release's recordings (targets_video.csv + videos/video_N.mp4)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from conftest_datasets import black_frame, write_video
from tactile_braille.datasets.importer import SUPERVISED_TAP_DEPTH_MM, import_original, read_video_frame
from tactile_braille.datasets.store import DatasetError, load_dataset
from tactile_braille.keyboard.calibration import CALIBRATED_FRAMES
from tactile_braille.keyboard.layout import NONE_KEY
from tactile_braille.rigs.virtual import VirtualRig
from tactile_braille.sensor.processing import process_frame

SUPERVISED_COLUMNS = ["sensor_video", "obj_id", "obj_lbl", "obj_pose", "pose_id"] + [
    f"pose_{i}" for i in range(1, 7)
]
GRID_COLUMNS = [*SUPERVISED_COLUMNS, "tap_depth", "pressed_buttons"]

# key, (pose_1 = dx, pose_2 = dy, pose_3 = depth offset, pose_6 = yaw)
SUPERVISED_TAPS = [
    ("UP", (0.4, -0.3, -0.5, 6.0)),
    ("A", (-0.7, 0.2, -0.1, -8.0)),
    ("SPACE", (0.1, 0.9, -0.9, 2.5)),
]

# work-frame x, y, tap_depth, pressed_buttons
GRID_TAPS = [(-10.0, 5.0, 3.5, "UP"), (-20.0, -20.0, 0.0, NONE_KEY), (-3.0, 12.0, 6.0, "LEFT")]


@pytest.fixture(autouse=True)
def _isolated_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("TACTILE_BRAILLE_DATA", str(tmp_path / "cache"))


def _pose_text(x: float, y: float, yaw: float = 0.0) -> str:
    return f"[{x}, {y}, 0.0, 0.0, 0.0, {yaw}]"


def _write_csv(path: Path, columns: list[str], rows: list[dict]) -> Path:
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=columns)
        writer.writeheader()
        for row in rows:
            writer.writerow({column: row.get(column, "0.0") for column in columns})
    return path


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A tiny supervised recording whose frame 1 of each video is a real rendered frame.

    Frame 0 is black and frame 2 is the next tap's render, so that taking the
    wrong frame shows.
    """
    root = tmp_path_factory.mktemp("original")
    rig = VirtualRig(seed=None)
    renders, poses, rows = [], [], []
    for number, (key, (dx, dy, dz, yaw)) in enumerate(SUPERVISED_TAPS, start=1):
        cx, cy = rig.layout.centre_mm(key)
        pose = (cx + dx, cy + dy, SUPERVISED_TAP_DEPTH_MM + dz, yaw)
        renders.append(rig.tap(*pose).frame)
        poses.append(pose)
        rows.append(
            {
                "sensor_video": f"video_{number}.mp4", "obj_id": number, "obj_lbl": key,
                "obj_pose": _pose_text(cx, cy), "pose_id": number,
                "pose_1": dx, "pose_2": dy, "pose_3": dz, "pose_4": 0.0, "pose_5": 0.0, "pose_6": yaw,
            }
        )  # fmt: skip
    for number in range(1, len(renders) + 1):
        following = renders[number % len(renders)]
        write_video(root / "videos" / f"video_{number}.mp4", [black_frame(), renders[number - 1], following])
    _write_csv(root / "targets_video.csv", SUPERVISED_COLUMNS, rows)
    return {"root": root, "csv": root / "targets_video.csv", "renders": renders, "poses": poses, "rows": rows}


def _grid_csv(recording, path: Path) -> Path:
    rows = [
        {
            "sensor_video": f"video_{number}.mp4", "obj_id": number, "obj_lbl": f"{x}_{y}_{depth}",
            "obj_pose": _pose_text(x, y, -145.0), "pose_id": 1, "tap_depth": depth,
            "pressed_buttons": pressed,
        }
        for number, (x, y, depth, pressed) in enumerate(GRID_TAPS, start=1)
    ]  # fmt: skip
    return _write_csv(path, GRID_COLUMNS, rows)


def _mismatch(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean(a != b))


def test_video_frames_survive_the_lossy_round_trip(recording):
    frame = read_video_frame(recording["root"] / "videos" / "video_1.mp4", 1)
    assert frame.shape == (480, 640)
    assert frame.dtype == np.uint8
    assert np.abs(frame.astype(int) - recording["renders"][0]).mean() < 5
    assert read_video_frame(recording["root"] / "videos" / "video_1.mp4", 0).max() < 20  # black


def test_supervised_import_gives_the_rendered_observations(recording, tmp_path):
    output = import_original(recording["csv"], tmp_path / "imported.h5", progress=False)
    dataset = load_dataset(output, expect_procedure="perturbed")
    assert len(dataset) == len(SUPERVISED_TAPS)
    assert dataset.observations.shape == (3, 100, 100)
    assert set(np.unique(dataset.observations)) <= {0, 255}
    expected = [process_frame(render) for render in recording["renders"]]
    for index, observation in enumerate(dataset.observations):
        # mp4 is lossy: nearly all pixels agree with the render of frame 1 ...
        assert _mismatch(observation, expected[index]) <= 0.01
        # ... and far more than with any other tap's render (taps look much alike).
        others = [_mismatch(observation, other) for j, other in enumerate(expected) if j != index]
        assert _mismatch(observation, expected[index]) < min(others) / 2
        assert _mismatch(observation, process_frame(black_frame())) > 0.1


def test_supervised_import_labels_and_poses(recording, tmp_path):
    dataset = load_dataset(import_original(recording["csv"], tmp_path / "imported.h5", progress=False))
    assert list(dataset.label_names()) == [key for key, _ in SUPERVISED_TAPS]
    assert list(dataset.pressed_names()) == [NONE_KEY] * 3
    np.testing.assert_allclose(dataset.poses, recording["poses"], atol=1e-12)
    np.testing.assert_array_equal(dataset.tap_index, np.arange(3))
    metadata = dataset.metadata
    assert metadata.rig == "original-release"
    assert metadata.procedure["procedure"] == "perturbed"
    assert metadata.procedure["imported_from"] == "targets_video.csv"
    assert metadata.procedure["grid_frame"] is None
    assert metadata.procedure["frame_index"] == 1
    assert dataset.key_names[-1] == NONE_KEY


def test_frame_index_and_videos_dir_are_honoured(recording, tmp_path):
    output = import_original(
        recording["csv"], tmp_path / "frame2.h5", videos_dir=recording["root"] / "videos", frame_index=2,
        progress=False,
    )  # fmt: skip
    dataset = load_dataset(output)
    expected = [process_frame(render) for render in recording["renders"]]
    for index, observation in enumerate(dataset.observations):
        assert _mismatch(observation, expected[(index + 1) % 3]) <= 0.01
    assert dataset.metadata.procedure["frame_index"] == 2


def test_grid_import_places_taps_in_the_calibrated_frame(recording, tmp_path):
    csv_path = _grid_csv(recording, recording["root"] / "grid_targets_video.csv")
    dataset = load_dataset(
        import_original(csv_path, tmp_path / "grid.h5", grid_frame="arrows", progress=False),
        expect_procedure="grid",
    )
    frame = CALIBRATED_FRAMES["arrows"]
    expected = [
        (frame.offset_x_mm + x, frame.offset_y_mm + y, depth + 2.0, 0.0) for x, y, depth, _ in GRID_TAPS
    ]
    np.testing.assert_allclose(dataset.poses, expected, atol=1e-12)
    assert list(dataset.pressed_names()) == [pressed for *_, pressed in GRID_TAPS]
    np.testing.assert_array_equal(dataset.labels, dataset.pressed)
    assert dataset.metadata.procedure["grid_frame"] == "arrows"
    # The same videos as the supervised rows: the observations are frame 1 of each.
    for index, observation in enumerate(dataset.observations):
        assert _mismatch(observation, process_frame(recording["renders"][index])) <= 0.01


def test_grid_import_with_the_alphabet_frame(recording, tmp_path):
    csv_path = _grid_csv(recording, tmp_path / "targets_video.csv")
    dataset = load_dataset(
        import_original(
            csv_path, tmp_path / "grid.h5", videos_dir=recording["root"] / "videos", grid_frame="alphabet",
            progress=False,
        )
    )  # fmt: skip
    frame = CALIBRATED_FRAMES["alphabet"]
    np.testing.assert_allclose(dataset.poses[:, 0], [frame.offset_x_mm + x for x, *_ in GRID_TAPS])
    np.testing.assert_allclose(dataset.poses[:, 1], [frame.offset_y_mm + y for _, y, *_ in GRID_TAPS])


def test_missing_video_raises_dataset_error_naming_it(recording, tmp_path):
    rows = [dict(recording["rows"][0]), {**recording["rows"][1], "sensor_video": "video_9.mp4"}]
    csv_path = _write_csv(tmp_path / "targets_video.csv", SUPERVISED_COLUMNS, rows)
    with pytest.raises(DatasetError, match=r"video_9\.mp4"):
        import_original(
            csv_path, tmp_path / "out.h5", videos_dir=recording["root"] / "videos", progress=False
        )
    assert not (tmp_path / "out.h5").exists()


def test_short_video_raises_dataset_error(recording, tmp_path):
    write_video(tmp_path / "videos" / "video_1.mp4", [recording["renders"][0]])
    csv_path = _write_csv(tmp_path / "targets_video.csv", SUPERVISED_COLUMNS, [recording["rows"][0]])
    with pytest.raises(DatasetError, match="fewer than 2 frames"):
        import_original(csv_path, tmp_path / "out.h5", progress=False)
    assert not (tmp_path / "out.h5").exists()


def test_unknown_key_label_raises_dataset_error(recording, tmp_path):
    rows = [{**recording["rows"][0], "obj_lbl": "FOO"}]
    csv_path = _write_csv(tmp_path / "targets_video.csv", SUPERVISED_COLUMNS, rows)
    with pytest.raises(DatasetError, match="unknown key 'FOO'"):
        import_original(
            csv_path, tmp_path / "out.h5", videos_dir=recording["root"] / "videos", progress=False
        )


def test_unknown_pressed_button_raises_dataset_error(recording, tmp_path):
    csv_path = _grid_csv(recording, tmp_path / "targets_video.csv")
    text = csv_path.read_text().replace(",LEFT", ",LEFTISH")
    csv_path.write_text(text)
    with pytest.raises(DatasetError, match="row 4: unknown key 'LEFTISH'"):
        import_original(
            csv_path, tmp_path / "out.h5", videos_dir=recording["root"] / "videos", grid_frame="arrows",
            progress=False,
        )  # fmt: skip


def test_malformed_pose_raises_dataset_error(recording, tmp_path):
    for name, pose, match in (("a", "[1.0, 2.0]", "6 values"), ("b", "[x, y, z]", "malformed obj_pose")):
        rows = [{**recording["rows"][0], "obj_pose": pose}]
        csv_path = _write_csv(tmp_path / f"{name}.csv", SUPERVISED_COLUMNS, rows)
        with pytest.raises(DatasetError, match=match):
            import_original(
                csv_path, tmp_path / f"{name}.h5", videos_dir=recording["root"] / "videos", progress=False
            )


@pytest.mark.parametrize(
    ("header", "grid_frame"),
    [
        ("frame,x,y,label", None),
        ("sensor_video,obj_lbl,obj_pose", None),  # supervised jitter columns missing
        (",".join(SUPERVISED_COLUMNS), "arrows"),  # grid columns missing
    ],
)
def test_foreign_columns_raise_dataset_error(tmp_path, header, grid_frame):
    csv_path = tmp_path / "targets_video.csv"
    csv_path.write_text(header + "\n" + ",".join(["1"] * len(header.split(","))) + "\n")
    with pytest.raises(DatasetError, match="lacks the columns"):
        import_original(csv_path, tmp_path / "out.h5", grid_frame=grid_frame, progress=False)


def test_empty_csv_raises_dataset_error(tmp_path):
    csv_path = tmp_path / "targets_video.csv"
    csv_path.write_text(",".join(SUPERVISED_COLUMNS) + "\n")
    with pytest.raises(DatasetError, match="lacks the columns"):
        import_original(csv_path, tmp_path / "out.h5", progress=False)


def test_unknown_grid_frame_raises_value_error(recording, tmp_path):
    with pytest.raises(ValueError, match="no work frame 'numpad'"):
        import_original(recording["csv"], tmp_path / "out.h5", grid_frame="numpad", progress=False)


def test_import_refuses_to_overwrite(recording, tmp_path):
    output = import_original(recording["csv"], tmp_path / "imported.h5", progress=False)
    before = output.read_bytes()
    with pytest.raises(FileExistsError):
        import_original(recording["csv"], output, progress=False)
    assert output.read_bytes() == before


def test_a_nan_pose_stops_the_import_cleanly_and_restart_recovers_after_the_fix(recording, tmp_path):
    """A NaN once left a bad shard that no resume or re-run could get past."""
    from tactile_braille.datasets.store import ResumeMismatchError, partial_path

    rows = [dict(row) for row in recording["rows"]]
    rows[1]["pose_1"] = "nan"
    csv_path = _write_csv(tmp_path / "targets_video.csv", SUPERVISED_COLUMNS, rows)
    output, videos = tmp_path / "out.h5", recording["root"] / "videos"
    with pytest.raises(DatasetError, match="row 3: column pose_1 holds 'nan', not a finite number"):
        import_original(csv_path, output, videos_dir=videos, progress=False)
    assert partial_path(output).exists() and not output.exists()
    # The csv is fixed: a resume is refused (its inputs changed, by content: the name is the same) ...
    rows[1]["pose_1"] = recording["rows"][1]["pose_1"]
    _write_csv(csv_path, SUPERVISED_COLUMNS, rows)
    with pytest.raises(ResumeMismatchError, match="csv_sha256"):
        import_original(csv_path, output, videos_dir=videos, resume=True, progress=False)
    # ... and --restart discards the interrupted import and makes the whole dataset.
    made = import_original(csv_path, output, videos_dir=videos, restart=True, progress=False)
    assert len(load_dataset(made)) == len(rows) and not partial_path(output).exists()


def test_a_short_row_or_a_folder_for_a_csv_is_refused(recording, tmp_path):
    csv_path = _write_csv(tmp_path / "targets_video.csv", SUPERVISED_COLUMNS, recording["rows"][:2])
    lines = csv_path.read_text().splitlines()
    csv_path.write_text("\n".join([*lines[:2], lines[2].rsplit(",", 3)[0]]) + "\n")
    with pytest.raises(DatasetError, match="row 3: the row has fewer columns than the header"):
        import_original(
            csv_path, tmp_path / "out.h5", videos_dir=recording["root"] / "videos", progress=False
        )
    with pytest.raises(DatasetError, match="is not a file"):
        import_original(tmp_path, tmp_path / "other.h5", progress=False)
