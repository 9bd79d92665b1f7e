"""Stable-Baselines3 drives the braille environments unmodified (DQN with Hindsight Experience Replay)."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.datasets import PerturbedTaps, collect
from tactile_braille.rigs.virtual import VirtualRig

ENV_ID = "tactile_braille/DiscreteArrows-v0"


@pytest.fixture(scope="module", autouse=True)
def _cache_in_tmp(tmp_path_factory):
    """Point the default-dataset cache at a session-wide temporary folder while this module runs."""
    folder = tmp_path_factory.getbasetemp() / "tactile_braille_cache"
    folder.mkdir(exist_ok=True)
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("TACTILE_BRAILLE_DATA", str(folder))
        yield folder


@pytest.fixture(scope="session")
def small_keys_dataset(tmp_path_factory) -> Path:
    """3 perturbed taps per key (shared with the other ``test_envs_*`` modules)."""
    folder = tmp_path_factory.getbasetemp() / "tactile_braille_env_datasets"
    folder.mkdir(exist_ok=True)
    path = folder / "perturbed-all-3.h5"
    if not path.exists():
        collect(VirtualRig(seed=0), PerturbedTaps(keys="all", per_key=3), path, seed=0, progress=False)
    return path


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
