"""Setting up the UR5 rig: frame conversions, the work-frame fit, the crop box and the threshold preview."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tactile_braille.cli import main
from tactile_braille.rigs.base import Pose
from tactile_braille.rigs.calibration import (
    REFERENCE_KEYS,
    fit_work_frame,
    propose_crop_box,
    record_reference_poses,
    save_threshold_preview,
    threshold_preview,
)
from tactile_braille.rigs.fakes import SimulatedUR5, simulated_config
from tactile_braille.rigs.hardware import URArm
from tactile_braille.rigs.transforms import (
    base_to_work,
    rotation_from_euler_deg,
    rotation_from_rotvec,
    rotvec_from_rotation,
    tcp_offset_to_ur,
    work_to_base,
)
from tactile_braille.rigs.ur5 import UR5Rig
from tactile_braille.rigs.virtual import VirtualRig
from tactile_braille.sensor.config import ImageProcessing
from tactile_braille.sensor.processing import process_frame

FRAME = (400.0, -150.0, 120.0, 180.0, 0.0, 0.0)


# ---------------------------------------------------------------- transforms
def test_a_flat_keyboard_frame_flips_y_and_z_into_the_base():
    tool = work_to_base(Pose(10.0, 20.0, 5.0, 0.0), FRAME)
    np.testing.assert_allclose(tool[:3], [0.410, -0.170, 0.115], atol=1e-12)  # depth goes down
    np.testing.assert_allclose(np.abs(tool[3:]), [np.pi, 0.0, 0.0], atol=1e-9)  # the tool points down
    turned = work_to_base(Pose(10.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 180.0, 0.0, 90.0))
    np.testing.assert_allclose(turned[:3], [0.0, 0.010, 0.0], atol=1e-12)  # yaw 90: work x along base y


@given(
    pose=st.tuples(st.floats(-200, 200), st.floats(-300, 300), st.floats(-40, 15), st.floats(-179, 179)),
    frame=st.tuples(
        st.floats(-800, 800),
        st.floats(-800, 800),
        st.floats(-200, 600),
        st.floats(-180, 180),
        st.floats(-30, 30),
        st.floats(-180, 180),
    ),
)
def test_work_and_base_poses_round_trip(pose, frame):
    there = Pose(*pose)
    back = base_to_work(work_to_base(there, frame), frame)
    np.testing.assert_allclose(back.as_array()[:3], there.as_array()[:3], atol=1e-6)
    assert (back.yaw_deg - there.yaw_deg + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-6)


@given(axis=st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)), angle=st.floats(0.0, np.pi))
def test_rotation_vectors_round_trip_up_to_half_a_turn(axis, angle):
    axis = np.array(axis)
    if np.linalg.norm(axis) < 1e-3:
        axis = np.array([0.0, 0.0, 1.0])
    rotvec = axis / np.linalg.norm(axis) * angle
    rotation = rotation_from_rotvec(rotvec)
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(rotation_from_rotvec(rotvec_from_rotation(rotation)), rotation, atol=1e-9)
    assert np.linalg.norm(rotvec_from_rotation(rotation)) <= np.pi + 1e-9


def test_the_papers_tool_offset_becomes_a_125_mm_tcp_turned_minus_145_degrees():
    tcp = tcp_offset_to_ur((0.0, 0.0, 125.0, 0.0, 0.0, -145.0))
    np.testing.assert_allclose(tcp, [0.0, 0.0, 0.125, 0.0, 0.0, np.radians(-145.0)], atol=1e-12)
    np.testing.assert_allclose(rotation_from_euler_deg(0, 0, -145), rotation_from_rotvec(tcp[3:]), atol=1e-12)


# ------------------------------------------------------------ work-frame fit
TRUE_FRAME = (412.3, -131.7, 117.9, 180.0, 0.0, 23.5)


def test_jogging_to_reference_keys_recovers_the_keyboards_true_frame():
    """The configured frame is 15 mm and 3.5 deg off; the fit on four jogged keys finds the true one."""
    world = SimulatedUR5(simulated_config(), true_work_frame_mm_deg=TRUE_FRAME)
    rng = np.random.default_rng(0)
    arm = URArm(world.drivers(), world.config.host, [0.0] * 6, dry_run=True)
    poses = record_reference_poses(
        arm.tool_pose, REFERENCE_KEYS, lambda key: world.jog_to_key_top(key, noise_mm=0.05, rng=rng)
    )
    fit = fit_work_frame(poses, clearance_mm=world.config.clearance_mm)
    np.testing.assert_allclose(fit.work_frame_mm_deg[:3], TRUE_FRAME[:3], atol=0.15)
    assert fit.work_frame_mm_deg[5] == pytest.approx(TRUE_FRAME[5], abs=0.1)
    assert fit.work_frame_mm_deg[3:5] == (180.0, 0.0)
    assert set(fit.residuals_mm) == set(REFERENCE_KEYS)
    assert 0.0 < fit.rms_mm < 0.15 and fit.height_spread_mm < 1e-6
    world.place_sensor(Pose(20.0, -100.0, -40.0))  # the operator jogs the sensor off the keys

    def presses(frame) -> list[str | None]:
        config = simulated_config(work_frame_mm_deg=frame)
        with UR5Rig(config, drivers=world.drivers()) as rig:
            return [rig.tap(*rig.layout.centre_mm(k), 8.0).pressed_key for k in ("Q", "H", "P", "DOWN")]

    assert presses(fit.work_frame_mm_deg) == ["Q", "H", "P", "DOWN"]
    assert presses(world.config.work_frame_mm_deg) != ["Q", "H", "P", "DOWN"]  # the uncalibrated rig misses


def test_the_fit_reports_a_misplaced_key_and_refuses_too_few_keys():
    world = SimulatedUR5(simulated_config())
    poses = {}
    for key in REFERENCE_KEYS:
        world.jog_to_key_top(key)
        poses[key] = world.tool_pose()
    poses["Z"] = list(np.add(poses["Z"], [0.004, 0.0, 0.0, 0.0, 0.0, 0.0]))  # jogged 4 mm off
    fit = fit_work_frame(poses)
    assert max(fit.residuals_mm, key=fit.residuals_mm.get) == "Z"
    assert fit.rms_mm > 1.0
    with pytest.raises(ValueError, match="at least two keys"):
        fit_work_frame({"Q": poses["Q"]})
    with pytest.raises(ValueError, match="did the arm move between keys"):
        fit_work_frame({"Q": poses["Q"], "P": poses["Q"]})


def test_rig_calibrate_command_prints_the_fit_and_writes_the_config(tmp_path, capsys):
    config = simulated_config(work_frame_mm_deg=(405.0, -140.0, 118.0, 180.0, 0.0, 18.0))
    path = config.save(tmp_path / "rig.json")
    assert main(["rig", "calibrate", "--simulated", "--config", str(path), "--write"]) == 0
    out = capsys.readouterr().out
    assert "work_frame_mm_deg: [405.000, -140.000, 118.000, 180.000, 0.000, 18.000]" in out
    assert "RIGHT: residual 0.00 mm" in out


# ------------------------------------------------------- crop box, threshold
@pytest.fixture(scope="module")
def frame():
    return VirtualRig(seed=0).tap(0.0, 0.0, 0.0).frame  # no contact


def test_the_crop_box_proposal_finds_the_sensor(frame):
    proposal = propose_crop_box(frame)
    np.testing.assert_allclose(proposal, ImageProcessing().crop_px, atol=4)  # the paper's box
    assert proposal[2] - proposal[0] == proposal[3] - proposal[1]  # square
    shifted = np.roll(frame, (12, -20), axis=(0, 1))
    moved = propose_crop_box(cv2.cvtColor(shifted, cv2.COLOR_GRAY2BGR))
    np.testing.assert_allclose(np.subtract(moved, proposal), [-20, 12, -20, 12], atol=2)
    with pytest.raises(ValueError, match="too few to be the sensor's pins"):
        propose_crop_box(np.full((480, 640), 20, np.uint8))


def test_the_threshold_preview_shows_the_observation(frame, tmp_path):
    processing = ImageProcessing()
    preview = threshold_preview(frame, processing)
    assert preview.shape == (480, 640 + 480 + 480, 3)
    centres = ((np.arange(100) + 0.5) * 4.8).astype(int)
    shown = preview[:, -480:, 0][np.ix_(centres, centres)]
    observation = process_frame(frame, processing)
    assert (shown[10:] == observation[10:]).mean() > 0.99  # the title covers the top rows
    path = save_threshold_preview(frame, processing, tmp_path / "preview.png")
    assert cv2.imread(str(path)).shape == preview.shape


def test_rig_crop_and_check_commands_run_on_simulated_hardware(tmp_path, capsys):
    path = simulated_config().save(tmp_path / "rig.json")
    assert main(["rig", "crop", "--simulated", "--config", str(path), "--output", str(tmp_path / "p.png"),
                 "--write"]) == 0  # fmt: skip
    assert "proposed crop_px" in capsys.readouterr().out
    assert (tmp_path / "p.png").exists()
    from tactile_braille.rigs.ur5 import UR5Config

    assert UR5Config.load(path).crop_px is not None
    assert main(["rig", "check", "--dry-run", "--keys", "A,F"]) == 0
    out = capsys.readouterr().out
    assert "dry run" in out and "logged, not sent" in out and out.count("moveL(") >= 6
    assert main(["rig", "check", "--simulated", "--depth", "8", "--keys", "A,SPACE"]) == 0
    assert "simulated keyboard registered: ['A', 'SPACE']" in capsys.readouterr().out
    assert main(["rig", "check", "--config", str(tmp_path / "missing.json")]) == 2
    assert "no rig settings" in capsys.readouterr().err
