"""Tap memory: the last taps and the moves between them, stacked into each observation."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.envs.memory import TapMemory

ARROWS = "tactile_braille/DiscreteArrows-v0"
CONTINUOUS = "tactile_braille/ContinuousArrows-v0"


@pytest.mark.filterwarnings("ignore:.*different from the unwrapped version")
@pytest.mark.parametrize("env_id", [ARROWS, CONTINUOUS])
def test_tap_memory_passes_gymnasiums_checks(env_id, env_datasets):
    env = TapMemory(gym.make(env_id, dataset=env_datasets[env_id]), taps=3)
    check_env(env, skip_render_check=True)
    spaces = env.observation_space
    assert spaces["observation"].shape == (100, 100, 3)
    assert spaces["previous_action"].shape == (2 * env.env.observation_space["previous_action"].shape[0],)


def test_tap_memory_stacks_the_last_taps_oldest_first_and_the_actions_between_them(env_datasets):
    plain = gym.make(ARROWS, dataset=env_datasets[ARROWS])
    memory = TapMemory(gym.make(ARROWS, dataset=env_datasets[ARROWS]), taps=3)
    seen, remembered = [plain.reset(seed=4)[0]], [memory.reset(seed=4)[0]]
    for action in (3, 1, 2):  # RIGHT, DOWN, LEFT: moves that do not end the episode
        seen.append(plain.step(action)[0])
        remembered.append(memory.step(action)[0])
    blank = np.zeros_like(seen[0]["observation"])
    no_action = np.zeros_like(seen[0]["previous_action"])
    for step, observation in enumerate(remembered):
        taps = [seen[i]["observation"] if i >= 0 else blank for i in range(step - 2, step + 1)]
        actions = [seen[i]["previous_action"] if i >= 0 else no_action for i in range(step - 1, step + 1)]
        np.testing.assert_array_equal(observation["observation"], np.concatenate(taps, axis=-1))
        np.testing.assert_array_equal(observation["previous_action"], np.concatenate(actions))
        for key in ("desired_goal", "achieved_goal"):
            np.testing.assert_array_equal(observation[key], seen[step][key])
    assert seen[1]["observation"].any() and not np.array_equal(seen[0]["observation"], seen[1]["observation"])


def test_a_reset_clears_the_memory_even_where_it_keeps_the_pose(env_datasets):
    env = TapMemory(gym.make(ARROWS, dataset=env_datasets[ARROWS]), taps=2)
    env.reset(seed=0)
    stepped = env.step(3)[0]
    assert stepped["observation"][..., 0].any()  # the first tap, remembered
    again, _ = env.reset(options={"keep_pose": True})
    assert not again["observation"][..., 0].any() and not again["previous_action"].any()
    assert again["observation"][..., 1].any()  # the tap the reset made


@pytest.mark.parametrize("taps", [1, 0, 2.0, True])
def test_tap_memory_refuses_fewer_than_two_taps(taps, env_datasets):
    with pytest.raises(ValueError, match="at least 2 taps"):
        TapMemory(gym.make(ARROWS, dataset=env_datasets[ARROWS]), taps=taps)


def test_tap_memory_refuses_an_environment_without_tactile_images():
    with pytest.raises(ValueError, match="one-channel tactile images"):
        TapMemory(gym.make("CartPole-v1"), taps=2)
