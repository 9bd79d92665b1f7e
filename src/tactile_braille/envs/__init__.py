"""Gymnasium environments for the four braille tasks, registered on ``import tactile_braille``.

* ``tactile_braille/DiscreteArrows-v0``, ``tactile_braille/DiscreteAlphabet-v0``
* ``tactile_braille/ContinuousArrows-v0``, ``tactile_braille/ContinuousAlphabet-v0``
"""

from __future__ import annotations

from tactile_braille._registration import ENV_IDS, MAX_EPISODE_STEPS, register_envs

__all__ = ["ENV_IDS", "MAX_EPISODE_STEPS", "register_envs"]
