"""tactile_braille: a benchmark for reinforcement learning from touch.

Layers (each imports only those above it): ``keyboard`` (the braille keyboard
as data and physics), ``sensor`` (the simulated TacTip and the shared image
processing), ``rigs`` (anything that taps: virtual or real), ``datasets``
(collection, storage, cache), ``envs`` (the four Gymnasium tasks, registered
on import).
"""

__version__ = "0.1.0"

from tactile_braille.envs import register_envs as _register_envs

_register_envs()
