"""The real robot's activation maps, and how well the switch model reproduces them.

The original release recorded, for a dense grid of taps (x, y, depth) over
the alphabet keys and over the arrow block, which key registered. Each map was
recorded in its own work frame; :class:`FrameTransform` places it on the
keyboard. The switch model's physical parameters are shared by both maps; only
the frame transforms differ (see ``docs/calibration.md`` and
``tools/fit_switch_model.py``, which produced the defaults).
"""

from __future__ import annotations

import csv
import dataclasses
import gzip
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from tactile_braille.keyboard.layout import NONE_KEY, KeyboardLayout, key_set
from tactile_braille.keyboard.switch import SWITCH_TOLERANCE_MM, SwitchModel

RIG_TAP_OFFSET_MM = 2.0
"""The original rig added this constant to every recorded ``tap_depth``."""

MAP_NAMES: tuple[str, ...] = ("alphabet", "arrows")


@dataclass(frozen=True)
class ActivationMap:
    """Taps over a grid and the key each one actuated (``"NONE"`` for none).

    Attributes:
        name: ``"alphabet"`` or ``"arrows"`` (which key set the recorder listened for).
        x_mm, y_mm: tap positions in the map's own work frame.
        depth_mm: tap depth below the work-frame origin, the rig's constant
            2 mm included.
        pressed: key name per tap.
    """

    name: str
    x_mm: np.ndarray
    y_mm: np.ndarray
    depth_mm: np.ndarray
    pressed: np.ndarray

    def __len__(self) -> int:
        return len(self.pressed)


@dataclass(frozen=True)
class FrameTransform:
    """Placement of a map's work frame on the keyboard.

    ``keyboard = rotate(yaw) @ (x, y) + offset``; the work frame's origin sits
    ``clearance_mm + tilt_x * x + tilt_y * y`` above the key tops (the frame
    need not be parallel to the keyboard).
    """

    offset_x_mm: float
    offset_y_mm: float
    yaw_deg: float = 0.0
    clearance_mm: float = 3.5
    tilt_x: float = 0.0
    tilt_y: float = 0.0

    def to_keyboard(self, x_mm: np.ndarray, y_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Work-frame points in the keyboard frame."""
        yaw = np.radians(self.yaw_deg)
        c, s = np.cos(yaw), np.sin(yaw)
        return c * x_mm - s * y_mm + self.offset_x_mm, s * x_mm + c * y_mm + self.offset_y_mm

    def clearance_at_mm(self, x_mm: np.ndarray, y_mm: np.ndarray) -> np.ndarray:
        """Height of the work frame above the key tops at work-frame points."""
        return self.clearance_mm + self.tilt_x * x_mm + self.tilt_y * y_mm


CALIBRATED_FRAMES: dict[str, FrameTransform] = {
    "alphabet": FrameTransform(28.9578, -90.1392, -0.1320, 4.2918, 0.00998, -0.00070),
    "arrows": FrameTransform(57.3100, -236.7582, 0.1970, 4.3109, -0.03642, -0.00573),
}
"""Fitted placement of each real map's work frame (with :class:`SwitchModel` defaults)."""


def work_frame_origin_mm(name: str) -> tuple[float, float]:
    """Keyboard-frame origin of a continuous task's work frame (``"alphabet"`` or ``"arrows"``).

    The translation of the calibrated frame: its fitted yaw (0.13 and 0.20 deg,
    under 0.3 mm at the workspace's edge) is left out so that work-frame grids
    stay aligned with the keyboard frame; its clearance and tilt describe the
    real rig's frame, not the virtual rig's (which sits at the nominal 3.5 mm).
    """
    try:
        frame = CALIBRATED_FRAMES[name]
    except KeyError:
        raise ValueError(f"no work frame {name!r}; choose one of {sorted(CALIBRATED_FRAMES)}") from None
    return frame.offset_x_mm, frame.offset_y_mm


@dataclass(frozen=True)
class Agreement:
    """How often a model's outcome matches the robot's.

    Attributes:
        overall: fraction of all taps with the same outcome (NONE included).
        actuated: the same over the taps where the robot or the model
            actuated a key.
        taps: number of taps compared.
    """

    overall: float
    actuated: float
    taps: int


def _reference_file(name: str):
    return resources.files("tactile_braille.keyboard").joinpath(f"reference/{name}_grid_targets_video.csv.gz")


def load_activation_map(name: str, path: str | Path | None = None) -> ActivationMap:
    """Load a real activation map (``targets_video.csv`` of the original release).

    Args:
        name: ``"alphabet"`` or ``"arrows"``.
        path: a ``targets_video.csv`` (optionally gzipped); by default the copy
            shipped with the package.
    """
    if name not in MAP_NAMES:
        raise ValueError(f"unknown activation map {name!r}; choose one of {MAP_NAMES}")
    source = Path(path) if path is not None else _reference_file(name)
    opener = gzip.open if str(source).endswith(".gz") else open
    with opener(source, "rt", newline="") as handle:
        rows = list(csv.DictReader(handle))
    required = {"obj_pose", "tap_depth", "pressed_buttons"}
    if not rows or not required <= set(rows[0]):
        raise ValueError(f"{source} is not a grid targets_video.csv (needs columns {sorted(required)})")
    poses = np.array([[float(v) for v in row["obj_pose"].strip("[]").split(",")[:2]] for row in rows])
    return ActivationMap(
        name=name,
        x_mm=poses[:, 0],
        y_mm=poses[:, 1],
        depth_mm=np.array([float(row["tap_depth"]) for row in rows]) + RIG_TAP_OFFSET_MM,
        pressed=np.array([row["pressed_buttons"] for row in rows]),
    )


def _heard_margins(
    activation_map: ActivationMap,
    switch: SwitchModel,
    frame: FrameTransform,
    layout: KeyboardLayout,
) -> tuple[np.ndarray, np.ndarray]:
    """Actuation margins of the map's heard keys per tap, and those keys' names."""
    x_kb, y_kb = frame.to_keyboard(activation_map.x_mm, activation_map.y_mm)
    clearance = frame.clearance_at_mm(activation_map.x_mm, activation_map.y_mm)
    depth = activation_map.depth_mm - (clearance - switch.clearance_mm)
    margin = switch.actuation_margin_mm(layout, x_kb, y_kb, depth)
    names = key_set(activation_map.name)
    heard = np.array([layout.key(name).index for name in names])
    return margin[:, heard], np.array(names)


def _outcomes(margin: np.ndarray, names: np.ndarray) -> np.ndarray:
    best = np.argmax(margin, axis=-1)
    pressed = margin[np.arange(len(best)), best] >= 0
    return np.where(pressed, names[best], NONE_KEY)


def predict_activation_map(
    activation_map: ActivationMap,
    switch: SwitchModel | None = None,
    frame: FrameTransform | None = None,
    layout: KeyboardLayout | None = None,
) -> np.ndarray:
    """The key the model actuates for each tap of a map (names, ``"NONE"`` for none).

    As on the rig, only the keys of the map's key set are heard: the
    recorder listened for those and logged anything else as NONE.
    """
    switch = switch or SwitchModel()
    frame = frame or CALIBRATED_FRAMES[activation_map.name]
    return _outcomes(*_heard_margins(activation_map, switch, frame, layout or KeyboardLayout()))


def fit_travel_offsets(
    activation_map: ActivationMap,
    switch: SwitchModel | None = None,
    frame: FrameTransform | None = None,
    taps: np.ndarray | None = None,
    limit_mm: float = 0.5,
    step_mm: float = 0.05,
    sweeps: int = 4,
) -> dict[str, float]:
    """Per-key travel offsets that best reproduce a map's outcomes.

    Coordinate search on exact agreement over ``taps`` (indices; all by
    default): each heard key's offset in turn takes the value of the grid of
    multiples of ``step_mm`` within ``+/- limit_mm`` that matches the most
    taps (on ties the smallest in magnitude, the negative one first), until a
    sweep changes nothing or ``sweeps`` sweeps are done. The switch's own
    offsets are replaced, not added to.

    Returns:
        The offsets of the keys whose offset is not 0, ``{key name: mm}``.
    """
    if not 0 < step_mm <= limit_mm <= SWITCH_TOLERANCE_MM:
        raise ValueError(
            f"need 0 < step_mm <= limit_mm <= {SWITCH_TOLERANCE_MM} (the switch tolerance), "
            f"got step {step_mm}, limit {limit_mm}"
        )
    switch = dataclasses.replace(switch or SwitchModel(), travel_offsets_mm=())
    frame = frame or CALIBRATED_FRAMES[activation_map.name]
    margin, names = _heard_margins(activation_map, switch, frame, KeyboardLayout())
    taps = np.arange(len(activation_map)) if taps is None else np.asarray(taps)
    margin, observed = margin[taps], activation_map.pressed[taps]
    steps = int(np.floor(limit_mm / step_mm + 1e-9))
    grid = np.round(step_mm * np.arange(-steps, steps + 1), 6)  # symmetric, 0 included
    grid = grid[np.argsort(np.abs(grid), kind="stable")]  # tried from 0 outwards, negative first
    offsets = np.zeros(len(names))
    for _ in range(sweeps):
        changed = False
        for k in range(len(names)):
            trial = offsets.copy()
            scores = []
            for value in grid:
                trial[k] = value
                scores.append(int((_outcomes(margin + trial, names) == observed).sum()))
            best = float(grid[int(np.argmax(scores))])
            changed |= best != offsets[k]
            offsets[k] = best
        if not changed:
            break
    return {str(name): float(value) for name, value in zip(names, offsets, strict=True) if value}


def held_out_agreement(
    activation_map: ActivationMap,
    switch: SwitchModel | None = None,
    frame: FrameTransform | None = None,
    folds: int = 2,
    seed: int = 0,
) -> Agreement:
    """Agreement of per-key offsets on taps they were not fitted on (cross-validation).

    The map's taps are dealt at random into ``folds`` parts; each part is
    predicted with offsets fitted (:func:`fit_travel_offsets`) on the others,
    and the pooled predictions are scored against the whole map. Compare with
    the agreement of the switch without offsets to see what they are worth.
    """
    if folds < 2:
        raise ValueError(f"folds must be at least 2, got {folds}")
    switch = switch or SwitchModel()
    frame = frame or CALIBRATED_FRAMES[activation_map.name]
    fold = np.random.default_rng(seed).permutation(len(activation_map)) % folds
    predicted = np.full(len(activation_map), NONE_KEY, dtype=object)
    for k in range(folds):
        offsets = fit_travel_offsets(activation_map, switch, frame, taps=np.flatnonzero(fold != k))
        model = dataclasses.replace(switch, travel_offsets_mm=tuple(offsets.items()))
        predicted[fold == k] = predict_activation_map(activation_map, model, frame)[fold == k]
    return agreement(activation_map.pressed, predicted)


def agreement(observed: np.ndarray, predicted: np.ndarray) -> Agreement:
    """Agreement between two sequences of outcomes (key names or ``"NONE"``)."""
    observed, predicted = np.asarray(observed), np.asarray(predicted)
    if observed.shape != predicted.shape:
        raise ValueError(f"shape mismatch: {observed.shape} vs {predicted.shape}")
    same = observed == predicted
    actuated = (observed != NONE_KEY) | (predicted != NONE_KEY)
    return Agreement(
        overall=float(same.mean()),
        actuated=float(same[actuated].mean()) if actuated.any() else 1.0,
        taps=len(same),
    )
