"""Tap memory: the agent's own recent observations, stacked into each observation.

The paper's agents see one tactile image and the previous action. A single
light tap often says little about where the sensor is (docs/notes/tactile-track.md,
"Perception is the first bottleneck"); with the last ``taps`` images and the moves between them, a
policy can read where it is from a short history, as a person feeling for a
key does. Everything stacked is the environment's own observation dictionary
at earlier steps, so a run with memory stays on the ``tactile`` track.

:class:`TapMemory` keeps, after each reset:

* ``observation``: the last ``taps`` tactile images along the channel axis,
  oldest first, newest last: shape ``(H, W, taps)``. Taps before the episode's
  first are blank (all zero), which no tap of the sensor renders.
* ``previous_action``: the last ``taps - 1`` actions, oldest first, each as the
  environment reports it (zeros before the first), concatenated: the moves
  between the stacked taps.

Goals and any other entries pass through unchanged, so hindsight relabelling
and the typing protocols work as without memory. A reset (every key of the
typing evaluation resets, keeping the pose) clears the memory.

>>> import gymnasium as gym
>>> import tactile_braille
>>> env = TapMemory(gym.make("tactile_braille/DiscreteArrows-v0"), taps=2)
>>> observation, _ = env.reset(seed=0)
>>> observation["observation"].shape, observation["previous_action"].shape
((100, 100, 2), (5,))
>>> bool(observation["observation"][..., 0].any())  # no tap before the first
False
"""

from __future__ import annotations

from collections import deque
from typing import Any

import gymnasium as gym
import numpy as np


class TapMemory(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """The last ``taps`` tactile images and the ``taps - 1`` actions between them in each observation.

    Args:
        env: a goal-conditioned braille environment with image observations ``(H, W, 1)``.
        taps: images kept, at least 2 (1 is the environment itself: do not wrap).
    """

    def __init__(self, env: gym.Env, taps: int) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, taps=taps)
        gym.Wrapper.__init__(self, env)
        if not isinstance(taps, int) or isinstance(taps, bool) or taps < 2:
            raise ValueError(f"TapMemory keeps at least 2 taps (1 is no memory), got {taps!r}")
        spaces = env.observation_space
        entries = spaces.spaces if isinstance(spaces, gym.spaces.Dict) else {}
        image = entries.get("observation")
        if image is None or len(image.shape) != 3 or image.shape[2] != 1 or "previous_action" not in entries:
            raise ValueError(
                "TapMemory stacks one-channel tactile images (H, W, 1) and their previous actions, "
                f"got {spaces}"
            )
        self.taps = taps
        action = spaces["previous_action"]
        self.observation_space = gym.spaces.Dict({
            **spaces.spaces,
            "observation": gym.spaces.Box(0, 255, (*image.shape[:2], taps), image.dtype),
            "previous_action": gym.spaces.Box(
                np.tile(action.low, taps - 1), np.tile(action.high, taps - 1), dtype=action.dtype
            ),
        })  # fmt: skip
        self._images: deque[np.ndarray] = deque(maxlen=taps)
        self._actions: deque[np.ndarray] = deque(maxlen=taps - 1)

    def reset(self, **kwargs: Any) -> tuple[dict[str, np.ndarray], dict]:
        observation, info = self.env.reset(**kwargs)
        image, action = observation["observation"], observation["previous_action"]
        self._images.extend([np.zeros_like(image)] * self.taps)
        self._actions.extend([np.zeros_like(action)] * (self.taps - 1))
        return self._remember(observation), info

    def step(self, action):
        observation, reward, terminated, truncated, info = self.env.step(action)
        return self._remember(observation), reward, terminated, truncated, info

    def _remember(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        self._images.append(observation["observation"])
        self._actions.append(observation["previous_action"])
        return {
            **observation,
            "observation": np.concatenate(self._images, axis=-1),
            "previous_action": np.concatenate(self._actions),
        }
