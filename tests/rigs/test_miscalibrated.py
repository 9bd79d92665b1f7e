"""A rig whose work frame is off: each commanded tap lands displaced and turned."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_braille.rigs.base import OutOfWorkspaceError, Pose, Workspace
from tactile_braille.rigs.miscalibrated import MiscalibratedRig, RandomFrameRig, room_needed_mm, with_room
from tactile_braille.rigs.virtual import VirtualRig


def test_landing_turns_about_the_pivot_then_offsets():
    rig = MiscalibratedRig(
        VirtualRig(seed=None), offset_mm=(1.0, -0.5), rotation_deg=90.0, pivot_mm=(10.0, 20.0)
    )
    assert rig.landing(Pose(10.0, 20.0, 5.0, 3.0)) == Pose(11.0, 19.5, 5.0, 93.0)
    landed = rig.landing(Pose(12.0, 20.0, 5.0, 0.0))  # 2 mm along x turns to 2 mm along y
    np.testing.assert_allclose([landed.x_mm, landed.y_mm], [11.0, 21.5], atol=1e-12)


def test_a_tap_lands_where_the_error_sends_it_and_reports_the_commanded_pose():
    inner = VirtualRig(seed=3)
    layout = inner.layout
    a = np.array(layout.centre_mm("A"))
    pitch = layout.pitch_mm
    rig = MiscalibratedRig(inner, offset_mm=(0.0, pitch), pivot_mm=tuple(a))
    # One key pitch along y: the tap commanded over A presses A's neighbour there.
    centres = np.array([layout.centre_mm(k.name) for k in layout.keys])
    neighbour = layout.keys[
        int(np.argmin(np.linalg.norm(centres - (a + np.array([0.0, pitch])), axis=1)))
    ].name
    assert neighbour != "A"
    inner.reseed(7)
    sample = rig.tap(*a, 8.0)
    assert sample.pressed_key == neighbour and sample.pose == Pose(*a, 8.0, 0.0)
    assert rig.pose == Pose(*a, 0.0, 0.0)
    inner.reseed(7)
    np.testing.assert_array_equal(sample.frame, inner.tap(a[0], a[1] + pitch, 8.0).frame)
    error = rig.describe()["work_frame_error"]
    assert error == {"offset_mm": [0.0, pitch], "rotation_deg": 0.0, "pivot_mm": list(map(float, a))}


def test_commanded_poses_are_checked_against_the_calibrated_workspace():
    inner = VirtualRig(seed=None, workspace=Workspace(x_mm=(-500, 500), y_mm=(-500, 500)))
    calibrated = Workspace(x_mm=(0.0, 100.0), y_mm=(0.0, 100.0))
    rig = MiscalibratedRig(inner, offset_mm=(1.0, 0.0), workspace=calibrated)
    with pytest.raises(OutOfWorkspaceError, match=r"x_mm=150\.000"):
        rig.tap(150.0, 50.0, 5.0)
    with pytest.raises(OutOfWorkspaceError):
        rig.move_to(50.0, -1.0)
    assert inner.pose == Pose(0.0, 0.0, 0.0, 0.0)  # nothing moved
    with pytest.raises(ValueError, match="finite"):
        MiscalibratedRig(inner, offset_mm=(np.nan, 0.0))


def test_a_random_frame_draws_each_error_within_its_bounds_from_the_generator_it_is_given():
    rig = RandomFrameRig(VirtualRig(seed=None), max_offset_mm=1.0, max_rotation_deg=2.0, pivot_mm=(5.0, 6.0))
    assert rig.offset_mm == (0.0, 0.0) and rig.rotation_deg == 0.0  # no error before the first draw
    draws = []
    for _ in range(200):
        rig.redraw(np.random.default_rng(len(draws)))
        draws.append((*rig.offset_mm, rig.rotation_deg))
    draws = np.array(draws)
    assert np.abs(draws[:, :2]).max() <= 1.0 and np.abs(draws[:, 2]).max() <= 2.0
    assert np.abs(draws[:, :2]).max() > 0.9 and np.abs(draws[:, 2]).max() > 1.8  # the whole range
    rig.redraw(np.random.default_rng(0))
    assert (*rig.offset_mm, rig.rotation_deg) == tuple(draws[0])  # the generator alone decides
    assert rig.describe()["work_frame_noise"] == {
        "max_offset_mm": 1.0, "max_rotation_deg": 2.0, "pivot_mm": [5.0, 6.0]
    }  # fmt: skip
    for bad in ((-1.0, 2.0), (1.0, np.inf)):
        with pytest.raises(ValueError, match="finite and >= 0"):
            RandomFrameRig(VirtualRig(seed=None), *bad)
    with pytest.raises(ValueError, match="at most 30"):
        RandomFrameRig(VirtualRig(seed=None), 1.0, 31.0)


def test_the_room_left_past_the_edges_holds_every_landing_of_the_largest_errors():
    box, pivot = Workspace(x_mm=(-40.0, 60.0), y_mm=(-250.0, 30.0)), (29.0, -90.0)
    room = room_needed_mm(box, pivot, 1.0, 2.0)
    widest = 0.0
    for dx in (-1.0, 1.0):
        for dy in (-1.0, 1.0):
            for turn in (-2.0, 2.0):
                rig = MiscalibratedRig(VirtualRig(seed=None), (dx, dy), turn, pivot)
                for x in box.x_mm:
                    for y in box.y_mm:
                        landed = rig.landing(Pose(x, y, 0.0, 0.0))
                        past = max(box.x_mm[0] - landed.x_mm, landed.x_mm - box.x_mm[1],
                                   box.y_mm[0] - landed.y_mm, landed.y_mm - box.y_mm[1])  # fmt: skip
                        widest = max(widest, past)
    assert widest <= room <= widest + 2.5  # room enough, and not much more
    inner, calibrated = with_room(VirtualRig(seed=None), room)
    assert (
        inner.workspace.x_mm[0] == calibrated.x_mm[0] - room
        and inner.workspace.depth_mm == calibrated.depth_mm
    )
