"""Rigs: things that move a tactile sensor over a keyboard and tap.

``VirtualRig`` simulates one; ``UR5Rig`` drives the real robot (its hardware
libraries are the optional extra ``robot``, imported only when it connects).
"""

from tactile_braille.rigs.base import (
    OutOfWorkspaceError,
    Pose,
    Rig,
    RigError,
    TactileSample,
    Workspace,
)
from tactile_braille.rigs.ur5 import UR5Config, UR5Rig
from tactile_braille.rigs.virtual import VirtualRig

__all__ = [
    "OutOfWorkspaceError",
    "Pose",
    "Rig",
    "RigError",
    "TactileSample",
    "UR5Config",
    "UR5Rig",
    "VirtualRig",
    "Workspace",
]
