"""One episode of a policy in an environment: the rollout that test episodes, typing and figures share.

>>> import gymnasium as gym, numpy as np
>>> class Press:  # a policy that always presses
...     def policy_action(self, observation, step, explore, rng, deterministic=False):
...         return 4
>>> env = gym.make("tactile_braille/DiscreteArrows-v0")
>>> episode = run_episode(Press(), env, np.random.default_rng(0), seed=0)
>>> episode.steps, episode.terminated
(1, True)
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium as gym
import numpy as np


@dataclass
class Episode:
    """What an episode gave: its return, its steps, how it ended and the last step's info."""

    total_return: float
    steps: int
    terminated: bool
    info: dict


def run_episode(
    agent,
    env: gym.Env,
    rng: np.random.Generator,
    *,
    seed: int | None = None,
    options: dict | None = None,
    deterministic: bool = False,
) -> Episode:
    """Reset ``env`` (with ``seed`` and ``options``) and act with the agent's test-time policy
    (``explore=False``; ``deterministic`` also turns off a test-time exploration such as DQN's
    ``test_epsilon``) until the episode terminates or is cut by the time limit."""
    observation, _ = env.reset(seed=seed, options=options)
    total, steps, info = 0.0, 0, {}
    while True:
        action = agent.policy_action(observation, 0, explore=False, rng=rng, deterministic=deterministic)
        observation, reward, terminated, truncated, info = env.step(action)
        total, steps = total + float(reward), steps + 1
        if terminated or truncated:
            return Episode(total, steps, bool(terminated), info)


def evaluate(agent, env: gym.Env, episodes: int, seed: int) -> dict[str, float]:
    """Mean return, length and success rate of test episodes (the agent's test-time actions)."""
    rng = np.random.default_rng(seed)
    results = [run_episode(agent, env, rng, seed=seed + number) for number in range(episodes)]
    return {
        "test/episodic_return": float(np.mean([e.total_return for e in results])),
        "test/episode_length": float(np.mean([e.steps for e in results])),
        "test/success_rate": float(np.mean([e.info.get("is_success", e.total_return > 0) for e in results])),
    }
