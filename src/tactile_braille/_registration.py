"""Registration of the four environment ids with Gymnasium (by entry-point strings only).

Kept apart from ``tactile_braille.envs`` so that ``import tactile_braille``
registers the environments without importing the environment layer itself.
"""

from __future__ import annotations

import gymnasium as gym

MAX_EPISODE_STEPS = 25
"""Episode cut (the registry's ``max_episode_steps``), as in the paper."""

ENV_IDS: tuple[str, ...] = (
    "tactile_braille/DiscreteArrows-v0",
    "tactile_braille/DiscreteAlphabet-v0",
    "tactile_braille/ContinuousArrows-v0",
    "tactile_braille/ContinuousAlphabet-v0",
)


def register_envs() -> None:
    """Register the four ids (idempotent)."""
    for env_id in ENV_IDS:
        if env_id in gym.registry:
            continue
        name = env_id.split("/")[1].removesuffix("-v0")
        action = "Discrete" if name.startswith("Discrete") else "Continuous"
        gym.register(
            id=env_id,
            entry_point=f"tactile_braille.envs.{action.lower()}:{action}BrailleEnv",
            vector_entry_point=f"tactile_braille.envs.vector:Vector{action}BrailleEnv",
            max_episode_steps=MAX_EPISODE_STEPS,
            kwargs={"keys": name.removeprefix(action).lower()},
        )
