"""Rigs: things that move a tactile sensor over a keyboard and tap."""

from tactile_braille.rigs.base import (
    OutOfWorkspaceError,
    Pose,
    Rig,
    RigError,
    TactileSample,
    Workspace,
)
from tactile_braille.rigs.virtual import VirtualRig

__all__ = [
    "OutOfWorkspaceError",
    "Pose",
    "Rig",
    "RigError",
    "TactileSample",
    "VirtualRig",
    "Workspace",
]
