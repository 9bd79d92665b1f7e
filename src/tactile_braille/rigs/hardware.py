"""Thin adapters over the three hardware libraries of the UR5 rig: ur-rtde, OpenCV and evdev.

Each adapter gets the library's objects from a :class:`Drivers` bundle of
constructors. :func:`real_drivers` imports the libraries only when an object
is made, and turns a missing package or device into a
:class:`~tactile_braille.rigs.base.RigError` that says what to install or
plug in; :func:`tactile_braille.rigs.fakes.SimulatedUR5.drivers` gives
stand-ins with the same methods, driven by the virtual rig, so that
everything above the libraries' API runs in tests.

* :class:`URArm`: ``rtde_control.RTDEControlInterface`` (``moveL``,
  ``stopL``, ``setTcp``...) and ``rtde_receive.RTDEReceiveInterface``
  (``getActualTCPPose``). Poses are the controller's: metres and rotation
  vectors. With ``dry_run`` no control interface is opened (none takes over
  the robot): commands are logged and recorded instead of sent.
* :class:`TacTipCamera`: ``cv2.VideoCapture`` (OpenCV is a core dependency) on V4L2 at a fixed size and
  exposure; a frame is the second of two reads (the driver's buffer holds a
  stale one).
* :class:`KeyListener`: ``evdev.InputDevice``, grabbed exclusively (key
  presses reach no other program), read by a background thread into
  time-stamped, debounced :class:`KeyPress` records.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from tactile_braille.rigs.base import RigError

LOG = logging.getLogger("tactile_braille.rigs")

INSTALL_HINT = "pip install 'tactile_braille[robot]'"
KEY_ALIASES = {"DELETE": "DEL", "SYSRQ": "PRTSC", "PRINT": "PRTSC"}
"""evdev key names that the keyboard layout spells differently."""


@dataclass(frozen=True)
class Drivers:
    """Constructors of the hardware libraries' objects.

    Attributes:
        rtde_control: ``host -> RTDEControlInterface``.
        rtde_receive: ``host -> RTDEReceiveInterface``.
        video_capture: ``index -> cv2.VideoCapture`` (opened on V4L2).
        input_device: ``path -> evdev.InputDevice``.
        ecodes: ``() -> evdev.ecodes`` (``EV_KEY`` and the ``KEY`` code-to-name table).
    """

    rtde_control: Callable[[str], Any]
    rtde_receive: Callable[[str], Any]
    video_capture: Callable[[int], Any]
    input_device: Callable[[str], Any]
    ecodes: Callable[[], Any]


def _import(module: str, package: str):
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as error:
        raise RigError(f"the UR5 rig needs the package {package} ({error}): {INSTALL_HINT}") from None


def real_drivers() -> Drivers:
    """The real libraries' constructors; each imports its library when first called."""

    def rtde_control(host: str):
        return _import("rtde_control", "ur-rtde").RTDEControlInterface(host)

    def rtde_receive(host: str):
        return _import("rtde_receive", "ur-rtde").RTDEReceiveInterface(host)

    def video_capture(index: int):
        return cv2.VideoCapture(index, cv2.CAP_V4L2)

    def input_device(path: str):
        return _import("evdev", "evdev").InputDevice(path)

    def ecodes():
        return _import("evdev", "evdev").ecodes

    return Drivers(rtde_control, rtde_receive, video_capture, input_device, ecodes)


# --------------------------------------------------------------------------- arm
class URArm:
    """A UR arm over RTDE: linear moves of the tool centre point, in the base frame.

    Args:
        drivers: where the RTDE interfaces come from.
        host: the robot's address.
        tcp_offset: the tool centre point as ``setTcp`` takes it (m, rotation vector).
        dry_run: log and record the commands instead of sending them.

    Raises:
        RigError: ur-rtde is missing, or the robot cannot be reached.
    """

    def __init__(
        self, drivers: Drivers, host: str, tcp_offset: Sequence[float], dry_run: bool = False
    ) -> None:
        self.host = host
        self.dry_run = dry_run
        self.sent: list[tuple[str, tuple]] = []  # what was sent (or, dry, would have been)
        self._control = None
        try:
            self._receive = drivers.rtde_receive(host)
            if not dry_run:
                self._control = drivers.rtde_control(host)
        except RigError:
            raise
        except Exception as error:  # ur-rtde raises RuntimeError for every connection fault
            self.close()
            raise RigError(
                f"cannot connect to the UR robot at {host!r} ({error}): check that it is on, "
                "reachable on the network, in remote control mode, and that no other program holds RTDE"
            ) from error
        self._command("setTcp", [float(v) for v in tcp_offset])

    def _command(self, name: str, *args) -> None:
        """Send (or, dry, log) one control command; raise :class:`RigError` if it fails."""
        self.sent.append((name, args))
        if self.dry_run:
            LOG.info("dry run: %s%s", name, args)
            return
        if self._control is None:
            raise RigError("the arm is closed")
        if not self._control.isConnected():
            raise RigError(f"lost the connection to the robot at {self.host!r} before {name}")
        result = getattr(self._control, name)(*args)
        if result is False:  # moveL and setTcp return False when the controller refuses
            raise RigError(
                f"the robot refused {name}{args} (protective stop, emergency stop or lost connection?)"
            )

    def move_linear(self, pose: Sequence[float], speed_m_s: float, acceleration_m_s2: float) -> None:
        """``moveL`` to a tool pose (m, rotation vector); blocks until the move ends."""
        values = [float(v) for v in pose]
        if len(values) != 6 or not all(math.isfinite(v) for v in values):
            raise RigError(f"refusing to send a malformed pose {pose!r}")  # never reached past the guard
        self._command("moveL", values, float(speed_m_s), float(acceleration_m_s2))

    def stop(self, deceleration_m_s2: float = 2.0) -> None:
        """Decelerate any linear move to a stop."""
        self._command("stopL", float(deceleration_m_s2))

    def tool_pose(self) -> list[float]:
        """The tool's actual pose (m, rotation vector) as the robot reports it."""
        if not self._receive.isConnected():
            raise RigError(f"lost the connection to the robot at {self.host!r} (receive interface)")
        return [float(v) for v in self._receive.getActualTCPPose()]

    def reconnect(self) -> bool:
        """Try once to reconnect both interfaces; returns whether both are connected."""
        connected = True
        for interface in (self._control, self._receive):
            if interface is None:
                continue
            try:
                if not interface.isConnected():
                    interface.reconnect()
                connected = connected and bool(interface.isConnected())
            except Exception:  # best effort: the caller reports
                connected = False
        return connected

    def close(self) -> None:
        """Stop the control script and disconnect (idempotent, best effort)."""
        control, receive = self._control, getattr(self, "_receive", None)
        self._control = self._receive = None
        if control is not None:
            for name in ("stopScript", "disconnect"):
                try:
                    getattr(control, name)()
                except Exception as error:
                    LOG.warning("closing the arm: %s failed: %s", name, error)
        if receive is not None:
            try:
                receive.disconnect()
            except Exception as error:
                LOG.warning("closing the arm: disconnect failed: %s", error)


# ------------------------------------------------------------------------ camera
class TacTipCamera:
    """The TacTip's camera through OpenCV, at a fixed size and exposure.

    Args:
        drivers: where ``cv2.VideoCapture`` comes from.
        index: the camera's V4L2 index (``/dev/video<index>``).
        size_px: (width, height) of its frames.
        exposure: fixed exposure in the driver's units (``None``: leave the
            camera's setting); auto exposure is switched off either way.

    Raises:
        RigError: no camera could be opened at ``index``.
    """

    def __init__(
        self, drivers: Drivers, index: int, size_px: tuple[int, int], exposure: float | None
    ) -> None:
        self.index = index
        self.size_px = tuple(size_px)
        self._capture = drivers.video_capture(index)
        if self._capture is None or not self._capture.isOpened():
            raise RigError(
                f"no camera at /dev/video{index}: check the TacTip's USB cable, its index "
                "(v4l2-ctl --list-devices) and that no other program has it open"
            )
        width, height = self.size_px
        self._capture.set(cv2.CAP_PROP_FRAME_WIDTH, width)
        self._capture.set(cv2.CAP_PROP_FRAME_HEIGHT, height)
        self._capture.set(cv2.CAP_PROP_AUTO_EXPOSURE, 1)  # V4L2: 1 = manual exposure
        if exposure is not None:
            self._capture.set(cv2.CAP_PROP_EXPOSURE, float(exposure))

    def read(self) -> np.ndarray | None:
        """A grey frame (uint8, height x width): the second of two reads; ``None`` if the camera gave none."""
        if self._capture is None:
            raise RigError("the camera is closed")
        self._capture.read()  # the frame the driver buffered before the tap's bottom
        ok, frame = self._capture.read()
        if not ok or frame is None:
            return None
        frame = np.asarray(frame)
        if frame.ndim == 3:
            frame = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        width, height = self.size_px
        if frame.shape != (height, width) or frame.dtype != np.uint8:
            raise RigError(
                f"the camera gives {frame.dtype} frames of shape {frame.shape}, not {height}x{width} uint8: "
                "set camera_size_px to a mode it supports (v4l2-ctl --list-formats-ext)"
            )
        return frame

    def close(self) -> None:
        """Release the camera (idempotent)."""
        capture, self._capture = self._capture, None
        if capture is not None:
            capture.release()


# ---------------------------------------------------------------------- keyboard
@dataclass(frozen=True)
class KeyPress:
    """A key that went down: its layout name and the kernel's time stamp (``time.time()`` clock)."""

    key: str
    timestamp: float


class KeyListener:
    """Key-down events of one keyboard, grabbed exclusively and read in a background thread.

    Args:
        drivers: where ``evdev.InputDevice`` and ``evdev.ecodes`` come from.
        path: the keyboard's event device (``/dev/input/by-id/...-event-kbd``).
        debounce_s: a second press of the same key within this time of the
            last is switch chatter and is dropped.
        poll_s: how often the thread polls the device (events keep the kernel's time stamps).

    Raises:
        RigError: evdev is missing, or there is no readable keyboard at ``path``.
    """

    def __init__(self, drivers: Drivers, path: str, debounce_s: float = 0.05, poll_s: float = 0.002) -> None:
        self.path = path
        self.debounce_s = float(debounce_s)
        self._poll_s = float(poll_s)
        self._ecodes = drivers.ecodes()
        try:
            self._device = drivers.input_device(path)
        except FileNotFoundError:
            raise RigError(
                f"no keyboard at {path!r}: list the keyboards with ls /dev/input/by-id/*-event-kbd"
            ) from None
        except PermissionError:
            raise RigError(
                f"no permission to read {path!r}: add your user to the 'input' group (then log in again)"
            ) from None
        except OSError as error:
            raise RigError(f"cannot open the keyboard at {path!r}: {error}") from error
        try:
            self._device.grab()  # exclusive: the presses type nothing anywhere else
        except OSError as error:
            self._device.close()
            raise RigError(
                f"cannot grab the keyboard at {path!r} ({error}): another program holds it"
            ) from error
        self._lock = threading.Lock()
        self._presses: list[KeyPress] = []
        self._last_down: dict[str, float] = {}
        self.error: RigError | None = None
        self.caught_up_at = -math.inf  # every event delivered before this time has been read
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"keyboard {path}", daemon=True)
        self._thread.start()

    def key_name(self, code: int) -> str | None:
        """The layout name of an evdev key code (``None`` for codes evdev does not name)."""
        names = self._ecodes.KEY.get(code)
        if names is None:
            return None
        for name in [names] if isinstance(names, str) else list(names):
            if name.startswith("KEY_"):
                bare = name[len("KEY_") :]
                return KEY_ALIASES.get(bare, bare)
        return None

    def _run(self) -> None:
        key_type = self._ecodes.EV_KEY
        while not self._stop.is_set():
            before = time.time()
            try:
                event = self._device.read_one()
            except (OSError, ValueError) as error:  # unplugged, or closed under us
                if not self._stop.is_set():
                    self.error = RigError(f"the keyboard at {self.path!r} stopped responding: {error}")
                return
            if event is None:
                self.caught_up_at = before
                time.sleep(self._poll_s)
                continue
            if event.type != key_type or event.value != 1:  # key down only: not up (0) or auto-repeat (2)
                continue
            name = self.key_name(event.code)
            if name is None:
                LOG.warning("ignoring key code %s, which evdev does not name", event.code)
                continue
            stamp = float(event.timestamp())
            with self._lock:
                if stamp - self._last_down.get(name, -math.inf) < self.debounce_s:
                    continue
                self._last_down[name] = stamp
                self._presses.append(KeyPress(name, stamp))

    def take(self, caught_up_to: float | None = None, timeout_s: float = 1.0) -> list[KeyPress]:
        """The presses read since the last call, oldest first (and forget them).

        With ``caught_up_to`` (a ``time.time()``), first wait until the reader
        has read every event the device had delivered by then.
        """
        if caught_up_to is not None:
            deadline = time.time() + timeout_s
            while self.caught_up_at < caught_up_to and self.error is None:
                if time.time() > deadline:
                    raise RigError(f"the keyboard reader of {self.path!r} stopped reading")
                time.sleep(self._poll_s / 2)
        if self.error is not None:
            raise self.error
        with self._lock:
            presses, self._presses = self._presses, []
        return presses

    def close(self) -> None:
        """Stop the thread, release the grab and close the device (idempotent)."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join(timeout=1.0)
        for name in ("ungrab", "close"):
            try:
                getattr(self._device, name)()
            except OSError as error:
                LOG.warning("closing the keyboard: %s failed: %s", name, error)
