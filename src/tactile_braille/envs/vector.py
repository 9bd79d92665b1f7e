"""Batched braille environments, stepped with NumPy over the batch.

``gym.make_vec("tactile_braille/DiscreteArrows-v0", num_envs=64,
vectorization_mode="vector_entry_point")`` builds one. The rules are those of
the single environments (the same :class:`BatchedBraille` core). On the
``render`` backend each step renders every sub-environment's tap at once with
the batched renderer (:mod:`tactile_braille.sensor.batched`) on
``render_device`` (by default a GPU where there is one; on a CPU each tap is
rendered by the single-tap renderer, the faster there).

Autoreset mode: ``NEXT_STEP`` (Gymnasium's default). When a sub-environment
terminates or is truncated, the step returns its final observation; the
*next* call to ``step`` resets it (its action is ignored), returning the
first observation of the new episode with reward 0 and no termination.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from gymnasium.error import ResetNeeded
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from tactile_braille.datasets.store import TactileDataset
from tactile_braille.envs.backends import DatasetBackend, RigBackend
from tactile_braille.envs.core import BatchedBraille, compute_reward
from tactile_braille.envs.tasks import MAX_EPISODE_STEPS, Task
from tactile_braille.envs.world import check_world
from tactile_braille.rigs.virtual import VirtualRig

VECTOR_BACKENDS = ("dataset", "render")


class VectorBrailleEnv(VectorEnv):
    """``num_envs`` braille environments on the dataset or render backend (see the module docs).

    Args:
        num_envs: batch size.
        keys: ``"arrows"`` or ``"alphabet"``.
        dataset: the dataset or its path (default: the cached one; dataset backend).
        sensor: sensor preset (of the default dataset, or rendered).
        max_episode_steps: truncation (25, the registry's).
        backend: ``"dataset"`` or ``"render"`` (the live renderer).
        proprio: observations also carry ``sensor_pose`` (the ``proprio`` track's).
        render_device: the render backend's torch device for the batched
            renderer (``"cpu"``, ``"cuda"``), or None to render each tap with
            the single-tap reference renderer. ``"auto"`` (the default):
            ``"cuda"`` where a GPU is, else None (on a CPU the single-tap
            renderer is the faster, and it is exact).
        edges: the continuous tasks' workspace edge, ``"stop"`` or ``"overrun"``; tap_depth: the stored
            depth their taps read, ``"commanded"`` or ``"released"`` (the continuous environments' docs);
            key_grid: the discrete tasks' key grid, ``"rig"`` or ``"released"`` (the discrete ones').
    """

    metadata: ClassVar[dict[str, Any]] = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}
    continuous: ClassVar[bool] = False

    def __init__(
        self,
        num_envs: int = 1,
        keys: str = "arrows",
        dataset: TactileDataset | str | Path | None = None,
        sensor: str = "braille_331",
        max_episode_steps: int = MAX_EPISODE_STEPS,
        backend: str = "dataset",
        proprio: bool = False,
        render_device: str | None = "auto",
        frame_noise: tuple[float, float] | None = None,
        edges: str = "stop",
        tap_depth: str = "commanded",
        key_grid: str = "rig",
    ) -> None:
        if frame_noise is not None:
            raise ValueError(
                "frame_noise is not supported by the vectorised environment (one calibration error per "
                "episode of each sub-environment is not built): use gym.make, or "
                "gym.make_vec(..., vectorization_mode='sync')"
            )
        if backend not in VECTOR_BACKENDS:
            choices = " or ".join(VECTOR_BACKENDS)
            raise ValueError(f"the vectorised environment runs on the {choices} backend, not {backend!r}")
        if num_envs < 1:
            raise ValueError(f"num_envs must be at least 1, got {num_envs}")
        check_world(self.continuous, backend, edges=edges, tap_depth=tap_depth, key_grid=key_grid)
        self.num_envs = int(num_envs)
        self.task = Task(keys=keys, continuous=self.continuous, grid=key_grid)
        if backend == "dataset":
            if render_device != "auto":
                raise ValueError(
                    "render_device is for the render backend; the dataset backend renders nothing"
                )
            source = DatasetBackend(self.task, dataset, sensor=sensor)
        else:
            if dataset is not None:
                raise ValueError("the render backend renders its taps: it takes no dataset")
            if render_device == "auto":
                import torch

                render_device = "cuda" if torch.cuda.is_available() else None
            source = RigBackend(VirtualRig(sensor=sensor), device=render_device, name="render")
        self._core = BatchedBraille(
            self.task, source, num_envs, proprio=proprio, edges=edges, tap_depth=tap_depth
        )
        self.single_observation_space = self._core.observation_space()
        self.single_action_space = self._core.action_space()
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.max_episode_steps = int(max_episode_steps)
        self._steps = np.zeros(num_envs, dtype=np.int64)
        self._needs_reset = np.zeros(num_envs, dtype=bool)
        self._np_random, _ = seeding.np_random(None)
        self._started = False

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Reset every sub-environment (``seed`` seeds the whole batch)."""
        if seed is not None:
            self._np_random, _ = seeding.np_random(seed)
            self.action_space.seed(seed)
        everyone = np.ones(self.num_envs, dtype=bool)
        self._core.reset(everyone, self._np_random)
        self._steps[:] = 0
        self._needs_reset[:] = False
        self._started = True
        return self._core.observations(), self._infos()

    def step(self, actions):
        """Step every sub-environment; those that ended last step are reset instead."""
        if not self._started:
            raise ResetNeeded("cannot step the vector environment before its first reset()")
        actions = self._core.check_actions(actions)
        resetting = self._needs_reset
        active = ~resetting
        rewards = self._core.step(actions, active, self._np_random)
        self._core.reset(resetting, self._np_random)
        self._steps = np.where(resetting, 0, self._steps + 1)
        terminated = self._core.terminated & active
        truncated = (self._steps >= self.max_episode_steps) & active  # as TimeLimit: also when terminated
        self._needs_reset = terminated | truncated
        return self._core.observations(), rewards, terminated, truncated, self._infos()

    def compute_reward(self, achieved_goal, desired_goal, info) -> np.ndarray:
        """1.0 where the achieved key equals the desired one; batch-safe over the last axis."""
        return compute_reward(achieved_goal, desired_goal, info)

    def _infos(self) -> dict[str, np.ndarray]:
        core = self._core
        success = (core.achieved >= 0) & (core.achieved == core.goal)
        every = np.ones(self.num_envs, dtype=bool)
        return {"is_success": success, "_is_success": every, "goal": core.goal.copy(), "_goal": every}


class VectorDiscreteBrailleEnv(VectorBrailleEnv):
    """Batched discrete braille environments."""

    continuous: ClassVar[bool] = False


class VectorContinuousBrailleEnv(VectorBrailleEnv):
    """Batched continuous braille environments."""

    continuous: ClassVar[bool] = True
