"""Collection procedures: which taps to make, independent of the rig that makes them.

A procedure is a deterministic, indexable list of :class:`TapSpec`: tap ``i``
is the same whatever happened before it, so that an interrupted collection
resumes exactly where it stopped, on a virtual rig or a real one.

* :class:`PerturbedTaps`: the paper's supervised and discrete-task data, N
  taps per key at the key centre with random perturbations
  (x, y ~ U[-1, 1] mm, depth ~ U[-1, 0] mm, yaw ~ U[-10, 10] deg).
* :class:`GridTaps`: the paper's continuous-task data, a dense grid of taps
  over a task's work frame at several depths, recording which key actuates.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from tactile_braille._tasks import KEY_SETS
from tactile_braille.keyboard.calibration import RIG_TAP_OFFSET_MM, work_frame_origin_mm
from tactile_braille.keyboard.layout import NONE_KEY, KeyboardLayout, key_set

NONE_TAP_OFFSET_MM = (-20.0, -20.0)
"""Where NONE-class taps of :class:`PerturbedTaps` are made, relative to Q (the
original's position); they are made in the air (depth 0), touching nothing,
as the original did 10 mm above the keys."""

SPLIT_SEED_OFFSET = {"train": 0, "validation": 1_000_003}


@dataclass(frozen=True)
class TapSpec:
    """One tap to make.

    Attributes:
        index: position in the procedure (the resume key).
        x_mm, y_mm, depth_mm, yaw_deg: the pose in the keyboard frame.
        label: the key the tap aims at (perturbed taps) or ``""`` (grids,
            where the label is whatever actuates).
    """

    index: int
    x_mm: float
    y_mm: float
    depth_mm: float
    yaw_deg: float
    label: str


@dataclass(frozen=True)
class PerturbedTaps:
    """``per_key`` perturbed taps at the centre of each key.

    Attributes:
        keys: key set name (``"arrows"``, ``"alphabet"``, ``"all"``).
        per_key: taps per key (the paper: 100 train, 50 validation).
        split: ``"train"`` or ``"validation"``; the splits draw different perturbations.
        depth_mm: nominal tap depth below the work-frame origin (5 mm: 1.5 mm
            into the key tops, short of actuation but for the earliest
            switches: O, P, Q, S, V and X register from 4.85-4.95 mm at
            their centres on the virtual rig).
        include_none: add a NONE class of taps in the air (depth 0, touching nothing).
        position_range_mm, depth_range_mm, yaw_range_deg: perturbation bounds.
        seed: seeds the perturbations.
    """

    keys: str = "all"
    per_key: int = 100
    split: str = "train"
    depth_mm: float = 5.0
    include_none: bool = True
    position_range_mm: float = 1.0
    depth_range_mm: tuple[float, float] = (-1.0, 0.0)
    yaw_range_deg: float = 10.0
    seed: int = 0

    def __post_init__(self) -> None:
        key_set(self.keys)  # validates the name
        if self.per_key < 1:
            raise ValueError(f"per_key must be at least 1, got {self.per_key}")
        if self.split not in SPLIT_SEED_OFFSET:
            raise ValueError(f"split must be one of {sorted(SPLIT_SEED_OFFSET)}, got {self.split!r}")
        for name in ("position_range_mm", "yaw_range_deg"):
            if not getattr(self, name) >= 0:  # NaN too
                raise ValueError(f"{name} must be a bound >= 0, got {getattr(self, name)}")
        low, high = self.depth_range_mm
        if not low <= high:
            raise ValueError(
                f"depth_range_mm must be (low, high) with low <= high, got {self.depth_range_mm}"
            )
        object.__setattr__(self, "depth_range_mm", (float(low), float(high)))  # a list, as JSON gives it

    @property
    def name(self) -> str:
        return "perturbed"

    @property
    def labels(self) -> tuple[str, ...]:
        """Class names in label order."""
        return key_set(self.keys) + ((NONE_KEY,) if self.include_none else ())

    def __len__(self) -> int:
        return len(self.labels) * self.per_key

    def tap(self, index: int, layout: KeyboardLayout) -> TapSpec:
        """The ``index``-th tap."""
        if not 0 <= index < len(self):
            raise IndexError(f"tap {index} out of range [0, {len(self)})")
        label = self.labels[index // self.per_key]
        # The same perturbation list for every key, as in the original release.
        rng = np.random.default_rng([self.seed + SPLIT_SEED_OFFSET[self.split], index % self.per_key])
        dx, dy = rng.uniform(-self.position_range_mm, self.position_range_mm, 2)
        dz = rng.uniform(*self.depth_range_mm)
        yaw = rng.uniform(-self.yaw_range_deg, self.yaw_range_deg)
        if label == NONE_KEY:
            q_x, q_y = layout.centre_mm("Q")
            x, y = q_x + NONE_TAP_OFFSET_MM[0], q_y + NONE_TAP_OFFSET_MM[1]
            return TapSpec(index, x + dx, y + dy, 0.0, yaw, label)  # in the air
        x, y = layout.centre_mm(label)
        return TapSpec(index, x + dx, y + dy, self.depth_mm + dz, yaw, label)

    def describe(self) -> dict:
        """JSON-able description (stored with the dataset)."""
        return {"procedure": self.name, **asdict(self)}


MAX_GRID_TAPS = 1_000_000
"""The most taps a grid collection may have (the paper's grids have about 15,000)."""


@dataclass(frozen=True)
class GridTaps:
    """A dense grid of taps over a task's work frame, at several depths.

    The paper's grids (each key set's ``grid_spacing_mm``, ``grid_depth_step_mm`` and
    ``workspace_mm``, :data:`~tactile_braille._tasks.KEY_SETS`): alphabet 3 mm in x and y over x in
    [-30, 30], y in [-90, 90] and tap depths 0..6 mm in 1 mm steps; arrows 1 mm over
    x in [-20, 0], y in [-20, 20] and 0..6 mm in 0.5 mm steps. Tap depths are
    the original's (the rig adds a constant 2 mm). Work frames sit where the
    calibration placed the real rig's (``CALIBRATED_FRAMES``); taps are made
    at yaw 0 and ordered x (outer), y, depth (inner), as in the release.

    Attributes:
        keys: ``"alphabet"`` or ``"arrows"``.
        spacing_mm: grid step in x and y (``None``: the paper's).
        depth_step_mm: tap depth step (``None``: the paper's).
        x_range_mm, y_range_mm: work-frame extent (``None``: the paper's).
        max_tap_depth_mm: deepest tap depth (the original's 6 mm).
    """

    keys: str = "alphabet"
    spacing_mm: float | None = None
    depth_step_mm: float | None = None
    x_range_mm: tuple[float, float] | None = None
    y_range_mm: tuple[float, float] | None = None
    max_tap_depth_mm: float = 6.0

    def __post_init__(self) -> None:
        if self.keys not in KEY_SETS:
            raise ValueError(f"grid keys must be one of {sorted(KEY_SETS)}, got {self.keys!r}")
        paper = KEY_SETS[self.keys]
        paper_x, paper_y = paper.workspace_mm

        def pick(value, default):
            return default if value is None else value

        resolved = {
            "spacing_mm": pick(self.spacing_mm, paper.grid_spacing_mm),
            "depth_step_mm": pick(self.depth_step_mm, paper.grid_depth_step_mm),
            "x_range_mm": tuple(pick(self.x_range_mm, paper_x)),
            "y_range_mm": tuple(pick(self.y_range_mm, paper_y)),
        }
        for name in ("spacing_mm", "depth_step_mm"):
            if not resolved[name] > 0:
                raise ValueError(f"{name} must be positive, got {resolved[name]!r}")
        for name in ("x_range_mm", "y_range_mm"):
            low, high = resolved[name]
            if not low <= high:
                raise ValueError(f"{name} must be (low, high) with low <= high, got {resolved[name]}")
        for name, value in resolved.items():
            object.__setattr__(self, name, value)
        if len(self) > MAX_GRID_TAPS:
            raise ValueError(
                f"a grid of spacing {self.spacing_mm} mm and depth step {self.depth_step_mm} mm has "
                f"{len(self):,} taps, more than the {MAX_GRID_TAPS:,} a dataset may hold "
                "(10 KB each, in memory): choose coarser steps"
            )

    @property
    def name(self) -> str:
        return "grid"

    @property
    def labels(self) -> tuple[str, ...]:
        """The keys the recorder listens for, plus NONE."""
        return (*key_set(self.keys), NONE_KEY)

    def _axis(self, low: float, high: float, step: float) -> np.ndarray:
        count = int(np.floor((high - low) / step + 1e-9)) + 1
        return low + step * np.arange(count)

    @property
    def axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Work-frame x, y and tap depths of the grid."""
        return (
            self._axis(*self.x_range_mm, self.spacing_mm),
            self._axis(*self.y_range_mm, self.spacing_mm),
            self._axis(0.0, self.max_tap_depth_mm, self.depth_step_mm),
        )

    def __len__(self) -> int:
        xs, ys, depths = self.axes
        return len(xs) * len(ys) * len(depths)

    def tap(self, index: int, layout: KeyboardLayout) -> TapSpec:
        """The ``index``-th tap (``layout`` is unused: the frame is fixed)."""
        if not 0 <= index < len(self):
            raise IndexError(f"tap {index} out of range [0, {len(self)})")
        xs, ys, depths = self.axes
        i, rest = divmod(index, len(ys) * len(depths))
        j, k = divmod(rest, len(depths))
        origin_x, origin_y = work_frame_origin_mm(KEY_SETS[self.keys].work_frame)
        return TapSpec(
            index,
            xs[i] + origin_x,
            ys[j] + origin_y,
            depths[k] + RIG_TAP_OFFSET_MM,
            0.0,
            "",
        )

    def describe(self) -> dict:
        """JSON-able description (stored with the dataset)."""
        return {
            "procedure": self.name,
            "keys": self.keys,
            "spacing_mm": self.spacing_mm,
            "depth_step_mm": self.depth_step_mm,
            "x_range_mm": list(self.x_range_mm),
            "y_range_mm": list(self.y_range_mm),
            "max_tap_depth_mm": self.max_tap_depth_mm,
        }


Procedure = PerturbedTaps | GridTaps
