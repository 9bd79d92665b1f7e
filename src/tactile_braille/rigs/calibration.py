"""Calibrating the UR5 rig: where the keyboard is, where the sensor is in the camera image.

(The switch model's calibration on the real activation maps is
:mod:`tactile_braille.keyboard.calibration`; this module sets up a rig.)

* :func:`record_reference_poses` and :func:`fit_work_frame`: the operator
  jogs the sensor's tip onto the centres of a few reference keys; a
  least-squares rigid fit of the key centres to the recorded tool positions
  gives the work frame for :class:`~tactile_braille.rigs.ur5.UR5Config`,
  with the residual of each key.
* :func:`propose_crop_box`: the square box around the sensor's bright pins
  in a raw camera frame, for ``UR5Config.crop_px``.
* :func:`save_threshold_preview`: raw frame with the box, the cropped image
  and the binary observation side by side, to check the threshold.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from tactile_braille._io import atomic_path
from tactile_braille.keyboard.layout import KeyboardLayout
from tactile_braille.rigs.transforms import FramePose
from tactile_braille.sensor.config import ImageProcessing
from tactile_braille.sensor.processing import process_frame

REFERENCE_KEYS: tuple[str, ...] = ("Q", "P", "Z", "RIGHT")
"""Keys far apart on the keyboard: jogging to these fixes the frame well."""


@dataclass(frozen=True)
class WorkFrameFit:
    """A fitted work frame and how well the reference keys agree with it.

    Attributes:
        work_frame_mm_deg: the frame for ``UR5Config.work_frame_mm_deg``
            (origin ``clearance_mm`` above the Q key's top, z down).
        residuals_mm: per key, the distance between its recorded position and
            the fitted centre, in the keyboard's plane.
        rms_mm: root mean square of the residuals.
        height_spread_mm: highest minus lowest recorded key top (a level keyboard: under ~0.5).
    """

    work_frame_mm_deg: FramePose
    residuals_mm: dict[str, float]
    rms_mm: float
    height_spread_mm: float


def fit_work_frame(
    tool_poses: Mapping[str, Sequence[float]],
    clearance_mm: float = 3.5,
    layout: KeyboardLayout | None = None,
) -> WorkFrameFit:
    """The work frame that best maps key centres onto tool positions recorded on them.

    The keyboard is taken to lie flat in the base frame's x-y plane (the work
    frame's z pointing straight down); its position and its rotation about the
    vertical are a 2D rigid least-squares fit (Kabsch), and the origin's
    height is the mean recorded key-top height plus ``clearance_mm``.

    Args:
        tool_poses: key name -> UR tool pose ``[x_m, y_m, z_m, rx, ry, rz]``
            recorded with the sensor's tip on the centre of that key's top
            (the tool centre point set to the tip). At least two keys.
        clearance_mm: height of the work-frame origin above the key tops.
        layout: the keyboard.

    Raises:
        ValueError: fewer than two keys, an unknown key, or poses that cannot belong to those keys.
    """
    layout = layout or KeyboardLayout()
    if len(tool_poses) < 2:
        raise ValueError(f"need the tool poses of at least two keys, got {sorted(tool_poses)}")
    names = list(tool_poses)
    keyboard = np.array([layout.centre_mm(name) for name in names], dtype=np.float64)
    measured = np.array([np.asarray(tool_poses[name], dtype=np.float64)[:3] * 1000.0 for name in names])
    if not np.isfinite(measured).all():
        raise ValueError("tool poses must be finite numbers")
    # Work x, y seen from above the table: the frame is turned over (z down), so y flips.
    source = keyboard * np.array([1.0, -1.0])
    target = measured[:, :2]
    source_mean, target_mean = source.mean(axis=0), target.mean(axis=0)
    a, b = source - source_mean, target - target_mean
    if np.linalg.norm(b) < 0.5 * np.linalg.norm(a):
        raise ValueError(
            f"the tool poses of {names} are closer together than the keys are: did the arm move between keys?"
        )
    h = a.T @ b
    yaw = np.arctan2(h[0, 1] - h[1, 0], h[0, 0] + h[1, 1])
    rotation = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    origin = target_mean - rotation @ source_mean
    fitted = source @ rotation.T + origin
    residuals = np.linalg.norm(fitted - target, axis=1)
    heights = measured[:, 2]
    frame = (float(origin[0]), float(origin[1]), float(heights.mean() + clearance_mm), 180.0, 0.0,
             float(np.degrees(yaw)))  # fmt: skip
    return WorkFrameFit(
        work_frame_mm_deg=frame,
        residuals_mm={name: float(r) for name, r in zip(names, residuals, strict=True)},
        rms_mm=float(np.sqrt(np.mean(residuals**2))),
        height_spread_mm=float(heights.max() - heights.min()),
    )


def ask_operator(key: str) -> None:
    """Wait until the operator has jogged the sensor onto ``key`` and pressed Enter."""
    input(f"Jog the sensor's tip onto the centre of the {key} key's top (just touching), then press Enter: ")


def record_reference_poses(
    read_tool_pose: Callable[[], Sequence[float]],
    keys: Sequence[str] = REFERENCE_KEYS,
    wait: Callable[[str], object] = ask_operator,
) -> dict[str, list[float]]:
    """Have the sensor put on each reference key in turn and record the tool pose there.

    Args:
        read_tool_pose: reads the tool's actual pose (``URArm.tool_pose``); the
            controller's TCP must be the sensor's tip.
        keys: the reference keys, far apart.
        wait: ``wait(key)`` returns once the sensor's tip is on ``key``
            (by default the operator jogs it there and presses Enter).
    """
    poses = {}
    for key in keys:
        wait(key)
        poses[key] = [float(v) for v in read_tool_pose()]
    return poses


def propose_crop_box(frame: np.ndarray, margin: float = 1.05) -> tuple[int, int, int, int]:
    """A square ``(x0, y0, x1, y1)`` box around the sensor's pins in a raw frame.

    The pins are the bright blobs left by an Otsu threshold; the box is
    centred on their centroid, with a half-side of the farthest pin's reach
    times ``margin``, moved (not shrunk) to stay inside the frame. On the
    virtual sensor it gives the paper's box to within a few pixels.

    Raises:
        ValueError: no pin-like blobs in the frame (camera covered, lights off?).
    """
    grey = np.asarray(frame)
    if grey.ndim == 3:
        grey = cv2.cvtColor(grey, cv2.COLOR_BGR2GRAY)
    if grey.dtype != np.uint8 or grey.ndim != 2:
        raise ValueError(f"expected a uint8 grey or BGR frame, got {grey.dtype} of shape {grey.shape}")
    blurred = cv2.GaussianBlur(grey, (5, 5), 0)
    _, binary = cv2.threshold(blurred, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    _, _, stats, centroids = cv2.connectedComponentsWithStats(binary)
    areas = stats[1:, cv2.CC_STAT_AREA]
    if len(areas) < 10:
        raise ValueError(f"found {len(areas)} bright blobs, too few to be the sensor's pins")
    typical = np.median(areas)
    pins = (areas >= typical / 4) & (areas <= typical * 4)  # drops noise specks and the rim's glare
    centres = centroids[1:][pins]
    radii = np.sqrt(areas[pins] / np.pi)
    centre = centres.mean(axis=0)
    reach = float((np.linalg.norm(centres - centre, axis=1) + radii).max())
    half = int(np.ceil(reach * margin))
    height, width = grey.shape
    side = min(2 * half, width, height)
    x0 = int(np.clip(round(centre[0]) - side // 2, 0, width - side))
    y0 = int(np.clip(round(centre[1]) - side // 2, 0, height - side))
    return x0, y0, x0 + side, y0 + side


def threshold_preview(frame: np.ndarray, processing: ImageProcessing) -> np.ndarray:
    """Raw frame with the crop box | cropped image | binary observation, as one BGR image."""
    grey = np.asarray(frame)
    if grey.ndim == 3:
        grey = cv2.cvtColor(grey, cv2.COLOR_BGR2GRAY)
    x0, y0, x1, y1 = processing.crop_px
    height = grey.shape[0]
    raw = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
    cv2.rectangle(raw, (x0, y0), (x1 - 1, y1 - 1), (0, 200, 255), 2)
    cropped = cv2.resize(grey[y0:y1, x0:x1], (height, height), interpolation=cv2.INTER_AREA)
    binary = cv2.resize(process_frame(grey, processing), (height, height), interpolation=cv2.INTER_NEAREST)
    panels = [raw, cv2.cvtColor(cropped, cv2.COLOR_GRAY2BGR), cv2.cvtColor(binary, cv2.COLOR_GRAY2BGR)]
    for panel, title in zip(panels, ("raw frame + crop box", "cropped", "observation"), strict=True):
        cv2.putText(panel, title, (8, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (0, 200, 255), 2)
    return np.hstack(panels)


def save_threshold_preview(frame: np.ndarray, processing: ImageProcessing, path: str | Path) -> Path:
    """Write :func:`threshold_preview` as a PNG (atomically)."""
    image = threshold_preview(frame, processing)
    ok, encoded = cv2.imencode(".png", image)
    if not ok:
        raise ValueError("could not encode the preview as PNG")
    with atomic_path(path) as temporary:
        temporary.write_bytes(encoded.tobytes())
    return Path(path)
