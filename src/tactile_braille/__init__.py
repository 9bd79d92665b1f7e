"""tactile_braille: a benchmark for reinforcement learning from touch.

Layers (each imports only those above it): ``keyboard`` (the braille keyboard
as data and physics), ``sensor`` (the simulated TacTip and the shared image
processing), ``rigs`` (anything that taps: virtual or real), ``datasets``
(collection, storage, cache), ``envs`` (the four Gymnasium tasks),
``supervised`` (the key classifier) and ``cli``. Importing the package
registers the environments with Gymnasium (by name; nothing else is loaded).
"""

from tactile_braille._registration import register_envs as _register_envs
from tactile_braille._registration import register_task
from tactile_braille._tasks import KeySet, RegisteredTask
from tactile_braille._version import __version__

_register_envs()

__all__ = ["KeySet", "RegisteredTask", "__version__", "register_task"]
