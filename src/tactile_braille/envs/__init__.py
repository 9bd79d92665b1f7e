"""Gymnasium environments for the four braille tasks, registered on ``import tactile_braille``.

* ``tactile_braille/DiscreteArrows-v0``, ``tactile_braille/DiscreteAlphabet-v0``
* ``tactile_braille/ContinuousArrows-v0``, ``tactile_braille/ContinuousAlphabet-v0``
"""

from __future__ import annotations

import gymnasium as gym

from tactile_braille.envs.tasks import MAX_EPISODE_STEPS

ENV_IDS: tuple[str, ...] = (
    "tactile_braille/DiscreteArrows-v0",
    "tactile_braille/DiscreteAlphabet-v0",
    "tactile_braille/ContinuousArrows-v0",
    "tactile_braille/ContinuousAlphabet-v0",
)


def register_envs() -> None:
    """Register the four ids (idempotent)."""
    for action in ("Discrete", "Continuous"):
        for keys in ("arrows", "alphabet"):
            env_id = f"tactile_braille/{action}{keys.capitalize()}-v0"
            if env_id in gym.registry:
                continue
            gym.register(
                id=env_id,
                entry_point=f"tactile_braille.envs.{action.lower()}:{action}BrailleEnv",
                vector_entry_point=f"tactile_braille.envs.vector:Vector{action}BrailleEnv",
                max_episode_steps=MAX_EPISODE_STEPS,
                kwargs={"keys": keys},
            )


__all__ = ["ENV_IDS", "MAX_EPISODE_STEPS", "register_envs"]
