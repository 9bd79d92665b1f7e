"""Stable-Baselines3 drives the braille environments unmodified (DQN with Hindsight Experience Replay)."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import tactile_braille  # noqa: F401 - registers the environments

ENV_ID = "tactile_braille/DiscreteArrows-v0"


@pytest.fixture(scope="session")
def small_keys_dataset(env_datasets) -> Path:
    """3 perturbed taps per key (see ``env_datasets`` in conftest.py)."""
    return env_datasets[ENV_ID]


def test_dqn_with_her_learns_on_the_env(small_keys_dataset):
    pytest.importorskip("stable_baselines3")
    torch = pytest.importorskip("torch")
    from stable_baselines3 import DQN, HerReplayBuffer

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        env = gym.make(ENV_ID, dataset=small_keys_dataset)
        model = DQN(
            "MultiInputPolicy",
            env,
            replay_buffer_class=HerReplayBuffer,
            replay_buffer_kwargs={"n_sampled_goal": 2, "goal_selection_strategy": "future"},
            learning_starts=50,
            buffer_size=500,
            batch_size=16,
            policy_kwargs={"net_arch": [32]},
            device="cpu",
            seed=0,
            verbose=0,
        )
        model.learn(200)
    finally:
        torch.set_num_threads(threads)

    assert model.num_timesteps == 200
    assert model._n_updates > 0  # gradient steps on HER samples happened
    buffer = model.replay_buffer
    assert isinstance(buffer, HerReplayBuffer)
    assert buffer.size() == 200
    # HER relabels goals and recomputes rewards with the env's compute_reward: they agree.
    samples = buffer.sample(64)
    achieved = samples.next_observations["achieved_goal"].cpu().numpy()
    desired = samples.observations["desired_goal"].cpu().numpy()
    rewards = samples.rewards.cpu().numpy().ravel()
    np.testing.assert_array_equal(rewards, env.unwrapped.compute_reward(achieved, desired, {}))
    assert set(np.unique(rewards)) <= {0.0, 1.0}
    # The trained policy acts in the env's action space.
    observation, _ = env.reset(seed=0)
    action, _ = model.predict(observation, deterministic=True)
    assert env.action_space.contains(int(action))
    env.close()
