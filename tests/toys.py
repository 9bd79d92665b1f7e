"""Small goal-conditioned toys with the braille tasks' interface, to check that agents learn.

Both speak the braille environments' language: Dict observations with a
100x100x1 uint8 ``observation``, ``desired_goal``, ``achieved_goal`` (what the
final press achieved, zeros before) and ``previous_action``; any press ends
the episode; reward 1 when the press achieves the goal. So the paper's HER
rule, the replay buffer and the networks run unchanged on them.

* ``toys/BitFlipPress-v0``: flip one of ``n`` bits per step or PRESS to
  submit the bits (Andrychowicz et al.'s bit flipping, with a submit action
  so that the achieved goal exists only at the end, as on the keyboard).
  Random pressing succeeds once in ``2**n`` episodes: without HER nothing is
  learned, with it the task is solved.
* ``toys/ContinuousTap-v0``: a sensor over one of 4 cells on a line (the
  image shows which); one action ``dx`` in [-1, 1] taps at ``x + 2 dx`` and
  presses the cell there, ending the episode: the agent must read its
  position from the image to hit the goal cell (random: 1 in 4).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces

IMAGE = (100, 100, 1)


def _dict_space(goal_size: int, previous_size: int, previous_low: float) -> spaces.Dict:
    return spaces.Dict(
        {
            "observation": spaces.Box(0, 255, IMAGE, np.uint8),
            "desired_goal": spaces.Box(0.0, 1.0, (goal_size,), np.float32),
            "achieved_goal": spaces.Box(0.0, 1.0, (goal_size,), np.float32),
            "previous_action": spaces.Box(previous_low, 1.0, (previous_size,), np.float32),
        }
    )


class BitFlipPress(gym.Env):
    """Flip bits until they match the goal, then press."""

    def __init__(self, bits: int = 6, max_steps: int | None = None) -> None:
        self.bits = bits
        self.max_steps = max_steps or 2 * bits
        self.action_space = spaces.Discrete(bits + 1)  # flip 0..n-1, PRESS = n
        self.observation_space = _dict_space(bits, bits + 1, 0.0)
        self.width = IMAGE[1] // bits

    def _observation(self, achieved: np.ndarray) -> dict:
        image = np.zeros(IMAGE, np.uint8)
        for i in np.flatnonzero(self.state):
            image[:, i * self.width : (i + 1) * self.width] = 255
        return {
            "observation": image,
            "desired_goal": self.goal.copy(),
            "achieved_goal": achieved,
            "previous_action": self.previous.copy(),
        }

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.state = self.np_random.integers(0, 2, self.bits).astype(np.float32)
        self.goal = self.np_random.integers(0, 2, self.bits).astype(np.float32)
        while not self.goal.any():
            self.goal = self.np_random.integers(0, 2, self.bits).astype(np.float32)
        self.previous = np.zeros(self.bits + 1, np.float32)
        self.steps = 0
        return self._observation(np.zeros(self.bits, np.float32)), {}

    def step(self, action):
        action = int(action)
        self.steps += 1
        self.previous = np.eye(self.bits + 1, dtype=np.float32)[action]
        pressed = action == self.bits
        if not pressed:
            self.state[action] = 1.0 - self.state[action]
        achieved = self.state.copy() if pressed else np.zeros(self.bits, np.float32)
        reward = float(self.compute_reward(achieved, self.goal, {}))
        info = {"is_success": reward > 0}
        truncated = self.steps >= self.max_steps and not pressed
        return self._observation(achieved), reward, pressed, truncated, info

    def compute_reward(self, achieved_goal, desired_goal, info):
        return np.all(np.asarray(achieved_goal) == np.asarray(desired_goal), axis=-1).astype(np.float32)


class ContinuousTap(gym.Env):
    """Tap the goal cell with one relative move."""

    cells = 4

    def __init__(self) -> None:
        self.action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)
        self.observation_space = _dict_space(self.cells, 1, -1.0)

    def _cell(self, x: float) -> int:
        return min(int((x + 1.0) / 2.0 * self.cells), self.cells - 1)

    def _observation(self, achieved: np.ndarray) -> dict:
        image = np.zeros(IMAGE, np.uint8)
        width, cell = IMAGE[1] // self.cells, self._cell(self.x)
        image[:, cell * width : (cell + 1) * width] = 255
        return {
            "observation": image,
            "desired_goal": np.eye(self.cells, dtype=np.float32)[self.goal],
            "achieved_goal": achieved,
            "previous_action": self.previous.copy(),
        }

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.x = float(self.np_random.uniform(-1.0, 1.0))
        self.goal = int(self.np_random.integers(self.cells))
        self.previous = np.zeros(1, np.float32)
        return self._observation(np.zeros(self.cells, np.float32)), {}

    def step(self, action):
        action = np.clip(np.asarray(action, np.float32).reshape(1), -1.0, 1.0)
        self.previous = action
        tapped = self._cell(float(np.clip(self.x + 2.0 * action[0], -1.0, 1.0)))
        achieved = np.eye(self.cells, dtype=np.float32)[tapped]
        reward = float(tapped == self.goal)
        return self._observation(achieved), reward, True, False, {"is_success": reward > 0}

    def compute_reward(self, achieved_goal, desired_goal, info):
        return np.all(np.asarray(achieved_goal) == np.asarray(desired_goal), axis=-1).astype(np.float32)


def register() -> None:
    """Register the toys with Gymnasium (idempotent)."""
    for name, entry in (("toys/BitFlipPress-v0", BitFlipPress), ("toys/ContinuousTap-v0", ContinuousTap)):
        if name not in gym.registry:
            gym.register(name, entry_point=entry)
