"""SAC and TD3 on feature observations, and batches whose reward only the sensor pose explains.

Shared by the tests of the asymmetric critics (agents, networks, the touch
wrapper): the sizes are those of the continuous arrow task's goals, previous
actions and actions, with small feature vectors for images.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import torch

from tactile_braille.agents import SACAgent, SACConfig, TD3Agent, TD3Config
from tactile_braille.agents.common import POSE_SIZE

FEATURES, GOALS, PREVIOUS, ACTIONS = 6, 4, 3, 3


def feature_observation_space() -> gym.spaces.Dict:
    return gym.spaces.Dict(
        {
            "observation": gym.spaces.Box(-np.inf, np.inf, (FEATURES,), np.float32),
            "previous_action": gym.spaces.Box(-1.0, 1.0, (PREVIOUS,), np.float32),
            "achieved_goal": gym.spaces.Box(0.0, 1.0, (GOALS,), np.float32),
            "desired_goal": gym.spaces.Box(0.0, 1.0, (GOALS,), np.float32),
        }
    )


ACTION_SPACE = gym.spaces.Box(-1.0, 1.0, (ACTIONS,), np.float32)
AGENT_KINDS = {"sac": (SACAgent, SACConfig), "td3": (TD3Agent, TD3Config)}


def make(algo: str, critic_pose: bool, seed: int = 0, **config):
    agent_class, config_class = AGENT_KINDS[algo]
    torch.manual_seed(seed)
    settings = {"hidden": (32, 32), "batch_size": 64, "learning_rate": 3e-3, "critic_pose": critic_pose}
    return agent_class(feature_observation_space(), ACTION_SPACE, config_class(**{**settings, **config}))


def batch(rng: np.random.Generator, size: int = 64, poses: bool = True) -> dict[str, np.ndarray]:
    """One-step episodes whose reward is hidden from the observation: 1 when pose x + action x > 0."""
    pose = rng.uniform(-1, 1, (size, POSE_SIZE)).astype(np.float32)
    actions = rng.uniform(-1, 1, (size, ACTIONS)).astype(np.float32)
    goals = np.eye(GOALS, dtype=np.float32)[rng.integers(GOALS, size=size)]
    result = {
        "images": rng.standard_normal((size, FEATURES)).astype(np.float32),
        "previous_actions": np.zeros((size, PREVIOUS), np.float32),
        "goals": goals,
        "actions": actions,
        "rewards": (pose[:, 0] + actions[:, 0] > 0).astype(np.float32),
        "next_images": rng.standard_normal((size, FEATURES)).astype(np.float32),
        "next_previous_actions": actions,
        "dones": np.ones(size, np.float32),
    }
    if poses:
        result["poses"], result["next_poses"] = pose, rng.uniform(-1, 1, (size, POSE_SIZE)).astype(np.float32)
    return result
