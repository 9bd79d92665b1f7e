"""The UR5 rig, run end to end on simulated hardware behind the libraries' own APIs.

The stand-ins for ur-rtde, ``cv2.VideoCapture`` and evdev (``rigs/fakes.py``)
are driven by the virtual rig's physics, so every layer above the libraries
runs for real here: the adapters, the safety gate, the tap sequence, the
collection into HDF5 and a training run.
"""

from __future__ import annotations

import contextlib
import copy
import csv
import dataclasses
import importlib.util
import json
import math
import time

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tactile_braille._registration import ENV_IDS
from tactile_braille.agents.config import TrainConfig
from tactile_braille.agents.run import read_progress
from tactile_braille.agents.training import train
from tactile_braille.datasets.collector import collect
from tactile_braille.datasets.procedures import GridTaps, PerturbedTaps
from tactile_braille.datasets.store import load_dataset
from tactile_braille.rigs.base import OutOfWorkspaceError, Pose, Rig, RigError
from tactile_braille.rigs.fakes import FAKE_ECODES, LINUX_KEY_CODES, SimulatedUR5, simulated_config
from tactile_braille.rigs.hardware import TacTipCamera, real_drivers
from tactile_braille.rigs.safety import HARD_MAX_SPEED_MM_S, SafetyLimits
from tactile_braille.rigs.transforms import base_to_work
from tactile_braille.rigs.ur5 import TAP_LOG_COLUMNS, LateKeyEventError, UR5Config, UR5Rig
from tactile_braille.rigs.virtual import VirtualRig
from tactile_braille.sensor.processing import process_frame


def open_rig(world: SimulatedUR5, **config_changes) -> UR5Rig:
    config = dataclasses.replace(world.config, **config_changes)
    return UR5Rig(config, drivers=world.drivers())


@pytest.fixture
def world():
    return SimulatedUR5(simulated_config())


@pytest.fixture
def rig(world):
    with open_rig(world) as ur5:
        yield ur5


def move_commands(world: SimulatedUR5, start: int = 0) -> list[tuple]:
    return [args for name, args in world.commands[start:] if name == "moveL"]


def assert_commands_within_limits(world: SimulatedUR5, rig: UR5Rig, start: int = 0) -> None:
    """Every moveL the arm received lies in the workspace, above the depth limit, under the caps."""
    low_depth, high_depth = rig.limits.depth_range_mm
    for pose, speed, acceleration, asynchronous in move_commands(world, start):
        assert len(pose) == 6 and all(math.isfinite(v) for v in pose)
        work = base_to_work(pose, rig.config.work_frame_mm_deg)
        assert rig.workspace.x_mm[0] - 1e-6 <= work.x_mm <= rig.workspace.x_mm[1] + 1e-6
        assert rig.workspace.y_mm[0] - 1e-6 <= work.y_mm <= rig.workspace.y_mm[1] + 1e-6
        assert low_depth - 1e-6 <= work.depth_mm <= high_depth + 1e-6
        assert rig.workspace.yaw_deg[0] - 1e-6 <= work.yaw_deg <= rig.workspace.yaw_deg[1] + 1e-6
        assert 0 < speed <= rig.config.max_speed_mm_s / 1000 + 1e-12
        assert 0 < acceleration <= rig.config.max_acceleration_mm_s2 / 1000 + 1e-12
        assert asynchronous is False  # every move blocks until it ends


# ------------------------------------------------------------------ the rig
def test_ur5_rig_satisfies_the_rig_protocol(rig):
    assert isinstance(rig, Rig)
    assert copy.deepcopy(rig) is rig  # a handle on hardware is shared, not copied


def test_taps_press_the_key_under_the_sensor_and_not_at_shallow_depths(rig, world):
    for key in ("Q", "A", "M", "SPACE", "UP", "LEFT"):
        x, y = rig.layout.centre_mm(key)
        assert rig.tap(x, y, 8.0).pressed_key == key
        assert rig.tap(x, y, 4.5).pressed_key is None  # 1 mm into the key top: short of actuation
    assert world.pressed_log == ["Q", "A", "M", "SPACE", "UP", "LEFT"]
    # Between taps the sensor is back at the travel height above the last key.
    assert world.sensor_pose().depth_mm == pytest.approx(-rig.config.travel_height_mm)
    assert rig.stats["taps"] == 12
    assert rig.stats["stray_key_presses"] == 0


def test_tap_sequence_goes_down_at_the_target_and_back_up(rig, world):
    x, y = rig.layout.centre_mm("F")
    rig.tap(x, y, 6.0, yaw_deg=5.0)
    start = len(world.commands)
    rig.tap(x + 1.0, y, 6.5, yaw_deg=5.0)
    moves = [base_to_work(args[0], rig.config.work_frame_mm_deg) for args in move_commands(world, start)]
    # Across at the travel height, straight down, straight up: the tap's three moves.
    assert [round(m.depth_mm, 6) for m in moves] == [-3.0, 6.5, -3.0]
    for move in moves:
        assert move.x_mm == pytest.approx(x + 1.0)
        assert move.y_mm == pytest.approx(y)
        assert move.yaw_deg == pytest.approx(5.0)
    speeds = {args[1] for args in move_commands(world, start)}
    assert speeds == {rig.config.speed_mm_s / 1000}


def test_tcp_offset_is_set_before_any_move(world):
    with open_rig(world) as rig:
        rig.tap(*rig.layout.centre_mm("A"), 5.0)
    names = [name for name, _ in world.commands]
    assert names[0] == "setTcp"
    np.testing.assert_allclose(world.commands[0][1][0][:3], [0.0, 0.0, 0.125])  # the paper's 125 mm
    assert names.index("setTcp") < names.index("moveL")


def test_first_move_starts_straight_up_from_where_the_arm_is(world):
    start = world.sensor_pose()
    with open_rig(world) as rig:
        rig.move_to(*rig.layout.centre_mm("J"))
        first = base_to_work(move_commands(world)[0][0], rig.config.work_frame_mm_deg)
    assert (first.x_mm, first.y_mm) == pytest.approx((start.x_mm, start.y_mm))
    assert first.depth_mm == pytest.approx(-rig.config.safe_height_mm)


def test_frames_are_the_virtual_sensors_at_the_same_pose(rig):
    """The camera path (two reads, grey conversion) returns the frame at the tap's bottom."""
    virtual = VirtualRig(seed=None)
    for key, depth, yaw in (("G", 5.0, 0.0), ("K", 6.0, 8.0), ("DOWN", 4.5, -6.0)):
        x, y = rig.layout.centre_mm(key)
        sample = rig.tap(x + 0.4, y - 0.3, depth, yaw)
        assert sample.frame.shape == (480, 640) and sample.frame.dtype == np.uint8
        expected = process_frame(virtual.tap(x + 0.4, y - 0.3, depth, yaw).frame, virtual.processing)
        observed = process_frame(sample.frame, rig.processing)
        assert (observed == expected).mean() > 0.995


def test_the_camera_keeps_the_second_of_two_frames(world):
    """The driver's buffer holds a stale frame: the first read after a move shows the old pose."""
    camera = TacTipCamera(world.drivers(), 0, (640, 480), exposure=150.0)
    camera.read()
    world.jog_to_key_top("H")  # the tip now touches H
    fresh = camera.read()
    np.testing.assert_array_equal(fresh, world.render()[..., 0])
    capture = world.drivers().video_capture(0)
    capture.read()
    world.jog_to_key_top("A")
    _, stale = capture.read()
    assert not np.array_equal(stale, world.render())  # one read would have been the previous pose
    assert world.camera_settings[15] == 150.0  # cv2.CAP_PROP_EXPOSURE
    camera.close()


def test_key_codes_map_to_layout_names(rig):
    assert rig.keyboard.key_name(LINUX_KEY_CODES["KEY_A"]) == "A"
    assert rig.keyboard.key_name(LINUX_KEY_CODES["KEY_DELETE"]) == "DEL"
    assert rig.keyboard.key_name(LINUX_KEY_CODES["KEY_SYSRQ"]) == "PRTSC"
    assert rig.keyboard.key_name(9999) is None
    for key in rig.layout.keys:  # every key of the layout has a code the rig understands
        code = next(c for c, name in FAKE_ECODES.KEY.items() if rig.keyboard.key_name(c) == key.name)
        assert code > 0


def test_switch_chatter_is_debounced_and_stray_presses_are_ignored(world):
    rig = open_rig(world, key_debounce_s=0.05)
    x, y = rig.layout.centre_mm("S")
    rig.tap(x, y, 5.0)
    # Someone touches the keyboard between taps: one press that chatters (two downs 10 ms apart).
    now = time.time()
    world.inject_key_event(LINUX_KEY_CODES["KEY_Z"], 1, now)
    world.inject_key_event(LINUX_KEY_CODES["KEY_Z"], 1, now + 0.01)
    sample = rig.tap(x, y, 8.0)
    assert sample.pressed_key == "S"
    assert rig.stats["stray_key_presses"] == 1  # the chatter counted once
    rig.close()


def test_dry_run_sends_no_motion_and_records_the_commands(world):
    with open_rig(world, dry_run=True) as rig:
        x, y = rig.layout.centre_mm("A")
        sample = rig.tap(x, y, 8.0)
        sent = list(rig.arm.sent)
    assert sample.pressed_key is None  # nothing moved, nothing pressed
    assert world.commands == []  # no control interface was even opened
    moves = [args for name, args in sent if name == "moveL"]
    bottom = base_to_work(moves[-2][0], world.config.work_frame_mm_deg)
    assert (bottom.x_mm, bottom.y_mm, bottom.depth_mm) == pytest.approx((x, y, 8.0))
    assert sent[0][0] == "setTcp"


def test_tap_log_records_each_taps_wall_time(world, tmp_path):
    log = tmp_path / "logs" / "taps.csv"
    with open_rig(world, tap_log=str(log)) as rig:
        for key in ("A", "B"):
            rig.tap(*rig.layout.centre_mm(key), 8.0)
        mean = rig.mean_tap_time_s
    rows = list(csv.DictReader(log.open()))
    assert tuple(rows[0]) == TAP_LOG_COLUMNS
    assert [r["pressed_key"] for r in rows] == ["A", "B"]
    assert all(float(r["wall_time_s"]) > 0 for r in rows)
    assert mean == pytest.approx(np.mean([float(r["wall_time_s"]) for r in rows]), abs=1e-3)


def test_close_retracts_to_the_safe_height_and_releases_everything(world):
    rig = open_rig(world)
    rig.tap(*rig.layout.centre_mm("A"), 5.0)
    device = rig.keyboard._device
    rig.close()
    rig.close()  # idempotent
    assert world.sensor_pose().depth_mm == pytest.approx(-rig.config.safe_height_mm)
    assert not device.grabbed
    assert [name for name, _ in world.commands][-2:] == ["stopScript", "disconnect"]
    with pytest.raises(RigError, match="closed"):
        rig.tap(*rig.layout.centre_mm("A"), 5.0)


def test_config_round_trips_through_json_and_refuses_bad_settings(tmp_path):
    config = simulated_config(crop_px=(108, 38, 512, 442))
    path = config.save(tmp_path / "rig.json")
    assert UR5Config.load(path) == config
    with pytest.raises(ValueError, match="unknown UR5 rig settings"):
        UR5Config.from_json({**config.to_json(), "speed": 1})
    with pytest.raises(ValueError, match="speed_mm_s"):
        simulated_config(speed_mm_s=400.0)
    with pytest.raises(ValueError, match="work_frame_mm_deg"):
        simulated_config(work_frame_mm_deg=(0, 0, float("nan"), 0, 0, 0))
    with pytest.raises(ValueError, match="max_speed_mm_s"):
        SafetyLimits(_box(), 30.0, HARD_MAX_SPEED_MM_S + 1, 500.0)
    with pytest.raises(FileNotFoundError, match="no rig settings"):
        UR5Config.load(tmp_path / "missing.json")


def _box():
    from tactile_braille.rigs.base import Workspace

    return Workspace((0.0, 10.0), (0.0, 10.0), (0.0, 9.0))


# ------------------------------------------------------------------ safety
JUNK = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(10**400), max_value=10**400),
    st.sampled_from([np.float32(10.0), np.int64(-40), np.float64(np.nan), 1e308, -1e308]),
    st.text(max_size=3),
    st.none(),
    st.booleans(),
    st.just(1 + 2j),
    st.just([1.0]),
)
"""Anything a caller might pass by mistake."""


@st.composite
def tap_arguments(draw, box: dict[str, tuple[float, float]]) -> dict[str, object]:
    """Numbers in and a little outside each range of ``box``; half the time one of them is junk."""
    spoiled = draw(st.sampled_from([None, None, None, None, *box]))
    arguments = {}
    for name, (low, high) in box.items():
        margin = 0.1 * (high - low) + 0.5
        numbers = st.floats(min_value=low - margin, max_value=high + margin)
        arguments[name] = draw(JUNK if name == spoiled else numbers)
    return arguments


def test_no_input_makes_a_command_outside_the_limits():
    world = SimulatedUR5(simulated_config())
    accepted = []
    with open_rig(world) as rig:
        box = {"x_mm": rig.workspace.x_mm, "y_mm": rig.workspace.y_mm, "depth_mm": (0.0, 9.0),
               "yaw_deg": (-45.0, 45.0)}  # fmt: skip

        @settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
        @given(arguments=tap_arguments(box))
        def tap_anything(arguments):
            x, y, depth, yaw = arguments.values()
            before = len(world.commands)
            try:
                rig.tap(x, y, depth, yaw)
            except OutOfWorkspaceError:
                assert len(world.commands) == before  # refused before anything was sent
            else:
                accepted.append((x, y, depth, yaw))
                assert len(move_commands(world, before)) >= 2  # down and up (and across unless there)
            with contextlib.suppress(OutOfWorkspaceError):
                rig.move_to(x, y, yaw)
            assert_commands_within_limits(world, rig, before)

        tap_anything()
        assert world.max_depth_mm <= rig.config.max_depth_mm + 1e-6
    assert len(accepted) >= 20  # the property held over real taps, not only over refusals
    assert_commands_within_limits(world, rig)


COORDINATE = st.one_of(st.floats(min_value=-60.0, max_value=60.0), JUNK)


@given(
    pose=st.tuples(COORDINATE, COORDINATE, st.one_of(st.floats(-40.0, 12.0), COORDINATE), COORDINATE),
    speed=st.one_of(st.floats(-10.0, 400.0), COORDINATE),
    acceleration=st.one_of(st.floats(-10.0, 3000.0), COORDINATE),
)
def test_the_safety_gate_returns_only_motions_within_the_limits(pose, speed, acceleration):
    limits = SafetyLimits(_box(), safe_height_mm=30.0, max_speed_mm_s=100.0, max_acceleration_mm_s2=800.0)
    try:
        motion = limits.check(Pose(*pose), speed, acceleration)
    except OutOfWorkspaceError as error:
        assert str(error)  # says what was wrong
        return
    checked = motion.pose.as_array()
    assert np.isfinite(checked).all() and type(motion.speed_mm_s) is float
    assert 0.0 <= checked[0] <= 10.0 and 0.0 <= checked[1] <= 10.0
    assert -30.0 <= checked[2] <= 9.0 and -45.0 <= checked[3] <= 45.0
    assert 0 < motion.speed_mm_s <= 100.0 and 0 < motion.acceleration_mm_s2 <= 800.0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((float("nan"), -50.0, 5.0), "x_mm=nan is not a finite number"),
        ((10.0, "left", 5.0), "y_mm='left' is not a real number"),
        ((10.0, -50.0, 9.5), "depth_mm=9.500 is outside"),
        ((10.0, -50.0, None), "depth_mm=None is not a real number"),
        ((10**400, -50.0, 5.0), "not representable"),
        ((True, -50.0, 5.0), "x_mm=True is not a real number"),
    ],
)
def test_bad_taps_raise_clear_errors_before_anything_moves(rig, world, args, message):
    before = len(world.commands)
    with pytest.raises(OutOfWorkspaceError, match=message):
        rig.tap(*args)
    assert len(world.commands) == before


def test_an_arm_started_away_from_the_keyboard_is_not_moved():
    world = SimulatedUR5(simulated_config(), start_pose=Pose(300.0, -100.0, -40.0))
    with open_rig(world) as rig:
        with pytest.raises(RigError, match="not above the keyboard's workspace"):
            rig.tap(*rig.layout.centre_mm("A"), 5.0)
        assert move_commands(world) == []


# ---------------------------------------------------------- missing hardware
@pytest.mark.skipif(
    importlib.util.find_spec("rtde_control") is not None or importlib.util.find_spec("evdev") is not None,
    reason="the robot extra is installed here",
)
def test_missing_libraries_name_the_extra_to_install():
    drivers = real_drivers()
    hint = r"pip install 'tactile_braille\[robot\]'"
    with pytest.raises(RigError, match=f"needs the package ur-rtde.*{hint}"):
        drivers.rtde_control("10.0.0.2")
    with pytest.raises(RigError, match=f"needs the package ur-rtde.*{hint}"):
        drivers.rtde_receive("10.0.0.2")
    with pytest.raises(RigError, match=f"needs the package evdev.*{hint}"):
        drivers.input_device("/dev/input/event0")
    with pytest.raises(RigError, match=hint):
        UR5Rig(simulated_config())  # the real libraries by default


@pytest.mark.parametrize(
    ("fault", "message"),
    [
        ("robot_reachable", "cannot connect to the UR robot at 'simulated-ur5'"),
        ("camera_present", "no camera at /dev/video0"),
        ("keyboard_paths", "no keyboard at"),
    ],
)
def test_missing_devices_raise_clear_errors_and_release_the_others(world, fault, message):
    setattr(world, fault, set() if fault == "keyboard_paths" else False)
    opened = []
    drivers = world.drivers()

    def open_device(path):
        opened.append(drivers.input_device(path))
        return opened[-1]

    wrapped = dataclasses.replace(drivers, input_device=open_device)
    with pytest.raises(RigError, match=message):
        UR5Rig(world.config, drivers=wrapped)
    assert all(not device.grabbed for device in opened)  # nothing left holding the keyboard
    assert move_commands(world) == []


# ------------------------------------------------------------ fault injection
def test_a_camera_that_misses_a_frame_is_retried(rig, world):
    world.camera_failures = 2  # both reads of the first grab
    sample = rig.tap(*rig.layout.centre_mm("D"), 8.0)
    assert sample.pressed_key == "D"
    assert rig.stats["camera_retries"] == 1


def test_a_camera_that_gives_no_frame_stops_the_tap_with_the_arm_retracted(rig, world):
    world.camera_failures = 4  # both grabs
    with pytest.raises(RigError, match=r"camera returned no frame \(2 tries\).*retracted to the safe height"):
        rig.tap(*rig.layout.centre_mm("D"), 6.0)
    assert world.sensor_pose().depth_mm == pytest.approx(-rig.config.safe_height_mm)
    assert rig.stats["retracts"] == 1
    assert rig.tap(*rig.layout.centre_mm("D"), 8.0).pressed_key == "D"  # the rig carries on


@pytest.mark.parametrize("drop_mode", ["raise", "false"])
def test_a_dropped_connection_ends_in_a_rig_error_and_a_retract_attempt(rig, world, drop_mode):
    rig.tap(*rig.layout.centre_mm("E"), 5.0)
    world.drop_after_moves, world.drop_mode = world.moves + 2, drop_mode  # during the next tap's descent
    before = len(world.commands)
    with pytest.raises(RigError, match="retracting to the safe height failed too"):
        rig.tap(*rig.layout.centre_mm("R"), 8.0)
    assert [name for name, _ in world.commands[before:]][-1] == "reconnect"  # it tried to get the arm back
    (stop, _), (last_move, (pose, *_)) = rig.arm.sent[-2:]  # then stop and go up, which the link refused
    assert (stop, last_move) == ("stopL", "moveL")
    up = base_to_work(pose, rig.config.work_frame_mm_deg)
    assert up.depth_mm == pytest.approx(-rig.config.safe_height_mm)
    assert rig.stats["retracts"] == 1


def test_a_connection_that_comes_back_lets_the_arm_retract(rig, world):
    rig.tap(*rig.layout.centre_mm("E"), 5.0)
    world.drop_after_moves, world.reconnect_allowed = world.moves + 2, True
    with pytest.raises(RigError, match="Robot is disconnected; the arm retracted to the safe height"):
        rig.tap(*rig.layout.centre_mm("R"), 8.0)
    assert world.sensor_pose().depth_mm == pytest.approx(-rig.config.safe_height_mm)
    assert_commands_within_limits(world, rig)


def test_a_late_key_event_within_the_grace_period_is_attributed_to_its_tap(world):
    world.key_delay_s = 0.08
    with open_rig(world, key_grace_s=0.3) as rig:
        assert rig.tap(*rig.layout.centre_mm("T"), 8.0).pressed_key == "T"
        assert rig.tap(*rig.layout.centre_mm("T"), 5.0).pressed_key is None


def test_a_key_event_later_than_the_grace_period_stops_the_next_tap(world):
    with open_rig(world, key_grace_s=0.0) as rig:
        rig.tap(*rig.layout.centre_mm("Y"), 5.0)  # the first render is slow: warm up
        world.key_delay_s = 0.4
        assert rig.tap(*rig.layout.centre_mm("Y"), 8.0).pressed_key is None  # its press is still on the way
        time.sleep(0.5)
        with pytest.raises(LateKeyEventError, match="a press of Y arrived after the previous tap"):
            rig.tap(*rig.layout.centre_mm("U"), 5.0)
        assert world.sensor_pose().depth_mm == pytest.approx(-rig.config.safe_height_mm)


# --------------------------------------------------------------- end to end
def test_collection_on_the_ur5_rig_matches_the_virtual_rig(tmp_path):
    """The same procedure writes the same HDF5 dataset on the UR5 path as on the virtual rig."""
    procedure = PerturbedTaps(keys="arrows", per_key=3)
    world = SimulatedUR5(simulated_config())
    with open_rig(world) as rig:
        collect(rig, procedure, tmp_path / "ur5.h5", seed=3, progress=False, shard_size=4)
    collect(VirtualRig(seed=None), procedure, tmp_path / "virtual.h5", seed=3, progress=False)
    ur5, virtual = load_dataset(tmp_path / "ur5.h5"), load_dataset(tmp_path / "virtual.h5")
    assert ur5.metadata.rig == "ur5" and len(ur5) == len(procedure) == 15
    np.testing.assert_array_equal(ur5.poses, virtual.poses)
    np.testing.assert_array_equal(ur5.labels, virtual.labels)
    np.testing.assert_array_equal(ur5.pressed, virtual.pressed)
    assert (ur5.observations == virtual.observations).mean() > 0.995


def test_grid_collection_records_the_keys_the_robot_pressed(tmp_path):
    procedure = GridTaps(keys="arrows", spacing_mm=10, depth_step_mm=3)
    world = SimulatedUR5(simulated_config())
    with open_rig(world) as rig:
        collect(rig, procedure, tmp_path / "grid.h5", progress=False)
    dataset = load_dataset(tmp_path / "grid.h5")
    pressed = [name for name in dataset.pressed_names() if name != "NONE"]
    assert pressed == world.pressed_log and len(pressed) > 0
    virtual = VirtualRig(seed=None)
    expected = [virtual.tap(*pose[:3], pose[3]).pressed_key or "NONE" for pose in dataset.poses]
    assert list(dataset.pressed_names()) == expected


def test_a_collection_stopped_by_a_dropped_connection_resumes_with_no_sample_lost(tmp_path):
    procedure = PerturbedTaps(keys="arrows", per_key=4)  # 20 taps
    output = tmp_path / "interrupted.h5"
    world = SimulatedUR5(simulated_config())
    world.drop_after_moves, world.reconnect_allowed = 35, True  # about the 11th of 20 taps
    rig = open_rig(world)
    with pytest.raises(RigError, match="the arm retracted to the safe height"):
        collect(rig, procedure, output, seed=5, progress=False, shard_size=8)
    rig.close()
    assert world.sensor_pose().depth_mm <= -rig.config.safe_height_mm + 1e-6
    assert not output.exists() and output.with_name(output.name + ".partial").exists()

    done_before = rig.stats["taps"]
    assert 0 < done_before < len(procedure)
    with open_rig(world) as resumed:
        collect(resumed, procedure, output, seed=5, resume=True, progress=False, shard_size=8)
        assert resumed.stats["taps"] == len(procedure) - done_before  # every finished tap was kept
    dataset = load_dataset(output)
    np.testing.assert_array_equal(dataset.tap_index, np.arange(len(procedure)))
    reference_world = SimulatedUR5(simulated_config())
    with open_rig(reference_world) as reference_rig:
        collect(reference_rig, procedure, tmp_path / "reference.h5", seed=5, progress=False)
    reference = load_dataset(tmp_path / "reference.h5")
    for name in ("observations", "poses", "labels", "pressed"):
        np.testing.assert_array_equal(getattr(dataset, name), getattr(reference, name), err_msg=name)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_every_task_runs_on_the_ur5_rig(env_id):
    """The four environments with backend="rig" tap the UR5 rig, inside its limits."""
    world = SimulatedUR5(simulated_config())
    with open_rig(world) as rig:
        env = gym.make(env_id, backend="rig", rig=rig)
        observation, _ = env.reset(seed=1)
        env.action_space.seed(1)
        for _ in range(4):
            observation, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                observation, _ = env.reset()
        assert observation["observation"].shape == (100, 100, 1)
        assert 0 < observation["observation"].mean() < 255  # a real tactile image, not a blank
        assert rig.stats["taps"] >= 5
        assert_commands_within_limits(world, rig)
        env.close()


def test_training_on_the_ur5_rig_checkpoints_survives_a_fault_and_resumes(tmp_path):
    """DQN + HER on DiscreteArrows with backend="rig": a fault mid-run, then a resume to the end."""
    world = SimulatedUR5(simulated_config(tap_log=str(tmp_path / "taps.csv")))
    config = TrainConfig(
        agent={"batch_size": 8, "hidden": (16,)},  # a small agent: the test is of the loop, not of learning
        task="tactile_braille/DiscreteArrows-v0",
        backend="rig",
        epochs=2,
        steps_per_epoch=60,
        start_steps=30,
        updates_per_step=1,
        threads=1,
        evaluation={"test_episodes": 2},
        replay={"capacity": 1000},
    )
    run_dir = tmp_path / "run"
    rig = open_rig(world)
    world.reconnect_allowed = True
    world.drop_after_moves = None
    dropped = []

    class DropInSecondEpoch:  # the connection drops once the first epoch's checkpoint exists
        def __init__(self, inner):
            self.inner = inner

        def __deepcopy__(self, memo):
            return self

        def __getattr__(self, name):
            return getattr(self.inner, name)

        def tap(self, *args, **kwargs):
            if (run_dir / "checkpoint.pt").exists() and not dropped:
                dropped.append(self.inner.stats["taps"])
                world.drop_after_moves = world.moves + 2
            return self.inner.tap(*args, **kwargs)

    with pytest.raises(RigError, match="retracted to the safe height"):
        train(config, run_dir=run_dir, progress=False, rig=DropInSecondEpoch(rig))
    rig.close()
    assert [int(r["epoch"]) for r in read_progress(run_dir)] == [0]

    with open_rig(world) as resumed_rig:
        train(run_dir=run_dir, resume=True, progress=False, rig=resumed_rig)
        assert resumed_rig.stats["taps"] >= 60  # the second epoch ran on the rig
    rows = read_progress(run_dir)
    assert [int(r["epoch"]) for r in rows] == [0, 1]
    assert [int(r["env_steps"]) for r in rows] == [60, 120]
    assert all(r["charts/SPS"] > 0 for r in rows)
    taps = list(csv.DictReader((tmp_path / "taps.csv").open()))
    assert len(taps) >= 120 + 2 * 2  # every env step, test episode and reset tapped the rig
    assert all(float(t["wall_time_s"]) > 0 for t in taps)
    assert_commands_within_limits(world, resumed_rig)


def test_collect_and_train_commands_run_on_the_ur5_code_path(tmp_path, capsys):
    from tactile_braille.cli import main

    output = tmp_path / "robot.h5"
    assert main(["collect", "--rig", "simulated-ur5", "--keys", "arrows", "--per-key", "2",
                 "--output", str(output)]) == 0  # fmt: skip
    dataset = load_dataset(output)
    assert dataset.metadata.rig == "ur5" and len(dataset) == 10
    assert main(["collect", "--rig", "ur5", "--keys", "arrows", "--output", str(tmp_path / "x.h5")]) == 2
    assert "--rig-config rig.json" in capsys.readouterr().err  # a real robot needs its settings
    run = tmp_path / "run"
    assert main(["train", "DiscreteArrows-v0", "dqn", "--simulated-rig", "--epochs", "1",  # implies the rig
                 "--test-episodes", "1", "--updates-per-step", "1", "--threads", "1", "--run-dir", str(run),
                 "--agent.batch-size", "8", "--agent.hidden", "16", "--quiet"]) == 0  # fmt: skip
    rows = read_progress(run)
    assert [int(r["epoch"]) for r in rows] == [0] and rows[0]["env_steps"] == 250
    assert json.loads((run / "config.json").read_text())["backend"] == "rig"
