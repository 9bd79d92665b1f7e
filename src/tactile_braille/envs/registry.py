"""What a registered environment id is, read from its Gymnasium spec rather than from the id's text.

>>> task_of("tactile_braille/ContinuousAlphabet-v0")
Task(keys='alphabet', continuous=True, grid='rig')
"""

from __future__ import annotations

import gymnasium as gym
from gymnasium.envs.registration import load_env_creator

from tactile_braille.envs.braille_env import BrailleEnv
from tactile_braille.envs.tasks import Task


def task_of(env_id: str) -> Task | None:
    """The braille :class:`Task` of a registered id (key set and action kind), or None for another
    goal-conditioned environment (which has no keyboard).

    Raises:
        ValueError: ``env_id`` is not registered.
    """
    if env_id not in gym.registry:
        from tactile_braille._registration import ENV_IDS

        raise ValueError(f"unknown task {env_id!r}; choose one of {ENV_IDS} (or a registered goal env)")
    spec = gym.spec(env_id)
    creator = spec.entry_point
    if isinstance(creator, str):
        creator = load_env_creator(creator)
    if not (isinstance(creator, type) and issubclass(creator, BrailleEnv)):
        return None
    return Task(keys=spec.kwargs.get("keys", "arrows"), continuous=creator.continuous)


def task_name(env_id: str) -> str:
    """The id without its namespace (``DiscreteArrows-v0``): run folders and reports name tasks so."""
    spec = gym.spec(env_id)
    return spec.name if spec.version is None else f"{spec.name}-v{spec.version}"
