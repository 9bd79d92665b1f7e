"""Import the original release's recordings (``targets_video.csv`` + ``videos/video_N.mp4``).

Each row of ``targets_video.csv`` names one tap's video. The original grabbed
two frames per tap and kept the second, so frame 1 (counting from 0) of each
video is the tactile image; it goes through the same :func:`process_frame` as
rendered frames. Poses become the keyboard frame:

* supervised data (``obj_lbl`` = key name) are already in it: the key centre
  ``obj_pose`` plus the jitter ``pose_1`` (x), ``pose_2`` (y), ``pose_3``
  (depth offset, in [-1, 0] mm) and ``pose_6`` (yaw);
* grid data (with ``tap_depth`` and ``pressed_buttons``) are in a task's work
  frame, placed on the keyboard by ``work_frame_origin_mm``; the rig added 2 mm
  to every ``tap_depth``.
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import io
import math
from pathlib import Path

import cv2
import numpy as np

from tactile_braille.datasets.store import DatasetError, DatasetMetadata, DatasetWriter
from tactile_braille.keyboard.calibration import RIG_TAP_OFFSET_MM, work_frame_origin_mm
from tactile_braille.keyboard.layout import NONE_KEY, KeyboardLayout
from tactile_braille.sensor.config import ImageProcessing
from tactile_braille.sensor.processing import process_frame

SUPERVISED_TAP_DEPTH_MM = 5.0
"""Nominal depth assumed for supervised taps (the release does not record it)."""


def read_video_frame(path: Path, frame_index: int = 1) -> np.ndarray:
    """Frame ``frame_index`` of a video as a grey uint8 image."""
    capture = cv2.VideoCapture(str(path))
    try:
        if not capture.isOpened():
            raise DatasetError(f"cannot open video {path}")
        frame = None
        for _ in range(frame_index + 1):
            ok, frame = capture.read()
            if not ok:
                raise DatasetError(f"video {path} has fewer than {frame_index + 1} frames")
        return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
    finally:
        capture.release()


def _parse_pose(text: str, source: object) -> list[float]:
    try:
        values = [float(v) for v in str(text).strip().strip("[]").split(",")]
    except ValueError:
        raise DatasetError(f"{source}: malformed obj_pose {text!r}") from None
    if len(values) != 6:
        raise DatasetError(f"{source}: obj_pose {text!r} should have 6 values")
    if not all(math.isfinite(v) for v in values):
        raise DatasetError(f"{source}: obj_pose {text!r} holds a value that is not a finite number")
    return values


def _number(row: dict, column: str, source: object) -> float:
    try:
        value = float(row[column])
    except (TypeError, ValueError):
        raise DatasetError(f"{source}: column {column} holds {row[column]!r}, not a number") from None
    if not math.isfinite(value):
        raise DatasetError(f"{source}: column {column} holds {row[column]!r}, not a finite number")
    return value


def _metadata(
    csv_name: str,
    csv_sha256: str,
    grid_frame: str | None,
    frame_index: int,
    processing: ImageProcessing,
    key_names,
) -> DatasetMetadata:
    """What an imported dataset records of its origin: the real rig of the original release."""
    return DatasetMetadata(
        key_names=key_names,
        procedure={
            "procedure": "grid" if grid_frame else "perturbed",
            "imported_from": csv_name,
            "csv_sha256": csv_sha256,  # what the rows hold: a resume after an edit is refused
            "grid_frame": grid_frame,
            "frame_index": frame_index,
        },
        keyboard={"source": "DREVO Excalibur 84 with 3D-printed braille keycaps (real)"},
        sensor={"source": "TacTip, 331 pins (real)", "processing": dataclasses.asdict(processing)},
        rig="original-release",
        seed=0,
        generator_version="original-release",
    )


def _tap(row: dict, grid_frame: str | None, source: str) -> tuple[float, float, float, float, str, str]:
    """A csv row's tap: x, y, depth (mm, keyboard frame), yaw (deg), its label and the key pressed."""
    x, y = _parse_pose(row["obj_pose"], source)[:2]  # the tap's yaw is pose_6 (supervised) or 0 (grid)
    if grid_frame:
        origin_x, origin_y = work_frame_origin_mm(grid_frame)
        depth = _number(row, "tap_depth", source) + RIG_TAP_OFFSET_MM
        return origin_x + x, origin_y + y, depth, 0.0, row["pressed_buttons"], row["pressed_buttons"]
    x += _number(row, "pose_1", source)
    y += _number(row, "pose_2", source)
    depth = SUPERVISED_TAP_DEPTH_MM + _number(row, "pose_3", source)
    return x, y, depth, _number(row, "pose_6", source), row["obj_lbl"], NONE_KEY


def import_original(
    csv_path: str | Path,
    output: str | Path,
    videos_dir: str | Path | None = None,
    grid_frame: str | None = None,
    frame_index: int = 1,
    processing: ImageProcessing | None = None,
    resume: bool = False,
    progress: bool = True,
    restart: bool = False,
) -> Path:
    """Convert an original-format recording to a dataset file.

    Args:
        csv_path: the ``targets_video.csv``.
        output: the dataset to write.
        videos_dir: folder of the videos (default: ``videos/`` beside the csv).
        grid_frame: for grid data, the task work frame (``"alphabet"`` or
            ``"arrows"``); ``None`` for supervised data.
        frame_index: which frame of each video to keep.
        processing: image processing (the paper's by default).
        resume: continue an interrupted import (refused if the csv changed since).
        restart: discard an interrupted import and start again (after fixing the csv).

    Raises:
        DatasetError: a malformed csv, an unknown key, a missing or short video.
    """
    csv_path = Path(csv_path)
    videos_dir = Path(videos_dir) if videos_dir is not None else csv_path.parent / "videos"
    processing = processing or ImageProcessing()
    if grid_frame is not None:
        work_frame_origin_mm(grid_frame)  # validates the name
    if not csv_path.is_file():
        raise DatasetError(f"{csv_path} is not a file (the original release's targets_video.csv)")
    text = csv_path.read_bytes()
    rows = list(csv.DictReader(io.StringIO(text.decode("utf-8", errors="replace"), newline="")))
    required = {"sensor_video", "obj_lbl", "obj_pose"}
    required |= {"tap_depth", "pressed_buttons"} if grid_frame else {"pose_1", "pose_2", "pose_3", "pose_6"}
    if not rows or not required <= set(rows[0]):
        raise DatasetError(f"{csv_path} lacks the columns {sorted(required)} of the original format")
    layout = KeyboardLayout()
    key_names = (*(key.name for key in layout.keys), NONE_KEY)
    name_index = {name: i for i, name in enumerate(key_names)}
    digest = hashlib.sha256(text).hexdigest()
    metadata = _metadata(csv_path.name, digest, grid_frame, frame_index, processing, key_names)
    writer = DatasetWriter(output, metadata, len(rows), resume=resume, restart=restart)
    pending = writer.pending()
    if progress:
        from tqdm.auto import tqdm

        pending = tqdm(pending, desc=f"importing {csv_path.name}", unit="video")
    try:
        for index in pending:
            row = rows[index]
            source = f"{csv_path}, row {index + 2}"
            if any(row.get(column) is None for column in required):
                raise DatasetError(f"{source}: the row has fewer columns than the header")
            x, y, depth, yaw, label, pressed = _tap(row, grid_frame, source)
            for key in (label, pressed):
                if key not in name_index:
                    raise DatasetError(f"{source}: unknown key {key!r}")
            image = process_frame(read_video_frame(videos_dir / row["sensor_video"], frame_index), processing)
            writer.add(index, image, (x, y, depth, yaw), name_index[label], name_index[pressed])
        writer.flush()
        return writer.finalize()
    except BaseException:
        writer.flush()  # keep what was imported
        raise
    finally:
        writer.close()  # let a retry (in this process too) take the dataset
