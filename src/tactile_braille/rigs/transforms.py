"""Poses between the keyboard's work frame (mm, degrees) and a UR robot's base frame (m, rotation vector).

The **work frame** is the keyboard frame of :mod:`tactile_braille.rigs.base`
lifted ``clearance_mm`` above the key tops: ``x`` towards the typist, ``y`` to
the typist's left and ``z`` *down* into the keyboard (a right-handed frame), so
that a pose's ``depth_mm`` is its ``z``. Its placement in the robot's base
frame is written ``(x_mm, y_mm, z_mm, roll_deg, pitch_deg, yaw_deg)`` with
extrinsic x-y-z Euler angles (``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``); a
keyboard lying flat on the robot's table has roll 180, pitch 0 and yaw its
rotation about the base's vertical axis.

A UR controller takes a tool pose as ``[x_m, y_m, z_m, rx, ry, rz]``: metres
and a rotation vector (axis times angle in radians). The sensor points along
the tool's ``z`` axis, so a sensor pose ``(x, y, depth, yaw)`` is the tool
pose with position ``R_work @ (x, y, depth) + origin`` and orientation
``R_work @ Rz(yaw)``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from tactile_braille.rigs.base import Pose

FramePose = tuple[float, float, float, float, float, float]
"""``(x_mm, y_mm, z_mm, roll_deg, pitch_deg, yaw_deg)`` of a frame in another frame."""


def rotation_from_euler_deg(roll_deg: float, pitch_deg: float, yaw_deg: float) -> np.ndarray:
    """The 3x3 rotation ``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (extrinsic x, y, z)."""
    a, b, c = np.radians([roll_deg, pitch_deg, yaw_deg])
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    return rz @ ry @ rx


def rotation_from_rotvec(rotvec: Sequence[float]) -> np.ndarray:
    """The 3x3 rotation of a rotation vector (Rodrigues' formula)."""
    rotvec = np.asarray(rotvec, dtype=np.float64)
    angle = float(np.linalg.norm(rotvec))
    if angle < 1e-12:
        return np.eye(3)
    kx, ky, kz = rotvec / angle
    k = np.array([[0, -kz, ky], [kz, 0, -kx], [-ky, kx, 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def rotvec_from_rotation(rotation: np.ndarray) -> np.ndarray:
    """The rotation vector of a 3x3 rotation, angle in [0, pi].

    Goes through a unit quaternion (Shepperd's method), which stays accurate
    at angles near pi, where a tool pointing straight down usually is.
    """
    m = np.asarray(rotation, dtype=np.float64)
    trace = np.trace(m)
    candidates = [trace, m[0, 0], m[1, 1], m[2, 2]]
    pick = int(np.argmax(candidates))
    if pick == 0:
        w = np.sqrt(1.0 + trace) / 2
        x, y, z = (m[2, 1] - m[1, 2]) / (4 * w), (m[0, 2] - m[2, 0]) / (4 * w), (m[1, 0] - m[0, 1]) / (4 * w)
    elif pick == 1:
        x = np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) / 2
        w, y, z = (m[2, 1] - m[1, 2]) / (4 * x), (m[0, 1] + m[1, 0]) / (4 * x), (m[0, 2] + m[2, 0]) / (4 * x)
    elif pick == 2:
        y = np.sqrt(1.0 - m[0, 0] + m[1, 1] - m[2, 2]) / 2
        w, x, z = (m[0, 2] - m[2, 0]) / (4 * y), (m[0, 1] + m[1, 0]) / (4 * y), (m[1, 2] + m[2, 1]) / (4 * y)
    else:
        z = np.sqrt(1.0 - m[0, 0] - m[1, 1] + m[2, 2]) / 2
        w, x, y = (m[1, 0] - m[0, 1]) / (4 * z), (m[0, 2] + m[2, 0]) / (4 * z), (m[1, 2] + m[2, 1]) / (4 * z)
    if w < 0:  # the same rotation; keeps the angle in [0, pi]
        w, x, y, z = -w, -x, -y, -z
    axis = np.array([x, y, z])
    norm = float(np.linalg.norm(axis))
    if norm < 1e-15:
        return np.zeros(3)
    return axis / norm * 2.0 * np.arctan2(norm, w)


def homogeneous(frame: FramePose) -> np.ndarray:
    """The 4x4 transform of a ``(x_mm, y_mm, z_mm, roll_deg, pitch_deg, yaw_deg)`` frame (mm)."""
    transform = np.eye(4)
    transform[:3, :3] = rotation_from_euler_deg(*frame[3:])
    transform[:3, 3] = frame[:3]
    return transform


def homogeneous_from_ur(pose: Sequence[float]) -> np.ndarray:
    """The 4x4 transform (mm) of a UR pose ``[x_m, y_m, z_m, rx, ry, rz]``."""
    transform = np.eye(4)
    transform[:3, :3] = rotation_from_rotvec(pose[3:6])
    transform[:3, 3] = np.asarray(pose[:3], dtype=np.float64) * 1000.0
    return transform


def ur_from_homogeneous(transform: np.ndarray) -> list[float]:
    """The UR pose ``[x_m, y_m, z_m, rx, ry, rz]`` of a 4x4 transform (mm)."""
    position = transform[:3, 3] / 1000.0
    return [float(v) for v in (*position, *rotvec_from_rotation(transform[:3, :3]))]


def sensor_transform(pose: Pose) -> np.ndarray:
    """The 4x4 transform (mm) of a sensor pose in the work frame."""
    transform = np.eye(4)
    transform[:3, :3] = rotation_from_euler_deg(0.0, 0.0, pose.yaw_deg)
    transform[:3, 3] = (pose.x_mm, pose.y_mm, pose.depth_mm)
    return transform


def work_to_base(pose: Pose, work_frame: FramePose) -> list[float]:
    """The UR tool pose (m, rotation vector) that puts the sensor at ``pose`` in the work frame."""
    return ur_from_homogeneous(homogeneous(work_frame) @ sensor_transform(pose))


def base_to_work(tool_pose: Sequence[float], work_frame: FramePose) -> Pose:
    """The work-frame sensor pose of a UR tool pose (the inverse of :func:`work_to_base`).

    The yaw is the rotation about the work frame's ``z``; a tool tilted off
    that axis keeps only its yaw (the rig never tilts the sensor).
    """
    relative = np.linalg.inv(homogeneous(work_frame)) @ homogeneous_from_ur(tool_pose)
    x, y, depth = relative[:3, 3]
    yaw = np.degrees(np.arctan2(relative[1, 0], relative[0, 0]))
    return Pose(float(x), float(y), float(depth), float(yaw))


def tcp_offset_to_ur(tcp_offset: FramePose) -> list[float]:
    """A tool centre point offset ``(mm, deg)`` as the UR pose ``setTcp`` takes."""
    return ur_from_homogeneous(homogeneous(tcp_offset))
