"""Fixtures shared by the agents' test modules."""

from __future__ import annotations

import gymnasium as gym
import pytest

from agents_helpers import DISCRETE_TASK


@pytest.fixture(scope="module")
def discrete_env(env_datasets):
    env = gym.make(DISCRETE_TASK, dataset=env_datasets[DISCRETE_TASK])
    yield env
    env.close()
