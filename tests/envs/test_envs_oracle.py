"""The scripted oracle solves every task on both simulated backends; a random policy does not.

The continuous tasks run on coarse grid datasets (4 mm / 6 mm spacing, 3 tap
depths): the oracle's deep tap lands on the stored sample nearest to the key
centre, which must still actuate that key.
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.envs import ENV_IDS
from tactile_braille.envs.oracle import oracle_action

SIMULATED_BACKENDS = ("dataset", "render")
EPISODES = 20


@pytest.fixture(scope="session")
def oracle_datasets(env_datasets) -> dict[str, Path]:
    """Small datasets keyed by env id (see ``env_datasets`` in conftest.py)."""
    return env_datasets


def _mean_return(env, policy, episodes: int, first_seed: int) -> tuple[float, list[int]]:
    returns, lengths = [], []
    for episode in range(episodes):
        env.reset(seed=first_seed + episode)
        total, steps, done = 0.0, 0, False
        while not done:
            _, reward, terminated, truncated, _ = env.step(policy(env))
            total += reward
            steps += 1
            done = terminated or truncated
        returns.append(total)
        lengths.append(steps)
    return float(np.mean(returns)), lengths


@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_oracle_solves_the_task_and_random_does_not(env_id, backend, oracle_datasets):
    kwargs = {"dataset": oracle_datasets[env_id]} if backend == "dataset" else {"backend": backend}
    env = gym.make(env_id, **kwargs)

    oracle_mean, oracle_lengths = _mean_return(env, oracle_action, EPISODES, first_seed=1000)
    assert oracle_mean >= 0.95
    assert max(oracle_lengths) < 25  # it presses well before the time limit

    env.action_space.seed(0)
    random_mean, _ = _mean_return(env, lambda e: e.action_space.sample(), 2 * EPISODES, first_seed=2000)
    assert random_mean <= 0.6
    assert random_mean < oracle_mean - 0.35
    env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_oracle_accepts_wrapped_and_unwrapped_envs(env_id, oracle_datasets):
    env = gym.make(env_id, dataset=oracle_datasets[env_id])
    env.reset(seed=0)
    wrapped, unwrapped = oracle_action(env), oracle_action(env.unwrapped)
    np.testing.assert_array_equal(wrapped, unwrapped)
    assert env.action_space.contains(
        np.asarray(wrapped, dtype=env.action_space.dtype).reshape(env.action_space.shape)
    )
    env.close()
