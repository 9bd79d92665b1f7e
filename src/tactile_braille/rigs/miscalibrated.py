"""A rig whose work frame is not where its calibration says: the first error a real deployment meets.

A policy commands taps in the calibrated keyboard frame. If the calibration is
off by a small rigid motion, every tap lands displaced and turned:
:class:`MiscalibratedRig` wraps any rig and applies that motion to each
commanded pose, so the same code path types under a known calibration error.
"""

from __future__ import annotations

from collections.abc import Sequence

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
