"""A simulated UR5 rig behind the hardware libraries' own APIs, driven by the virtual rig's physics.

:class:`SimulatedUR5` is the world: a UR5 whose tool follows ``moveL``, a
keyboard placed at a *true* work frame (which calibration may have to find),
a TacTip mounted at a *true* tool offset. Its :meth:`~SimulatedUR5.drivers`
hands out stand-ins for ``rtde_control.RTDEControlInterface``,
``rtde_receive.RTDEReceiveInterface``, ``cv2.VideoCapture`` and
``evdev.InputDevice`` (with an ``evdev.ecodes``-like table), with the same
method names and signatures, so that :class:`~tactile_braille.rigs.ur5.UR5Rig`
and its adapters run unchanged on them:

* the arm tracks the tool pose from ``moveL``/``setTcp`` and records every call;
* when the sensor is down on a key, the keyboard emits the key event the
  virtual rig's switch model computes (and the release when it comes up);
* the camera returns the virtual rig's rendered frame (BGR, 640x480) at the
  sensor's true pose, through a one-frame buffer like a real driver's, so
  the rig's real image processing runs on it.

Faults can be injected: a camera that returns no frame, a connection that
drops after some moves, key events delivered late, a stray key press, a
missing robot, camera or keyboard. Tests, ``tactile-braille rig check
--simulated`` and the documentation's examples use it.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, replace
from types import SimpleNamespace

import cv2
import numpy as np

from tactile_braille.rigs.base import Pose, Workspace
from tactile_braille.rigs.hardware import Drivers
from tactile_braille.rigs.transforms import (
    FramePose,
    homogeneous,
    homogeneous_from_ur,
    sensor_transform,
    ur_from_homogeneous,
)
from tactile_braille.rigs.ur5 import UR5Config
from tactile_braille.rigs.virtual import VirtualRig

EV_SYN, EV_KEY = 0, 1
LINUX_KEY_CODES: dict[str, int] = {
    "KEY_ESC": 1, **{f"KEY_{d}": 2 + i for i, d in enumerate("1234567890")}, "KEY_MINUS": 12, "KEY_EQUAL": 13,
    "KEY_BACKSPACE": 14, "KEY_TAB": 15, **{f"KEY_{c}": 16 + i for i, c in enumerate("QWERTYUIOP")},
    "KEY_LEFTBRACE": 26, "KEY_RIGHTBRACE": 27, "KEY_ENTER": 28, "KEY_LEFTCTRL": 29,
    **{f"KEY_{c}": 30 + i for i, c in enumerate("ASDFGHJKL")}, "KEY_SEMICOLON": 39, "KEY_APOSTROPHE": 40,
    "KEY_GRAVE": 41, "KEY_LEFTSHIFT": 42, "KEY_BACKSLASH": 43,
    **{f"KEY_{c}": 44 + i for i, c in enumerate("ZXCVBNM")}, "KEY_COMMA": 51, "KEY_DOT": 52, "KEY_SLASH": 53,
    "KEY_RIGHTSHIFT": 54, "KEY_LEFTALT": 56, "KEY_SPACE": 57, "KEY_CAPSLOCK": 58,
    **{f"KEY_F{i}": 58 + i for i in range(1, 11)}, "KEY_F11": 87, "KEY_F12": 88, "KEY_RIGHTCTRL": 97,
    "KEY_SYSRQ": 99, "KEY_RIGHTALT": 100, "KEY_HOME": 102, "KEY_UP": 103, "KEY_PAGEUP": 104, "KEY_LEFT": 105,
    "KEY_RIGHT": 106, "KEY_END": 107, "KEY_DOWN": 108, "KEY_PAGEDOWN": 109, "KEY_DELETE": 111,
    "KEY_PAUSE": 119, "KEY_LEFTMETA": 125, "KEY_FN": 464,
}  # fmt: skip
"""Linux input key codes (``linux/input-event-codes.h``) of the rig keyboard's keys."""

FAKE_ECODES = SimpleNamespace(
    EV_SYN=EV_SYN,
    EV_KEY=EV_KEY,
    KEY={code: name for name, code in LINUX_KEY_CODES.items()},
    ecodes={"EV_SYN": EV_SYN, "EV_KEY": EV_KEY, **LINUX_KEY_CODES},
)
"""The part of ``evdev.ecodes`` the rig uses."""

_LAYOUT_TO_EVDEV = {"DEL": "KEY_DELETE", "PRTSC": "KEY_SYSRQ"}


def simulated_config(**overrides) -> UR5Config:
    """A configuration for the simulated rig: a keyboard 400 mm in front of the robot, turned 20 deg.

    ``key_grace_s`` is 0: simulated key events arrive at once (unless delayed on purpose); so is
    ``key_debounce_s``: simulated taps follow each other within milliseconds, not a second.
    """
    config = UR5Config(
        host="simulated-ur5",
        keyboard_device="/dev/input/by-id/simulated-keyboard-event-kbd",
        work_frame_mm_deg=(400.0, -150.0, 120.0, 180.0, 0.0, 20.0),
        key_grace_s=0.0,
        key_debounce_s=0.0,
    )
    return replace(config, **overrides)


@dataclass(frozen=True)
class FakeInputEvent:
    """An ``evdev.InputEvent``: kernel time stamp, type, code and value."""

    sec: int
    usec: int
    type: int
    code: int
    value: int

    def timestamp(self) -> float:
        return self.sec + self.usec / 1e6


def _event(stamp: float, type_: int, code: int, value: int) -> FakeInputEvent:
    sec = int(stamp)
    return FakeInputEvent(sec, round((stamp - sec) * 1e6), type_, code, value)


class SimulatedUR5:
    """The simulated UR5, TacTip and keyboard (see the module docstring).

    Args:
        config: the rig's configuration (its host, devices and camera index are
            what the stand-ins answer to).
        virtual: the physics (default: a noiseless virtual rig).
        true_work_frame_mm_deg: where the keyboard really is (default: the config's).
        true_tcp_offset_mm_deg: where the sensor really is on the flange (default: the config's).
        start_pose: the sensor's first pose in the true work frame (default: 40 mm over the alphabet).
        installation_tcp_mm_deg: the controller's TCP before any ``setTcp`` (default: the
            config's, as set on the teach pendant).
    """

    def __init__(
        self,
        config: UR5Config,
        virtual: VirtualRig | None = None,
        true_work_frame_mm_deg: FramePose | None = None,
        true_tcp_offset_mm_deg: FramePose | None = None,
        start_pose: Pose | None = None,
        installation_tcp_mm_deg: FramePose | None = None,
    ) -> None:
        self.config = config
        unlimited = Workspace((-1e6, 1e6), (-1e6, 1e6), (-1e6, 1e6), (-180.0, 180.0))
        self.virtual = virtual or VirtualRig(seed=None, workspace=unlimited)
        if virtual is not None:
            self.virtual.workspace = unlimited
        self.work_frame = homogeneous(true_work_frame_mm_deg or config.work_frame_mm_deg)
        self.sensor_mount = homogeneous(true_tcp_offset_mm_deg or config.tcp_offset_mm_deg)
        self.active_tcp = homogeneous(installation_tcp_mm_deg or config.tcp_offset_mm_deg)  # until setTcp
        self.place_sensor(start_pose or Pose(20.0, -100.0, -40.0, 0.0))
        # What happened, for tests and the dry-run printout.
        self.commands: list[tuple[str, tuple]] = []
        self.moves = 0
        self.max_depth_mm = -np.inf
        self.camera_settings: dict[int, float] = {}
        self.pressed_log: list[str] = []
        # Presence and faults.
        self.robot_reachable = True
        self.camera_present = True
        self.keyboard_paths = {config.keyboard_device}
        self.connected = True
        self.drop_after_moves: int | None = None
        self.drop_mode = "raise"  # or "false": moveL returns False
        self.reconnect_allowed = False
        self.camera_failures = 0
        self.key_delay_s = 0.0
        self._held: int | None = None
        self._events: list[tuple[float, FakeInputEvent]] = []
        self._lock = threading.Lock()

    # ------------------------------------------------------------ drivers
    def drivers(self) -> Drivers:
        """Constructors of the stand-ins, in place of :func:`~tactile_braille.rigs.hardware.real_drivers`."""
        return Drivers(
            rtde_control=lambda host: FakeRTDEControl(self, host),
            rtde_receive=lambda host: FakeRTDEReceive(self, host),
            video_capture=lambda index: FakeVideoCapture(self, index),
            input_device=lambda path: FakeInputDevice(self, path),
            ecodes=lambda: FAKE_ECODES,
        )

    # ------------------------------------------------------------ physics
    def tool_pose(self) -> list[float]:
        """The controller's TCP pose (m, rotation vector), as ``getActualTCPPose`` reports it."""
        return ur_from_homogeneous(self.flange @ self.active_tcp)

    def sensor_pose(self, flange: np.ndarray | None = None) -> Pose:
        """Where the sensor's tip is in the true work frame (with the flange at ``flange``, default: now)."""
        flange = self.flange if flange is None else flange
        relative = np.linalg.inv(self.work_frame) @ flange @ self.sensor_mount
        x, y, depth = relative[:3, 3]
        yaw = np.degrees(np.arctan2(relative[1, 0], relative[0, 0]))
        return Pose(float(x), float(y), float(depth), float(yaw))

    def move_tool(self, tool_pose) -> None:
        """Put the TCP at ``tool_pose`` (what a finished ``moveL`` does) and update the keys."""
        self.flange = homogeneous_from_ur(tool_pose) @ np.linalg.inv(self.active_tcp)
        self.moves += 1
        pose = self.sensor_pose()
        self.max_depth_mm = max(self.max_depth_mm, pose.depth_mm)
        virtual = self.virtual
        index = int(virtual.switch.pressed_key_index(virtual.layout, pose.x_mm, pose.y_mm, pose.depth_mm))
        held = None if index < 0 else index
        if held != self._held:
            now = time.time()
            if self._held is not None:
                self._emit(self._held, 0, now)
            if held is not None:
                self._emit(held, 1, now)
                self.pressed_log.append(virtual.layout.keys[held].name)
            self._held = held

    def _emit(self, key_index: int, value: int, stamp: float) -> None:
        name = self.virtual.layout.keys[key_index].name
        code = LINUX_KEY_CODES[_LAYOUT_TO_EVDEV.get(name, f"KEY_{name}")]
        self.inject_key_event(code, value, stamp, delay_s=self.key_delay_s)

    def inject_key_event(
        self, code: int, value: int, stamp: float | None = None, delay_s: float = 0.0
    ) -> None:
        """Queue a key event (and its SYN report), delivered ``delay_s`` after now."""
        stamp = time.time() if stamp is None else stamp
        deliver_at = time.time() + delay_s
        with self._lock:
            self._events.append((deliver_at, _event(stamp, EV_KEY, code, value)))
            self._events.append((deliver_at, _event(stamp, EV_SYN, 0, 0)))

    def next_event(self) -> FakeInputEvent | None:
        """The next event due for delivery, if any."""
        with self._lock:
            now = time.time()
            for i, (deliver_at, event) in enumerate(self._events):
                if deliver_at <= now:
                    del self._events[i]
                    return event
        return None

    def render(self, flange: np.ndarray | None = None) -> np.ndarray:
        """The camera's BGR frame of the sensor at its true pose (flange at ``flange``, default: now)."""
        pose = self.sensor_pose(flange)
        frame = self.virtual.tap(pose.x_mm, pose.y_mm, pose.depth_mm, pose.yaw_deg).frame
        return cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)

    def jog_to_key_top(self, key: str, noise_mm: float = 0.0, rng: np.random.Generator | None = None) -> None:
        """Put the sensor's tip on the centre of ``key``'s top, as an operator jogging the arm would."""
        x, y = self.virtual.layout.centre_mm(key)
        if noise_mm:
            rng = rng or np.random.default_rng(0)
            x, y = x + rng.normal(0, noise_mm), y + rng.normal(0, noise_mm)
        self.place_sensor(Pose(x, y, self.virtual.clearance_mm, 0.0))

    def place_sensor(self, pose: Pose) -> None:
        """Put the sensor at ``pose`` in the true work frame (the operator jogging; no key events)."""
        self.flange = self.work_frame @ sensor_transform(pose) @ np.linalg.inv(self.sensor_mount)

    def check_connection(self) -> bool:
        """Drop the connection once ``drop_after_moves`` moves are done; returns whether it is up."""
        if self.drop_after_moves is not None and self.moves >= self.drop_after_moves:
            self.connected = False
        return self.connected


class FakeRTDEControl:
    """Stands in for ``rtde_control.RTDEControlInterface(hostname)``."""

    def __init__(self, world: SimulatedUR5, hostname: str) -> None:
        if not world.robot_reachable or hostname != world.config.host:
            raise RuntimeError(f"Could not connect to robot at {hostname}")  # what ur-rtde raises
        self.world = world

    def _record(self, name: str, *args) -> None:
        self.world.commands.append((name, args))

    def _lost(self, name: str):
        if self.world.drop_mode == "false" and name == "moveL":
            return False
        raise RuntimeError("RTDEControlInterface: Robot is disconnected")

    def isConnected(self) -> bool:
        return self.world.connected

    def moveL(self, pose, speed: float = 0.25, acceleration: float = 1.2, asynchronous: bool = False):
        self._record("moveL", list(pose), speed, acceleration, asynchronous)
        if not self.world.check_connection():
            return self._lost("moveL")
        self.world.move_tool(pose)
        return True

    def stopL(self, a: float = 10.0, asynchronous: bool = False) -> None:
        self._record("stopL", a, asynchronous)
        if not self.world.connected:
            self._lost("stopL")

    def setTcp(self, tcp_offset) -> bool:
        self._record("setTcp", list(tcp_offset))
        if not self.world.connected:
            return self._lost("setTcp")
        self.world.active_tcp = homogeneous_from_ur(tcp_offset)  # the flange stays put
        return True

    def getTCPOffset(self) -> list[float]:
        return ur_from_homogeneous(self.world.active_tcp)

    def isPoseWithinSafetyLimits(self, pose) -> bool:
        return True

    def reconnect(self) -> bool:
        self._record("reconnect")
        if self.world.reconnect_allowed:
            self.world.connected = True
            self.world.drop_after_moves = None
        return self.world.connected

    def stopScript(self) -> None:
        self._record("stopScript")

    def disconnect(self) -> None:
        self._record("disconnect")


class FakeRTDEReceive:
    """Stands in for ``rtde_receive.RTDEReceiveInterface(hostname)``."""

    def __init__(self, world: SimulatedUR5, hostname: str) -> None:
        if not world.robot_reachable or hostname != world.config.host:
            raise RuntimeError(f"Could not connect to robot at {hostname}")
        self.world = world

    def isConnected(self) -> bool:
        return self.world.connected

    def getActualTCPPose(self) -> list[float]:
        if not self.world.connected:
            raise RuntimeError("RTDEReceiveInterface: Robot is disconnected")
        return self.world.tool_pose()

    def reconnect(self) -> bool:
        if self.world.reconnect_allowed:
            self.world.connected = True
        return self.world.connected

    def disconnect(self) -> None:
        pass


class FakeVideoCapture:
    """Stands in for ``cv2.VideoCapture(index, cv2.CAP_V4L2)``, with a one-frame driver buffer."""

    def __init__(self, world: SimulatedUR5, index: int) -> None:
        self.world = world
        self._open = world.camera_present and index == world.config.camera_index
        self._buffered: np.ndarray | None = None  # the sensor's flange pose when the buffered frame was taken

    def isOpened(self) -> bool:
        return self._open

    def set(self, prop: int, value: float) -> bool:
        self.world.camera_settings[int(prop)] = float(value)
        return True

    def get(self, prop: int) -> float:
        return self.world.camera_settings.get(int(prop), 0.0)

    def read(self) -> tuple[bool, np.ndarray | None]:
        world = self.world
        if not self._open:
            return False, None
        if world.camera_failures > 0:
            world.camera_failures -= 1
            return False, None
        # The driver hands out the frame it buffered at the last read and buffers a new one.
        now = world.flange.copy()
        then, self._buffered = (now if self._buffered is None else self._buffered), now
        return True, world.render(then)

    def release(self) -> None:
        self._open = False


class FakeInputDevice:
    """Stands in for ``evdev.InputDevice(path)``."""

    def __init__(self, world: SimulatedUR5, path: str) -> None:
        if path not in world.keyboard_paths:
            raise FileNotFoundError(2, "No such file or directory", path)
        self.world = world
        self.path = path
        self.name = "Simulated DREVO Excalibur 84"
        self.grabbed = False
        self._closed = False

    def grab(self) -> None:
        self.grabbed = True

    def ungrab(self) -> None:
        self.grabbed = False

    def read_one(self) -> FakeInputEvent | None:
        if self._closed:
            raise OSError(9, "Bad file descriptor")
        return self.world.next_event()

    def read_loop(self):
        while not self._closed:
            event = self.read_one()
            if event is None:
                time.sleep(0.001)
                continue
            yield event

    def close(self) -> None:
        self._closed = True
