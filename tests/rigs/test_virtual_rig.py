"""The virtual rig behind the Rig protocol."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tactile_braille.keyboard.layout import ALPHABET_KEYS, KeyboardLayout
from tactile_braille.keyboard.switch import SwitchModel
from tactile_braille.rigs.base import OutOfWorkspaceError, Pose, Rig, RigError, TactileSample, Workspace
from tactile_braille.rigs.virtual import VirtualRig
from tactile_braille.sensor.config import sensor_preset


@pytest.fixture
def rig():
    with VirtualRig(seed=0) as virtual:
        yield virtual


def test_virtual_rig_satisfies_the_rig_protocol(rig):
    assert isinstance(rig, Rig)


def test_protocol_check_rejects_incomplete_rigs():
    class NotARig:
        workspace = Workspace(x_mm=(0, 1), y_mm=(0, 1))
        clearance_mm = 3.5

        def move_to(self, x_mm, y_mm, yaw_deg=0.0):
            pass

        def close(self):
            pass

    assert not isinstance(NotARig(), Rig)


def test_out_of_workspace_error_is_a_rig_error_and_a_value_error():
    assert issubclass(OutOfWorkspaceError, RigError)
    assert issubclass(OutOfWorkspaceError, ValueError)
    assert issubclass(RigError, RuntimeError)


def test_default_workspace_is_the_keyboard(rig):
    x_min, x_max, y_min, y_max = rig.layout.bounds_mm
    assert rig.workspace.x_mm == (x_min, x_max)
    assert rig.workspace.y_mm == (y_min, y_max)
    assert rig.workspace.depth_mm == (0.0, 10.0)
    assert rig.clearance_mm == 3.5


def test_tap_returns_sample_with_commanded_pose(rig):
    x, y = rig.layout.centre_mm("A")
    sample = rig.tap(x, y, 5.0, yaw_deg=2.0)
    assert isinstance(sample, TactileSample)
    assert sample.pose == Pose(x, y, 5.0, 2.0)
    assert sample.frame.shape == (480, 640)
    assert sample.frame.dtype == np.uint8
    assert sample.pressed_key is None  # 1.5 mm into the key top: short of actuation
    # After the tap the sensor is back up at the work-frame height, over the same spot.
    assert rig.pose == Pose(x, y, 0.0, 2.0)


@pytest.mark.parametrize("key", [*ALPHABET_KEYS[::3], "SPACE", "UP", "DOWN", "LEFT", "RIGHT"])
def test_deep_tap_on_key_centre_presses_it(rig, key):
    x, y = rig.layout.centre_mm(key)
    assert rig.tap(x, y, 8.0).pressed_key == key


def test_shallow_and_no_contact_taps_press_nothing(rig):
    x, y = rig.layout.centre_mm("F")
    assert rig.tap(x, y, 0.0).pressed_key is None
    assert rig.tap(x, y, 3.5).pressed_key is None


def test_tap_between_keys_presses_at_most_a_neighbour(rig):
    gx, gy = rig.layout.centre_mm("G")
    for depth in (4.0, 6.0, 8.0, 10.0):
        assert rig.tap(gx, gy - 9.5, depth).pressed_key in (None, "G", "H")


def test_pressed_key_frame_differs_from_no_contact(rig):
    x, y = rig.layout.centre_mm("A")
    pressed = rig.tap(x, y, 8.0).frame.astype(int)
    free = rig.tap(x, y, 0.0).frame.astype(int)
    assert (np.abs(pressed - free) > 50).sum() > 1000


def test_move_to_moves_at_work_frame_height(rig):
    x, y = rig.layout.centre_mm("P")
    rig.move_to(x, y, yaw_deg=-10.0)
    assert rig.pose == Pose(x, y, 0.0, -10.0)


@pytest.mark.parametrize(
    ("x_offset", "y_offset", "depth", "yaw", "bad"),
    [
        (500.0, 0.0, 5.0, 0.0, "x_mm"),
        (0.0, -1000.0, 5.0, 0.0, "y_mm"),
        (0.0, 0.0, float("nan"), 0.0, "depth_mm"),
        (0.0, 0.0, 10.5, 0.0, "depth_mm"),
        (0.0, 0.0, -1.0, 0.0, "depth_mm"),
        (0.0, 0.0, 5.0, 90.0, "yaw_deg"),
        (float("inf"), 0.0, 5.0, 0.0, "x_mm"),
    ],
)
def test_out_of_workspace_tap_raises_and_does_not_move(rig, x_offset, y_offset, depth, yaw, bad):
    x, y = rig.layout.centre_mm("A")
    rig.move_to(x, y)
    before = rig.pose
    with pytest.raises(OutOfWorkspaceError, match=bad):
        rig.tap(x + x_offset, y + y_offset, depth, yaw_deg=yaw)
    assert rig.pose == before


def test_out_of_workspace_move_raises_and_does_not_move(rig):
    x, y = rig.layout.centre_mm("A")
    rig.move_to(x, y)
    with pytest.raises(OutOfWorkspaceError):
        rig.move_to(x + 500.0, y)
    with pytest.raises(OutOfWorkspaceError):
        rig.move_to(x, float("nan"))
    assert rig.pose == Pose(x, y, 0.0, 0.0)


def test_workspace_check_names_first_bad_coordinate():
    workspace = Workspace(x_mm=(0.0, 10.0), y_mm=(0.0, 10.0))
    workspace.check(Pose(5.0, 5.0, 5.0, 0.0))  # inside: no error
    with pytest.raises(OutOfWorkspaceError, match="not a finite number"):
        workspace.check(Pose(math.nan, 5.0))
    with pytest.raises(OutOfWorkspaceError, match=r"y_mm=11\.000 is outside"):
        workspace.check(Pose(5.0, 11.0))


def test_custom_workspace_is_enforced():
    rig = VirtualRig(seed=None, workspace=Workspace(x_mm=(-5.0, 5.0), y_mm=(-5.0, 5.0), depth_mm=(0.0, 6.0)))
    rig.tap(0.0, 0.0, 6.0)
    with pytest.raises(OutOfWorkspaceError):
        rig.tap(0.0, 0.0, 7.0)
    with pytest.raises(OutOfWorkspaceError):
        rig.tap(19.0, 0.0, 5.0)


def test_closed_rig_raises(rig):
    rig.close()
    rig.close()  # idempotent
    with pytest.raises(RuntimeError, match="closed"):
        rig.tap(0.0, 0.0, 5.0)
    with pytest.raises(RuntimeError, match="closed"):
        rig.move_to(0.0, 0.0)


def test_closed_rig_raises_rig_error(rig):
    rig.close()
    with pytest.raises(RigError):
        rig.tap(0.0, 0.0, 5.0)


def test_context_manager_closes():
    with VirtualRig(seed=None) as rig:
        rig.tap(0.0, 0.0, 5.0)
    with pytest.raises(RuntimeError):
        rig.tap(0.0, 0.0, 5.0)


def _frames(rig, keys=("A", "B", "UP")):
    return [rig.tap(*rig.layout.centre_mm(k), 5.0).frame for k in keys]


def test_same_seed_gives_identical_frames_across_rigs():
    first, second = VirtualRig(seed=11), VirtualRig(seed=11)
    for a, b in zip(_frames(first), _frames(second), strict=True):
        np.testing.assert_array_equal(a, b)


def test_different_seeds_give_different_frames():
    for a, b in zip(_frames(VirtualRig(seed=1)), _frames(VirtualRig(seed=2)), strict=True):
        assert (a != b).sum() > 1000


def test_seedless_rig_is_noiseless_and_repeatable():
    rig = VirtualRig(seed=None)
    x, y = rig.layout.centre_mm("A")
    first = rig.tap(x, y, 5.0).frame
    second = rig.tap(x, y, 5.0).frame
    np.testing.assert_array_equal(first, second)


def test_seeded_rig_draws_fresh_noise_each_tap():
    rig = VirtualRig(seed=0)
    x, y = rig.layout.centre_mm("A")
    assert (rig.tap(x, y, 5.0).frame != rig.tap(x, y, 5.0).frame).any()


def test_sensor_by_preset_name_or_config():
    by_name = VirtualRig(sensor="tactip_127", seed=None)
    by_config = VirtualRig(sensor=sensor_preset("tactip_127"), seed=None)
    assert by_name.sensor.config == by_config.sensor.config
    assert by_name.sensor.pin_rest_mm.shape == (127, 2)
    with pytest.raises(ValueError, match="unknown sensor preset"):
        VirtualRig(sensor="nope")


def test_custom_switch_and_layout_are_used():
    stiff = VirtualRig(switch=SwitchModel(actuation_travel_mm=5.0), seed=None)
    x, y = stiff.layout.centre_mm("A")
    assert stiff.tap(x, y, 8.0).pressed_key is None
    assert stiff.tap(x, y, 9.0).pressed_key == "A"
    small = VirtualRig(layout=KeyboardLayout(pitch_mm=18.0), seed=None)
    assert small.tap(*small.layout.centre_mm("P"), 8.0).pressed_key == "P"


def test_pose_as_array():
    np.testing.assert_array_equal(Pose(1.0, 2.0, 3.0, 4.0).as_array(), [1.0, 2.0, 3.0, 4.0])
    assert Pose(1.0, 2.0).as_array().dtype == np.float64
