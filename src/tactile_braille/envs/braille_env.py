"""What the four braille environments share: backends, goals, observations, rendering."""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium.error import ResetNeeded

from tactile_braille.datasets.store import TactileDataset
from tactile_braille.envs.backends import DatasetBackend, RigBackend
from tactile_braille.envs.core import BatchedBraille, compute_reward
from tactile_braille.envs.rendering import top_view
from tactile_braille.envs.tasks import Task
from tactile_braille.envs.world import check_world
from tactile_braille.rigs.base import Rig
from tactile_braille.sensor.config import sensor_preset


def make_backend(
    task: Task,
    backend: str,
    dataset: TactileDataset | str | Path | None,
    rig: Rig | None,
    sensor: str,
    frame_noise: tuple[float, float] | None = None,
):
    """Build the backend called ``backend`` for ``task`` (``frame_noise``: see :class:`BrailleEnv`), one of
    :data:`~tactile_braille.envs.world.BACKENDS` (both as :func:`~tactile_braille.envs.world.check_world`
    accepts them)."""
    if backend == "dataset":
        return DatasetBackend(task, dataset, sensor=sensor)
    if backend == "render":
        from tactile_braille.rigs.virtual import VirtualRig

        rig = (
            VirtualRig(sensor=sensor) if frame_noise is None else _random_frame_rig(task, sensor, frame_noise)
        )
        return RigBackend(rig, name="render")
    if rig is None:  # backend == "rig"
        raise ValueError("backend='rig' needs a rig (rig=...)")
    return RigBackend(rig)


def _random_frame_rig(task: Task, sensor: str, frame_noise: tuple[float, float]):
    """A virtual rig behind a work-frame error redrawn every episode, with room for its taps to land."""
    from tactile_braille.rigs.miscalibrated import RandomFrameRig, room_needed_mm, with_room
    from tactile_braille.rigs.virtual import VirtualRig

    offset, rotation = frame_noise
    inner = VirtualRig(sensor=sensor)
    room = room_needed_mm(inner.workspace, task.frame_origin_mm, offset, rotation)
    inner, calibrated = with_room(inner, room)
    return RandomFrameRig(inner, offset, rotation, task.frame_origin_mm, workspace=calibrated)


class BrailleEnv(gym.Env):
    """Base of the braille-typing environments (see the subclasses for the docs)."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array", "human"], "render_fps": 4}
    continuous: ClassVar[bool] = False

    def __init__(
        self,
        keys: str = "arrows",
        backend: str = "dataset",
        dataset: TactileDataset | str | Path | None = None,
        rig: Rig | None = None,
        sensor: str = "braille_331",
        render_mode: str | None = None,
        proprio: bool = False,
        frame_noise: tuple[float, float] | None = None,
        edges: str = "stop",
        tap_depth: str = "commanded",
        key_grid: str = "rig",
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}"
            )
        check_world(self.continuous, backend, edges=edges, tap_depth=tap_depth, key_grid=key_grid,
                    frame_noise=frame_noise)  # fmt: skip
        self.task = Task(keys=keys, continuous=self.continuous, grid=key_grid)
        self._dome_radius_mm = sensor_preset(sensor).dome_diameter_mm / 2
        self._core = BatchedBraille(
            self.task,
            make_backend(self.task, backend, dataset, rig, sensor, frame_noise),
            1,
            proprio=proprio,
            edges=edges,
            tap_depth=tap_depth,
        )
        self.observation_space = self._core.observation_space()
        self.action_space = self._core.action_space()
        self.render_mode = render_mode
        self._path_mm: list[tuple[float, float]] = []
        self._all = np.ones(1, dtype=bool)
        self._figure = None
        self._terminated = False

    @property
    def layout(self):
        """The keyboard (:class:`~tactile_braille.keyboard.layout.KeyboardLayout`) in the sensor's frame."""
        return self._core.layout

    @property
    def world(self) -> dict:
        """Where the observations come from: backend, dataset or rig, and their parameters (JSON-ready),
        and the released simulator's rules where they apply (``edges``, ``tap_depth``, ``key_grid``)."""
        return {**self._core.backend.describe(), **self._core.rules()}

    @property
    def dataset(self):
        """The :class:`~tactile_braille.datasets.store.TactileDataset` the observations come from (the
        ``dataset`` backend's), or None on the others."""
        return getattr(self._core.backend, "dataset", None)

    @property
    def goal_keys(self) -> tuple[str, ...]:
        """The task's keys, in the order of the goal one-hots."""
        return self._core.goal_keys

    def sensor_placement(self) -> dict:
        """Where the sensor is: what a reset with ``keep_pose`` keeps (the grid cell on a discrete task,
        the commanded work-frame position on a continuous one). :meth:`place_sensor` puts it back."""
        core = self._core
        return {"cell": core.cell[0].tolist(), "position_mm": core.position_mm[0].tolist()}

    def place_sensor(self, placement: dict) -> None:
        """Put the sensor where :meth:`sensor_placement` found it, for the next ``keep_pose`` reset (no
        tap is made here): how a resumed training run restores the pose an episode kept."""
        self._core.cell[0] = placement["cell"]
        self._core.position_mm[0] = placement["position_mm"]
        pose = self._core.sensor_pose_mm()[0]
        self._path_mm = [(pose[0], pose[1])]  # a pose to keep, as after an episode

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an episode: a random goal key and a random start pose.

        ``options={"goal_key": "Q"}`` fixes the goal instead;
        ``options={"keep_pose": True}`` keeps the sensor where the last episode
        left it (typing a sequence of keys without a reset between them: the
        sensor taps again where it is, and the previous action starts at zero).
        """
        options = dict(options or {})
        goal = options.pop("goal_key", None)
        keep_pose = options.pop("keep_pose", False)
        if options:
            raise ValueError(f"unknown reset options {sorted(options)}; known: goal_key, keep_pose")
        if not isinstance(keep_pose, bool | np.bool_):
            raise TypeError(f"reset option keep_pose must be True or False, got {keep_pose!r}")
        if goal is not None and goal not in self.goal_keys:
            raise ValueError(f"goal_key {goal!r} is not one of {self.goal_keys}")
        if keep_pose and not self._path_mm:
            raise ValueError("keep_pose needs an earlier reset: there is no pose to keep")
        super().reset(seed=seed)
        redraw = getattr(getattr(self._core.backend, "rig", None), "redraw", None)
        if redraw is not None and not keep_pose:  # frame_noise: a new calibration error (not mid-sentence)
            redraw(self.np_random)
        self._core.reset(self._all, self.np_random, keep_pose=keep_pose)
        if goal is not None:
            self._core.goal[0] = self.goal_keys.index(goal)
        pose = self._core.sensor_pose_mm()[0]
        self._path_mm = [(pose[0], pose[1])]
        self._terminated = False
        return self._observation(), self._info(pose)

    def step(self, action):
        if self._terminated:
            raise ResetNeeded("the episode has terminated (a key was pressed): call reset() before step()")
        action = np.asarray(action)
        if action.shape != self.action_space.shape:
            raise ValueError(f"expected an action of shape {self.action_space.shape}, got {action.shape}")
        actions = self._core.check_actions(action[None])
        reward = float(self._core.step(actions, self._all, self.np_random)[0])
        pose = self._core.sensor_pose_mm()[0]
        self._path_mm.append((pose[0], pose[1]))
        terminated = self._terminated = bool(self._core.pressed_code[0] >= 0)
        if self.render_mode == "human":
            self.render()
        return self._observation(), reward, terminated, False, self._info(pose)

    def compute_reward(self, achieved_goal, desired_goal, info) -> np.ndarray:
        """1.0 where the achieved key equals the desired one; batch-safe over the last axis."""
        return compute_reward(achieved_goal, desired_goal, info)

    def _observation(self) -> dict[str, np.ndarray]:
        return {name: values[0] for name, values in self._core.observations().items()}

    def _info(self, pose: np.ndarray) -> dict[str, Any]:
        core = self._core
        achieved, goal = int(core.achieved[0]), int(core.goal[0])
        return {
            "is_success": achieved >= 0 and achieved == goal,
            "pressed_key": core.pressed_key(0),
            "sensor_pose_mm": pose,
            "goal_key": self.goal_keys[goal],
        }

    # ----------------------------------------------------------- render
    def _view_mm(self) -> tuple[float, float, float, float]:
        core = self._core
        if self.task.continuous:
            (x0, x1), (y0, y1) = self.task.workspace_mm
            ox, oy = self.task.frame_origin_mm
            corners = np.array([[x0 + ox, y0 + oy], [x1 + ox, y1 + oy]])
        else:
            corners = core.cell_positions_mm.reshape(-1, 2)
        margin = 22.0
        return (
            corners[:, 0].min() - margin,
            corners[:, 0].max() + margin,
            corners[:, 1].min() - margin,
            corners[:, 1].max() + margin,
        )

    def render(self):
        """An RGB top view (``rgb_array``), or the same shown in a window (``human``)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None
        core = self._core
        frame = top_view(
            core.layout,
            self._view_mm(),
            self.goal_keys[int(core.goal[0])],
            self._path_mm,
            self._dome_radius_mm,
            core.pressed_key(0),
            core.images[0],
        )
        if self.render_mode == "rgb_array":
            return frame
        import matplotlib.pyplot as plt

        if self._figure is None:
            self._figure = plt.figure("tactile_braille")
        self._figure.clf()
        self._figure.gca().imshow(frame)
        self._figure.gca().axis("off")
        plt.pause(1 / self.metadata["render_fps"])
        return None

    def close(self) -> None:
        if self._figure is not None:
            import matplotlib.pyplot as plt

            plt.close(self._figure)
            self._figure = None
