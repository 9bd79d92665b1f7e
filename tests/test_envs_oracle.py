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
from tactile_braille.datasets import GridTaps, PerturbedTaps, collect
from tactile_braille.envs import ENV_IDS
from tactile_braille.envs.oracle import oracle_action
from tactile_braille.rigs.virtual import VirtualRig

SIMULATED_BACKENDS = ("dataset", "render")
EPISODES = 20


@pytest.fixture(scope="module", autouse=True)
def _cache_in_tmp(tmp_path_factory):
    """Point the default-dataset cache at a session-wide temporary folder while this module runs."""
    folder = tmp_path_factory.getbasetemp() / "tactile_braille_cache"
    folder.mkdir(exist_ok=True)
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("TACTILE_BRAILLE_DATA", str(folder))
        yield folder


def _collect_once(tmp_path_factory, name: str, procedure) -> Path:
    """Collect ``procedure`` on the virtual rig into a session-wide folder (once per session)."""
    folder = tmp_path_factory.getbasetemp() / "tactile_braille_env_datasets"
    folder.mkdir(exist_ok=True)
    path = folder / f"{name}.h5"
    if not path.exists():
        collect(VirtualRig(seed=0), procedure, path, seed=0, progress=False)
    return path


@pytest.fixture(scope="session")
def oracle_datasets(tmp_path_factory) -> dict[str, Path]:
    perturbed = _collect_once(tmp_path_factory, "perturbed-all-3", PerturbedTaps(keys="all", per_key=3))
    arrows = _collect_once(
        tmp_path_factory, "grid-arrows-4mm", GridTaps(keys="arrows", spacing_mm=4, depth_step_mm=3)
    )
    alphabet = _collect_once(
        tmp_path_factory, "grid-alphabet-6mm", GridTaps(keys="alphabet", spacing_mm=6, depth_step_mm=3)
    )
    return {
        "tactile_braille/DiscreteArrows-v0": perturbed,
        "tactile_braille/DiscreteAlphabet-v0": perturbed,
        "tactile_braille/ContinuousArrows-v0": arrows,
        "tactile_braille/ContinuousAlphabet-v0": alphabet,
    }


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
