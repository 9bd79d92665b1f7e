"""The real rig: a UR5 arm taps a TacTip on the braille keyboard; the keyboard reports the presses.

:class:`UR5Rig` implements the :class:`~tactile_braille.rigs.base.Rig`
protocol over three adapters (:mod:`tactile_braille.rigs.hardware`): the arm
(ur-rtde), the sensor's camera (OpenCV) and the keyboard (evdev). The same
collection procedures, datasets, environments and training loop run on it
as on the virtual rig.

A tap: every pose of the tap is checked by :class:`SafetyLimits` before the
first command is sent; the arm moves at the travel height to above the
target, goes straight down to the tap depth, the camera's frame is taken at
the bottom, the arm goes back up, and the key press whose time stamp falls
in the tap (down-bottom-up, plus ``key_grace_s``) is its label. On any
exception inside a tap or a move the arm retracts straight up to the safe
height (best effort) and a :class:`RigError` says what failed and whether
the retract worked. Each tap's wall time is kept in :attr:`UR5Rig.stats`,
logged, and appended to ``tap_log`` (CSV) when one is configured.

Install the libraries with ``pip install 'tactile_braille[robot]'``; see
``docs/hardware.md`` for the rig, its calibration and its first run.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tactile_braille.keyboard.layout import KeyboardLayout
from tactile_braille.rigs.base import Pose, RigError, TactileSample, Workspace
from tactile_braille.rigs.hardware import (
    LOG,
    Drivers,
    KeyListener,
    KeyPress,
    TacTipCamera,
    URArm,
    real_drivers,
)
from tactile_braille.rigs.safety import Motion, SafetyLimits
from tactile_braille.rigs.transforms import FramePose, base_to_work, tcp_offset_to_ur, work_to_base
from tactile_braille.sensor.config import sensor_preset

PAPER_TCP_OFFSET_MM_DEG: FramePose = (0.0, 0.0, 125.0, 0.0, 0.0, -145.0)
"""The paper's tool offset: the TacTip's tip 125 mm along the flange's z, turned -145 deg about it."""


TAP_LOG_COLUMNS = ("time", "x_mm", "y_mm", "depth_mm", "yaw_deg", "pressed_key", "wall_time_s")
"""Columns of the tap log (``UR5Config.tap_log``), one row per tap."""


class LateKeyEventError(RigError):
    """A key press arrived after its tap had been labelled: that sample's label may be wrong."""


@dataclass(frozen=True)
class UR5Config:
    """How the UR5 rig is built and where it may go. Lengths in mm, angles in degrees, times in s.

    Attributes:
        host: the robot controller's address.
        keyboard_device: the keyboard's evdev device (``/dev/input/by-id/...-event-kbd``).
        work_frame_mm_deg: the work frame in the robot's base frame,
            ``(x, y, z, roll, pitch, yaw)`` (see :mod:`~tactile_braille.rigs.transforms`);
            ``tactile-braille rig calibrate`` measures it. Its origin is
            ``clearance_mm`` above the Q key's top, its z axis points down.
        tcp_offset_mm_deg: the sensor's tip relative to the flange, as ``setTcp`` gets it.
        clearance_mm: height of the work-frame origin above the key tops.
        travel_height_mm: moves between taps run this far above the work-frame origin.
        safe_height_mm: the retract height above the work-frame origin (faults, start, close).
        speed_mm_s: linear speed of taps and moves (the paper: 100).
        approach_speed_mm_s: speed of the first approach and of retracts (the paper homed at 30).
        acceleration_mm_s2: linear acceleration.
        max_speed_mm_s, max_acceleration_mm_s2: caps every command is checked against.
        max_depth_mm: the deepest tap (the depth limit).
        x_range_mm, y_range_mm: workspace in the work frame (``None``: the keyboard's extent).
        yaw_range_deg: accepted sensor yaws.
        sensor: sensor preset, for the image processing's parameters.
        crop_px: the sensor's box in the camera frame (``None``: the preset's);
            ``tactile-braille rig crop`` proposes one.
        camera_index: V4L2 index of the TacTip's camera.
        camera_size_px: (width, height) of its frames.
        camera_exposure: fixed exposure in the driver's units (``None``: keep the camera's).
        camera_retries: reads retried when the camera returns no frame.
        key_debounce_s: repeated presses of a key within this time are one press
            (switch chatter); keep it well under the time between two taps.
        key_grace_s: after the arm is back up, how long a tap waits for a key event
            still on its way; a press arriving later stops the next tap with a
            :class:`LateKeyEventError`.
        dry_run: log and record the arm's commands instead of sending them.
        tap_log: a CSV file each tap is appended to (time, pose, key, wall time).
    """

    host: str
    keyboard_device: str
    work_frame_mm_deg: FramePose
    tcp_offset_mm_deg: FramePose = PAPER_TCP_OFFSET_MM_DEG
    clearance_mm: float = 3.5
    travel_height_mm: float = 3.0
    safe_height_mm: float = 30.0
    speed_mm_s: float = 100.0
    approach_speed_mm_s: float = 30.0
    acceleration_mm_s2: float = 500.0
    max_speed_mm_s: float = 150.0
    max_acceleration_mm_s2: float = 1000.0
    max_depth_mm: float = 9.0
    x_range_mm: tuple[float, float] | None = None
    y_range_mm: tuple[float, float] | None = None
    yaw_range_deg: tuple[float, float] = (-45.0, 45.0)
    sensor: str = "braille_331"
    crop_px: tuple[int, int, int, int] | None = None
    camera_index: int = 0
    camera_size_px: tuple[int, int] = (640, 480)
    camera_exposure: float | None = None
    camera_retries: int = 1
    key_debounce_s: float = 0.05
    key_grace_s: float = 0.05
    dry_run: bool = False
    tap_log: str | None = None

    def __post_init__(self) -> None:
        for name in ("work_frame_mm_deg", "tcp_offset_mm_deg"):
            value = tuple(float(v) for v in getattr(self, name))
            if len(value) != 6 or not np.isfinite(value).all():
                raise ValueError(f"{name} must be 6 finite numbers (x, y, z, roll, pitch, yaw), got {value}")
            object.__setattr__(self, name, value)
        for name in ("x_range_mm", "y_range_mm", "yaw_range_deg", "crop_px", "camera_size_px"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, tuple(value))
        if not 0 < self.travel_height_mm < self.safe_height_mm:
            raise ValueError("need 0 < travel_height_mm < safe_height_mm")
        if not 0 < self.max_depth_mm <= 15.0:
            raise ValueError(f"max_depth_mm must be in (0, 15], got {self.max_depth_mm!r}")
        for name in ("speed_mm_s", "approach_speed_mm_s"):
            if not 0 < getattr(self, name) <= self.max_speed_mm_s:
                raise ValueError(f"{name} must be in (0, max_speed_mm_s={self.max_speed_mm_s}]")
        if not 0 < self.acceleration_mm_s2 <= self.max_acceleration_mm_s2:
            raise ValueError(
                f"acceleration_mm_s2 must be in (0, max_acceleration_mm_s2={self.max_acceleration_mm_s2}]"
            )
        if self.camera_retries < 0 or self.key_grace_s < 0 or self.key_debounce_s < 0:
            raise ValueError("camera_retries, key_grace_s and key_debounce_s must not be negative")
        sensor_preset(self.sensor)  # validates the name

    def to_json(self) -> dict:
        """The configuration as JSON-able data (what :meth:`from_json` reads)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, data: dict) -> UR5Config:
        """A configuration from :meth:`to_json`'s data; unknown keys are an error."""
        known = {f.name for f in dataclasses.fields(cls)}
        if not isinstance(data, dict):
            raise ValueError(f"UR5 rig settings are a JSON object of settings, got {type(data).__name__}")
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"unknown UR5 rig settings {unknown}; known: {sorted(known)}")
        required = [f.name for f in dataclasses.fields(cls) if f.default is dataclasses.MISSING
                    and f.default_factory is dataclasses.MISSING]  # fmt: skip
        missing = [name for name in required if name not in data]
        if missing:
            raise ValueError(f"the UR5 rig settings lack {missing} (docs/hardware.md shows a full file)")
        return cls(**data)

    @classmethod
    def load(cls, path: str | Path) -> UR5Config:
        """Read a configuration file (JSON)."""
        if not Path(path).is_file():
            raise FileNotFoundError(f"no rig settings at {path}: write them as docs/hardware.md shows")
        try:
            data = json.loads(Path(path).read_text())
        except json.JSONDecodeError as error:
            raise ValueError(f"{path} is not a JSON rig configuration: {error}") from None
        return cls.from_json(data)

    def save(self, path: str | Path) -> Path:
        """Write the configuration as JSON."""
        from tactile_braille._io import atomic_path

        with atomic_path(path) as temporary:
            temporary.write_text(json.dumps(self.to_json(), indent=2) + "\n")
        return Path(path)


class UR5Rig:
    """The UR5 + TacTip + keyboard rig behind the :class:`~tactile_braille.rigs.base.Rig` protocol.

    Args:
        config: the rig's settings.
        drivers: the hardware libraries' constructors (default: the real
            libraries; :meth:`tactile_braille.rigs.fakes.SimulatedUR5.drivers`
            for a simulated rig).
        layout: the keyboard.

    Raises:
        RigError: a library is missing, or the robot, camera or keyboard cannot be reached.

    Example (against the simulated hardware; a real rig takes only the config):
        >>> from tactile_braille.rigs.fakes import SimulatedUR5, simulated_config
        >>> world = SimulatedUR5(simulated_config())
        >>> with UR5Rig(world.config, drivers=world.drivers()) as rig:
        ...     x, y = rig.layout.centre_mm("A")
        ...     sample = rig.tap(x, y, depth_mm=8.0)
        >>> sample.pressed_key, sample.frame.shape
        ('A', (480, 640))
    """

    def __init__(
        self, config: UR5Config, drivers: Drivers | None = None, layout: KeyboardLayout | None = None
    ) -> None:
        self.config = config
        self.layout = layout or KeyboardLayout()
        preset = sensor_preset(config.sensor)
        processing = preset.processing
        if config.crop_px is not None:
            processing = dataclasses.replace(processing, crop_px=config.crop_px)
        self.processing = processing
        self.clearance_mm = config.clearance_mm
        x_min, x_max, y_min, y_max = self.layout.bounds_mm
        self.workspace = Workspace(
            x_mm=config.x_range_mm or (x_min, x_max),
            y_mm=config.y_range_mm or (y_min, y_max),
            depth_mm=(0.0, config.max_depth_mm),
            yaw_deg=config.yaw_range_deg,
        )
        self.limits = SafetyLimits(
            self.workspace, config.safe_height_mm, config.max_speed_mm_s, config.max_acceleration_mm_s2
        )
        self.stats = {"taps": 0, "tap_time_s_total": 0.0, "last_tap_time_s": float("nan"), "retracts": 0,
                      "camera_retries": 0, "stray_key_presses": 0}  # fmt: skip
        self._pose: Pose | None = None  # last commanded pose; None until the first move
        self._last_window: tuple[float, float] | None = None  # the last tap's key window (time.time())
        self._closed = False
        drivers = drivers or real_drivers()
        self.keyboard = self.camera = self.arm = None
        try:  # the arm last: nothing moves before the camera and the keyboard work
            self.keyboard = KeyListener(drivers, config.keyboard_device, config.key_debounce_s)
            self.camera = TacTipCamera(
                drivers, config.camera_index, config.camera_size_px, config.camera_exposure
            )
            self.arm = URArm(drivers, config.host, tcp_offset_to_ur(config.tcp_offset_mm_deg), config.dry_run)
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------ protocol
    @property
    def pose(self) -> Pose:
        """The sensor's pose: the last commanded one, or the arm's actual pose before the first move."""
        if self._pose is not None:
            return self._pose
        return self.actual_pose()

    def actual_pose(self) -> Pose:
        """The sensor's pose in the work frame as the robot reports it."""
        self._check_open()
        return base_to_work(self.arm.tool_pose(), self.config.work_frame_mm_deg)

    def move_to(self, x_mm: float, y_mm: float, yaw_deg: float = 0.0) -> None:
        """Move at the travel height to above (x, y); raises :class:`OutOfWorkspaceError` before moving."""
        target = self.limits.check_tap(x_mm, y_mm, 0.0, yaw_deg)
        self._check_open()
        with self._retract_on_error(f"moving to ({target.x_mm:.2f}, {target.y_mm:.2f})"):
            self._travel_to(target.x_mm, target.y_mm, target.yaw_deg)

    def tap(self, x_mm: float, y_mm: float, depth_mm: float, yaw_deg: float = 0.0) -> TactileSample:
        """Tap at (x, y) down to ``depth_mm``: the frame at the bottom and the key that registered."""
        bottom = self.limits.check_tap(x_mm, y_mm, depth_mm, yaw_deg)
        self._check_open()
        started = time.perf_counter()
        context = f"tap at ({bottom.x_mm:.2f}, {bottom.y_mm:.2f}, depth {bottom.depth_mm:.2f})"
        with self._retract_on_error(context):
            self._check_late_presses()
            self._travel_to(bottom.x_mm, bottom.y_mm, bottom.yaw_deg)
            window_start = time.time()
            self._move(bottom, self.config.speed_mm_s)
            frame = self._grab_frame()
            self._move(self._above(bottom, self.config.travel_height_mm), self.config.speed_mm_s)
            pressed = self._pressed_key(window_start)
        elapsed = time.perf_counter() - started
        self._record_tap(bottom, pressed, elapsed)
        return TactileSample(frame=frame, pose=bottom, pressed_key=pressed)

    def reseed(self, seed: int | Sequence[int]) -> None:
        """A real rig's noise cannot be seeded: does nothing."""

    def describe(self) -> dict:
        """The rig's name, keyboard, sensor processing and settings (dataset metadata)."""
        config = self.config
        return {
            "rig": "ur5",
            "keyboard": {"pitch_mm": self.layout.pitch_mm, "clearance_mm": self.clearance_mm,
                         "work_frame_mm_deg": list(config.work_frame_mm_deg),
                         "tcp_offset_mm_deg": list(config.tcp_offset_mm_deg)},
            "sensor": {"preset": config.sensor, "processing": dataclasses.asdict(self.processing),
                       "camera_size_px": list(config.camera_size_px),
                       "camera_exposure": config.camera_exposure},
        }  # fmt: skip

    def close(self) -> None:
        """Retract to the safe height, then release the arm, the camera and the keyboard (idempotent)."""
        if self._closed:
            return
        if self.arm is not None and self._pose is not None:
            note = self._retract()
            LOG.info("closing the UR5 rig: %s", note)
        self._closed = True
        if self.keyboard is not None:
            try:
                for press in self.keyboard.take():
                    if self._belongs_to_last_tap(press):
                        LOG.warning("a press of %s arrived after the last tap was labelled", press.key)
            except RigError as error:
                LOG.warning("closing the UR5 rig: %s", error)
        for part in (self.arm, self.camera, self.keyboard):
            if part is not None:
                part.close()

    def __enter__(self) -> UR5Rig:
        return self

    def __deepcopy__(self, memo: dict) -> UR5Rig:
        """A rig is a handle on hardware: copies (Gymnasium copies an env's spec) share it."""
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    # ------------------------------------------------------------- motion
    def _check_open(self) -> None:
        if self._closed:
            raise RigError("the rig is closed")

    @staticmethod
    def _above(pose: Pose, height_mm: float) -> Pose:
        return Pose(pose.x_mm, pose.y_mm, -height_mm, pose.yaw_deg)

    def _move(self, pose: Pose, speed_mm_s: float) -> None:
        """The only way a motion reaches the arm: through the safety check."""
        motion: Motion = self.limits.check(pose, speed_mm_s, self.config.acceleration_mm_s2)
        tool_pose = work_to_base(motion.pose, self.config.work_frame_mm_deg)
        self._pose = motion.pose  # the arm may have moved part way even if the command fails
        self.arm.move_linear(tool_pose, motion.speed_mm_s / 1000.0, motion.acceleration_mm_s2 / 1000.0)

    def _travel_to(self, x_mm: float, y_mm: float, yaw_deg: float) -> None:
        """Reach the travel height above (x, y): up first if lower, then across."""
        travel, safe = self.config.travel_height_mm, self.config.safe_height_mm
        if self._pose is None:  # the first move: from where the arm is, straight to the safe height
            start = self.actual_pose()
            if not (self.workspace.x_mm[0] <= start.x_mm <= self.workspace.x_mm[1]
                    and self.workspace.y_mm[0] <= start.y_mm <= self.workspace.y_mm[1]
                    and start.depth_mm <= 0.0):  # fmt: skip
                raise RigError(
                    f"the arm starts at {start} (work frame), not above the keyboard's workspace: jog it "
                    "above the keys first (or check work_frame_mm_deg)"
                )
            yaw = float(np.clip(start.yaw_deg, *self.workspace.yaw_deg))
            self._move(Pose(start.x_mm, start.y_mm, -safe, yaw), self.config.approach_speed_mm_s)
            self._move(Pose(x_mm, y_mm, -safe, yaw_deg), self.config.approach_speed_mm_s)
        current = self._pose
        if current.depth_mm > -travel:
            self._move(self._above(current, travel), self.config.speed_mm_s)
            current = self._pose
        target = Pose(x_mm, y_mm, -travel, yaw_deg)
        if current != target:
            self._move(target, self.config.speed_mm_s)

    def _retract(self) -> str:
        """Stop and go straight up to the safe height (best effort); says how it went."""
        self.stats["retracts"] += 1
        if self.arm is None or self._pose is None:
            return "the arm had not moved"
        if not self.config.dry_run and not self.arm.reconnect():
            LOG.warning("retract: the robot did not reconnect")
        try:
            self.arm.stop()
        except Exception as error:
            LOG.warning("retract: stopL failed: %s", error)
        target = self._above(self._pose, self.config.safe_height_mm)
        try:
            self._move(target, self.config.approach_speed_mm_s)
        except Exception as error:
            return f"retracting to the safe height failed too ({error}): check the arm before going on"
        return f"the arm retracted to the safe height ({self.config.safe_height_mm} mm above the work frame)"

    @contextmanager
    def _retract_on_error(self, context: str) -> Iterator[None]:
        try:
            yield
        except BaseException as error:
            note = self._retract()
            if not isinstance(error, Exception):  # Ctrl-C: retracted, then stop as asked
                raise
            kind = type(error) if isinstance(error, RigError) else RigError
            raise kind(f"{context} failed: {error}; {note}") from error

    # ------------------------------------------------------------- sensing
    def _grab_frame(self) -> np.ndarray:
        tries = 1 + self.config.camera_retries
        for attempt in range(tries):
            frame = self.camera.read()
            if frame is not None:
                return frame
            if attempt + 1 < tries:
                self.stats["camera_retries"] += 1
                LOG.warning("the camera returned no frame; retrying")
        raise RigError(
            f"the camera returned no frame ({tries} tries): check the TacTip's USB cable and that no "
            f"other program reads /dev/video{self.config.camera_index}"
        )

    def _belongs_to_last_tap(self, press: KeyPress) -> bool:
        window = self._last_window
        return window is not None and window[0] <= press.timestamp <= window[1]

    def _check_late_presses(self) -> None:
        """Before a tap: a press stamped inside the last tap's window came too late to label it."""
        for press in self.keyboard.take(caught_up_to=time.time()):
            if self._belongs_to_last_tap(press):
                raise LateKeyEventError(
                    f"a press of {press.key} arrived after the previous tap had been labelled "
                    f"(key_grace_s={self.config.key_grace_s}): that sample may be mislabelled; "
                    "raise key_grace_s"
                )
            self.stats["stray_key_presses"] += 1
            LOG.warning("ignoring a press of %s outside any tap (someone at the keyboard?)", press.key)

    def _pressed_key(self, window_start: float) -> str | None:
        """The first key pressed since ``window_start``, waiting up to ``key_grace_s`` for late events."""
        back_up = time.time()
        deadline = back_up + self.config.key_grace_s
        presses = self.keyboard.take(caught_up_to=back_up)  # all events delivered by the time the arm is up
        while True:
            inside = [p for p in presses if p.timestamp >= window_start]
            if inside or time.time() >= deadline:
                break
            time.sleep(0.002)
            presses += self.keyboard.take()
        self._last_window = (window_start, time.time())
        for press in presses:
            if press.timestamp < window_start:
                self.stats["stray_key_presses"] += 1
                LOG.warning("ignoring a press of %s before the tap began", press.key)
        if len({p.key for p in inside}) > 1:
            LOG.warning("one tap registered several keys %s; keeping the first", [p.key for p in inside])
        return inside[0].key if inside else None

    def _record_tap(self, pose: Pose, pressed: str | None, elapsed_s: float) -> None:
        stats = self.stats
        stats["taps"] += 1
        stats["tap_time_s_total"] += elapsed_s
        stats["last_tap_time_s"] = elapsed_s
        LOG.debug("tap %d at %s pressed %s in %.3f s", stats["taps"], pose, pressed, elapsed_s)
        if self.config.tap_log:
            path = Path(self.config.tap_log)
            new = not path.exists()
            path.parent.mkdir(parents=True, exist_ok=True)
            with open(path, "a", newline="") as handle:
                writer = csv.writer(handle)
                if new:
                    writer.writerow(TAP_LOG_COLUMNS)
                writer.writerow([f"{time.time():.3f}", *(f"{v:.3f}" for v in pose.as_array()), pressed or "",
                                 f"{elapsed_s:.4f}"])  # fmt: skip

    @property
    def mean_tap_time_s(self) -> float:
        """Mean wall time of a tap so far (NaN before the first)."""
        taps = self.stats["taps"]
        return self.stats["tap_time_s_total"] / taps if taps else float("nan")
