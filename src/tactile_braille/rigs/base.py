"""The rig protocol: anything that can move a tactile sensor over a keyboard and tap.

Coordinates are the keyboard frame of :mod:`tactile_braille.keyboard.layout`
(origin at the centre of the Q key top, ``x`` towards the typist, ``y`` to
the left); a tap's ``depth_mm`` is measured down from the rig's work-frame
origin, ``clearance_mm`` above the key tops (3.5 mm on the paper's rig), so
the sensor first touches a key top at ``depth_mm = clearance_mm``.

A real arm (the UR5 rig of a later issue) implements the same protocol: it
moves at a safe height between taps and raises :class:`RigError` on faults,
so that a collection or an episode can stop cleanly and resume.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from tactile_braille.keyboard.layout import KeyboardLayout
from tactile_braille.sensor.config import ImageProcessing


class RigError(RuntimeError):
    """A rig could not carry out a command (fault, lost connection, unsafe pose)."""


class OutOfWorkspaceError(RigError, ValueError):
    """A commanded pose lies outside the rig's workspace; nothing was moved."""


@dataclass(frozen=True)
class Pose:
    """A sensor pose in the keyboard frame.

    Attributes:
        x_mm, y_mm: position of the sensor's axis.
        depth_mm: depth of the dome's apex below the work-frame origin
            (negative is above it).
        yaw_deg: rotation about the sensor's axis (0: braille upright in the image).
    """

    x_mm: float
    y_mm: float
    depth_mm: float = 0.0
    yaw_deg: float = 0.0

    def as_array(self) -> np.ndarray:
        """``[x_mm, y_mm, depth_mm, yaw_deg]`` as float64."""
        return np.array([self.x_mm, self.y_mm, self.depth_mm, self.yaw_deg], dtype=np.float64)


@dataclass(frozen=True)
class Workspace:
    """Box of poses a rig accepts (keyboard frame)."""

    x_mm: tuple[float, float]
    y_mm: tuple[float, float]
    depth_mm: tuple[float, float] = (0.0, 10.0)
    yaw_deg: tuple[float, float] = (-45.0, 45.0)

    def check(self, pose: Pose) -> None:
        """Raise :class:`OutOfWorkspaceError` naming the first bad coordinate."""
        for name, value in (
            ("x_mm", pose.x_mm),
            ("y_mm", pose.y_mm),
            ("depth_mm", pose.depth_mm),
            ("yaw_deg", pose.yaw_deg),
        ):
            low, high = getattr(self, name)
            if not math.isfinite(value):
                raise OutOfWorkspaceError(f"{name}={value!r} is not a finite number")
            if not low <= value <= high:
                raise OutOfWorkspaceError(f"{name}={value:.3f} is outside the workspace [{low}, {high}]")


@dataclass(frozen=True)
class TactileSample:
    """What one tap yields.

    Attributes:
        frame: the raw camera frame at the bottom of the tap (uint8, H x W).
        pose: the pose the sensor was commanded to.
        pressed_key: the key that registered (``None`` if none did).
    """

    frame: np.ndarray
    pose: Pose
    pressed_key: str | None


@runtime_checkable
class Rig(Protocol):
    """Moves a tactile sensor over a keyboard and taps."""

    workspace: Workspace
    clearance_mm: float
    layout: KeyboardLayout
    processing: ImageProcessing

    def tap(self, x_mm: float, y_mm: float, depth_mm: float, yaw_deg: float = 0.0) -> TactileSample:
        """Move above (x, y) at a safe height, tap down to ``depth_mm``, grab a
        frame at the bottom, record any key press, and come back up."""
        ...

    def move_to(self, x_mm: float, y_mm: float, yaw_deg: float = 0.0) -> None:
        """Move at the safe height to above (x, y) without touching anything."""
        ...

    @property
    def pose(self) -> Pose:
        """The sensor's current pose."""
        ...

    def reseed(self, seed: int | Sequence[int]) -> None:
        """Make the rig's own randomness reproducible from here on.

        Collections reseed before every tap so that tap ``i`` does not depend
        on what came before it (and survives a resume). A hardware rig, whose
        noise cannot be seeded, ignores it.
        """
        ...

    def describe(self) -> dict:
        """JSON-able description: ``rig`` name, ``keyboard`` and ``sensor`` parameters."""
        ...

    def close(self) -> None:
        """Release the hardware (idempotent)."""
        ...
