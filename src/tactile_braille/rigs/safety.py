"""The one gate every motion command of a robot rig passes before it reaches the arm.

:meth:`SafetyLimits.check` turns whatever a caller handed in (numbers of any
kind, NaN, infinities, huge integers, strings, ``None``) into a
:class:`Motion` that lies inside the workspace box, above the depth limit and
under the speed and acceleration caps, or raises
:class:`~tactile_braille.rigs.base.OutOfWorkspaceError` without anything
having been sent. The UR5 rig builds each command it sends from a
:class:`Motion`, and from nothing else.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

from tactile_braille.rigs.base import OutOfWorkspaceError, Pose, Workspace

HARD_MAX_SPEED_MM_S = 250.0
"""No configuration may let the tool move faster than this (the UR's reduced-mode default is 250 mm/s)."""
HARD_MAX_ACCELERATION_MM_S2 = 2500.0
"""No configuration may let the tool accelerate harder than this."""


def as_real(name: str, value: object) -> float:
    """``value`` as a finite float, or :class:`OutOfWorkspaceError` naming ``name``.

    Accepts Python and NumPy integers and floats; refuses booleans, strings,
    ``None``, complex numbers, NaN, infinities and integers too large for a float.
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise OutOfWorkspaceError(f"{name}={value!r} is not a real number")
    try:
        number = float(value)
    except (OverflowError, TypeError, ValueError):
        raise OutOfWorkspaceError(f"{name}={value!r} is not representable as a float") from None
    if not math.isfinite(number):
        raise OutOfWorkspaceError(f"{name}={value!r} is not a finite number")
    return number


@dataclass(frozen=True)
class Motion:
    """A checked linear move of the sensor: where to (work frame) and how fast."""

    pose: Pose
    speed_mm_s: float
    acceleration_mm_s2: float


@dataclass(frozen=True)
class SafetyLimits:
    """Where and how fast a robot rig may move the sensor.

    Attributes:
        workspace: accepted tap poses; ``depth_mm[1]`` is the depth limit.
        safe_height_mm: the highest the rig goes, above the work-frame origin
            (the retract height): motions span depths ``[-safe_height_mm, depth_mm[1]]``.
        max_speed_mm_s: cap on the tool's linear speed.
        max_acceleration_mm_s2: cap on its linear acceleration.
    """

    workspace: Workspace
    safe_height_mm: float
    max_speed_mm_s: float
    max_acceleration_mm_s2: float

    def __post_init__(self) -> None:
        low, high = self.workspace.depth_mm
        if not (math.isfinite(low) and math.isfinite(high) and 0.0 <= low <= high):
            raise ValueError(f"workspace depths must be 0 <= low <= high, got {self.workspace.depth_mm}")
        for name in ("x_mm", "y_mm", "yaw_deg"):
            lo, hi = getattr(self.workspace, name)
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise ValueError(f"workspace {name} must be a finite (low, high), got {(lo, hi)}")
        if not 0.0 < self.safe_height_mm <= 200.0:
            raise ValueError(f"safe_height_mm must be in (0, 200], got {self.safe_height_mm!r}")
        if not 0.0 < self.max_speed_mm_s <= HARD_MAX_SPEED_MM_S:
            raise ValueError(
                f"max_speed_mm_s must be in (0, {HARD_MAX_SPEED_MM_S}], got {self.max_speed_mm_s!r}"
            )
        if not 0.0 < self.max_acceleration_mm_s2 <= HARD_MAX_ACCELERATION_MM_S2:
            raise ValueError(
                f"max_acceleration_mm_s2 must be in (0, {HARD_MAX_ACCELERATION_MM_S2}], "
                f"got {self.max_acceleration_mm_s2!r}"
            )

    @property
    def depth_range_mm(self) -> tuple[float, float]:
        """Depths any motion may reach: from the safe height down to the depth limit."""
        return -self.safe_height_mm, self.workspace.depth_mm[1]

    def check_tap(self, x_mm: object, y_mm: object, depth_mm: object, yaw_deg: object) -> Pose:
        """A tap's bottom pose, checked against the workspace (tap depths ``workspace.depth_mm``)."""
        pose = Pose(as_real("x_mm", x_mm), as_real("y_mm", y_mm), as_real("depth_mm", depth_mm),
                    as_real("yaw_deg", yaw_deg))  # fmt: skip
        self.workspace.check(pose)
        return pose

    def check(self, pose: Pose, speed_mm_s: object, acceleration_mm_s2: object) -> Motion:
        """A motion to ``pose``, or :class:`OutOfWorkspaceError` naming the first thing wrong.

        ``pose`` may lie anywhere from the safe height down to the depth limit,
        over the workspace's x, y and yaw ranges.
        """
        coordinates = {
            name: as_real(name, getattr(pose, name)) for name in ("x_mm", "y_mm", "depth_mm", "yaw_deg")
        }
        checked = Pose(**coordinates)
        box = self.workspace
        Workspace(box.x_mm, box.y_mm, self.depth_range_mm, box.yaw_deg).check(checked)
        speed = as_real("speed_mm_s", speed_mm_s)
        acceleration = as_real("acceleration_mm_s2", acceleration_mm_s2)
        if not 0.0 < speed <= self.max_speed_mm_s:
            raise OutOfWorkspaceError(f"speed {speed} mm/s is outside (0, {self.max_speed_mm_s}]")
        if not 0.0 < acceleration <= self.max_acceleration_mm_s2:
            raise OutOfWorkspaceError(
                f"acceleration {acceleration} mm/s^2 is outside (0, {self.max_acceleration_mm_s2}]"
            )
        return Motion(checked, speed, acceleration)
