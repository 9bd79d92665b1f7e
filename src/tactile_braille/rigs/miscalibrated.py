"""A rig whose work frame is not where its calibration says: the first error a real deployment meets.

A policy commands taps in the calibrated keyboard frame. If the calibration is
off by a small rigid motion, every tap lands displaced and turned:
:class:`MiscalibratedRig` wraps any rig and applies that motion to each
commanded pose, so the same code path types under a known calibration error.
:class:`RandomFrameRig` draws a new error for every episode (domain
randomisation: training that expects its calibration to be off).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from tactile_braille.rigs.base import Pose, Rig, TactileSample, Workspace


class MiscalibratedRig:
    """``rig`` with its work frame offset by ``offset_mm`` and turned by ``rotation_deg`` about ``pivot_mm``.

    A tap commanded at ``(x, y, depth, yaw)`` lands at ``pivot + R (x, y) -
    R pivot + offset`` with yaw ``yaw + rotation``; the depth is unchanged.
    Commanded poses are checked against ``workspace`` (the calibrated one),
    the poses they land at by ``rig`` itself (give it room past the edges).
    The samples report the commanded pose, as a robot that believes its
    calibration would.

    Args:
        rig: the rig that taps (a :class:`~tactile_braille.rigs.virtual.VirtualRig`
            with a workspace a few mm larger than the keyboard, for a simulation).
        offset_mm: (x, y) displacement of the true frame from the calibrated one.
        rotation_deg: rotation of the true frame about the sensor's axis.
        pivot_mm: the keyboard-frame point the rotation turns about (the
            task's work-frame origin).
        workspace: the commanded poses' box (default: ``rig``'s).
    """

    def __init__(
        self,
        rig: Rig,
        offset_mm: tuple[float, float] = (0.0, 0.0),
        rotation_deg: float = 0.0,
        pivot_mm: tuple[float, float] = (0.0, 0.0),
        workspace: Workspace | None = None,
    ) -> None:
        values = (*offset_mm, rotation_deg, *pivot_mm)
        if len(values) != 5 or not np.isfinite(values).all():
            raise ValueError(
                f"offset_mm and pivot_mm are (x, y) and rotation_deg a number, all finite; got {values}"
            )
        self.rig = rig
        self.offset_mm = (float(offset_mm[0]), float(offset_mm[1]))
        self.rotation_deg = float(rotation_deg)
        self.pivot_mm = (float(pivot_mm[0]), float(pivot_mm[1]))
        self.workspace = workspace or rig.workspace
        self.layout, self.processing, self.clearance_mm = rig.layout, rig.processing, rig.clearance_mm
        self._pose = rig.pose

    def landing(self, pose: Pose) -> Pose:
        """Where a tap commanded at ``pose`` lands."""
        turn = np.radians(self.rotation_deg)
        cos, sin = np.cos(turn), np.sin(turn)
        dx, dy = pose.x_mm - self.pivot_mm[0], pose.y_mm - self.pivot_mm[1]
        x = self.pivot_mm[0] + cos * dx - sin * dy + self.offset_mm[0]
        y = self.pivot_mm[1] + sin * dx + cos * dy + self.offset_mm[1]
        return Pose(float(x), float(y), pose.depth_mm, pose.yaw_deg + self.rotation_deg)

    @property
    def pose(self) -> Pose:
        """The commanded pose of the last motion."""
        return self._pose

    def tap(self, x_mm: float, y_mm: float, depth_mm: float, yaw_deg: float = 0.0) -> TactileSample:
        """Tap where the calibration error sends a tap commanded at (x, y)."""
        commanded = Pose(float(x_mm), float(y_mm), float(depth_mm), float(yaw_deg))
        self.workspace.check(commanded)
        true = self.landing(commanded)
        sample = self.rig.tap(true.x_mm, true.y_mm, true.depth_mm, true.yaw_deg)
        self._pose = Pose(commanded.x_mm, commanded.y_mm, 0.0, commanded.yaw_deg)
        return TactileSample(frame=sample.frame, pose=commanded, pressed_key=sample.pressed_key)

    def move_to(self, x_mm: float, y_mm: float, yaw_deg: float = 0.0) -> None:
        commanded = Pose(float(x_mm), float(y_mm), 0.0, float(yaw_deg))
        self.workspace.check(commanded)
        true = self.landing(commanded)
        self.rig.move_to(true.x_mm, true.y_mm, true.yaw_deg)
        self._pose = commanded

    def reseed(self, seed: int | Sequence[int]) -> None:
        self.rig.reseed(seed)

    def describe(self) -> dict:
        """The wrapped rig's description, with the calibration error."""
        error = {
            "offset_mm": list(self.offset_mm),
            "rotation_deg": self.rotation_deg,
            "pivot_mm": list(self.pivot_mm),
        }
        return {**self.rig.describe(), "work_frame_error": error}

    def close(self) -> None:
        self.rig.close()

    def __enter__(self) -> MiscalibratedRig:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


MAX_FRAME_ROTATION_DEG = 30.0
"""The largest turn :class:`RandomFrameRig` draws: the rigs' yaw limit (45 degrees) less the yaw a
discrete task's tap may command (10 degrees), with room to spare."""


class RandomFrameRig(MiscalibratedRig):
    """A :class:`MiscalibratedRig` whose error :meth:`redraw` draws anew: offsets uniform in
    ``[-max_offset_mm, max_offset_mm]`` along x and y, a rotation uniform in ``[-max_rotation_deg,
    max_rotation_deg]`` (no error until the first draw). The environments redraw it at each reset.
    """

    def __init__(
        self,
        rig: Rig,
        max_offset_mm: float,
        max_rotation_deg: float,
        pivot_mm: tuple[float, float] = (0.0, 0.0),
        workspace: Workspace | None = None,
    ) -> None:
        bounds = (max_offset_mm, max_rotation_deg)
        if not all(isinstance(b, int | float) and math.isfinite(b) and b >= 0 for b in bounds):
            raise ValueError(f"max_offset_mm and max_rotation_deg must be finite and >= 0, got {bounds}")
        if max_rotation_deg > MAX_FRAME_ROTATION_DEG:
            raise ValueError(
                f"max_rotation_deg must be at most {MAX_FRAME_ROTATION_DEG:g} (the rig's yaw limit), "
                f"got {max_rotation_deg}"
            )
        super().__init__(rig, (0.0, 0.0), 0.0, pivot_mm, workspace)
        self.max_offset_mm, self.max_rotation_deg = float(max_offset_mm), float(max_rotation_deg)

    def redraw(self, rng: np.random.Generator) -> None:
        """A new calibration error, drawn from ``rng``."""
        dx, dy = rng.uniform(-self.max_offset_mm, self.max_offset_mm, 2)
        self.offset_mm = (float(dx), float(dy))
        self.rotation_deg = float(rng.uniform(-self.max_rotation_deg, self.max_rotation_deg))

    def describe(self) -> dict:
        """The wrapped rig's description, with the bounds of the errors drawn (not the present draw)."""
        noise = {"max_offset_mm": self.max_offset_mm, "max_rotation_deg": self.max_rotation_deg,
                 "pivot_mm": list(self.pivot_mm)}  # fmt: skip
        return {**self.rig.describe(), "work_frame_noise": noise}


def with_room(rig, room_mm: float):
    """``rig`` with its workspace widened by ``room_mm`` in x and y (depth and yaw kept), and its
    former workspace: commands are checked against the calibrated box, where they land may pass its
    edges a little."""
    calibrated = rig.workspace
    rig.workspace = replace(
        calibrated,
        x_mm=(calibrated.x_mm[0] - room_mm, calibrated.x_mm[1] + room_mm),
        y_mm=(calibrated.y_mm[0] - room_mm, calibrated.y_mm[1] + room_mm),
    )
    return rig, calibrated


def room_needed_mm(
    workspace: Workspace, pivot_mm: tuple[float, float], offset_mm: float, rotation_deg: float
):
    """How far past ``workspace`` a tap may land under an error of up to ``offset_mm`` along each axis
    and ``rotation_deg`` about ``pivot_mm`` (the farthest corner's displacement), plus 1 mm."""
    reach = max(math.hypot(x - pivot_mm[0], y - pivot_mm[1]) for x in workspace.x_mm for y in workspace.y_mm)
    return offset_mm * math.sqrt(2) + 2 * reach * math.sin(math.radians(rotation_deg) / 2) + 1.0
