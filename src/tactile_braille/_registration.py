"""Registration of the environment ids with Gymnasium (by entry-point strings only).

Kept apart from ``tactile_braille.envs`` so that ``import tactile_braille``
registers the environments without importing the environment layer itself.
One registration per row of :data:`~tactile_braille._tasks.REGISTERED_TASKS`.
"""

from __future__ import annotations

import dataclasses

import gymnasium as gym

from tactile_braille._tasks import (
    ENV_IDS,
    KEY_SETS,
    MAX_EPISODE_STEPS,
    REGISTERED_TASKS,
    KeySet,
    RegisteredTask,
)

__all__ = ["ENV_IDS", "MAX_EPISODE_STEPS", "register_envs", "register_task"]


def register_envs() -> None:
    """Register each row of :data:`~tactile_braille._tasks.REGISTERED_TASKS` (idempotent)."""
    for task in REGISTERED_TASKS:
        if task.env_id not in gym.registry:
            _register(task)


def register_task(task: RegisteredTask, key_set: KeySet | None = None) -> None:
    """Register a braille task of your own with Gymnasium: an id (``task``) typing a key set, the
    project's or a new one (``key_set``, added to :data:`~tactile_braille._tasks.KEY_SETS`).

    Raises:
        ValueError: the id is registered already, the key set is unknown, or a key set of that name
            with other contents exists; nothing is registered then.
    """
    if task.env_id in gym.registry:
        raise ValueError(f"{task.env_id} is registered already")
    if key_set is not None:
        if key_set.name != task.keys:
            raise ValueError(f"{task.env_id} types the key set {task.keys!r}, but {key_set.name!r} was given")
        known = KEY_SETS.get(key_set.name)
        if known is not None and dataclasses.asdict(known) != dataclasses.asdict(key_set):
            raise ValueError(
                f"a key set named {key_set.name!r} exists with other contents: choose another name"
            )
    elif task.keys not in KEY_SETS:
        raise ValueError(f"unknown key set {task.keys!r}; give its KeySet, or use one of {tuple(KEY_SETS)}")
    if key_set is not None:
        KEY_SETS[key_set.name] = key_set
    _register(task)


def _register(task: RegisteredTask) -> None:
    gym.register(
        id=task.env_id,
        entry_point=task.entry_point,
        vector_entry_point=task.vector_entry_point,
        max_episode_steps=task.max_episode_steps,
        kwargs={"keys": task.keys},
    )
