"""Registration of the environment ids with Gymnasium (by entry-point strings only).

Kept apart from ``tactile_braille.envs`` so that ``import tactile_braille``
registers the environments without importing the environment layer itself.
One registration per row of :data:`~tactile_braille._tasks.REGISTERED_TASKS`.
"""

from __future__ import annotations

import gymnasium as gym

from tactile_braille._tasks import ENV_IDS, MAX_EPISODE_STEPS, REGISTERED_TASKS

__all__ = ["ENV_IDS", "MAX_EPISODE_STEPS", "register_envs"]


def register_envs() -> None:
    """Register each row of :data:`~tactile_braille._tasks.REGISTERED_TASKS` (idempotent)."""
    for task in REGISTERED_TASKS:
        if task.env_id in gym.registry:
            continue
        gym.register(
            id=task.env_id,
            entry_point=task.entry_point,
            vector_entry_point=task.vector_entry_point,
            max_episode_steps=task.max_episode_steps,
            kwargs={"keys": task.keys},
        )
