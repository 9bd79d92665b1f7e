"""The four braille tasks as data: key sets, key grids, action bounds, work frames.

Each environment is a ``Task`` (what to type, how the sensor moves) played on
a backend (where the tactile images come from). The numbers are the paper's:
see ``docs/environments.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tactile_braille._registration import MAX_EPISODE_STEPS  # noqa: F401 - re-exported
from tactile_braille.keyboard.calibration import RIG_TAP_OFFSET_MM, work_frame_origin_mm
from tactile_braille.keyboard.layout import NONE_KEY, key_set

DISCRETE_ACTIONS: tuple[str, ...] = ("UP", "DOWN", "LEFT", "RIGHT", "PRESS")
"""Discrete actions: move to the neighbouring cell of the key grid, or press."""

MOVE_TAP_DEPTH_MM = 5.0
"""Depth of the tap that reads the key after a discrete move (1.5 mm into the
key top; the rig backends perturb it to 4-5 mm). Short of actuation but for
the earliest switches (O, P, Q, S, V and X register at or above 4.85-4.95 mm
at their centres on the virtual rig); a press during a reading tap does not
count as the agent's press."""
PRESS_DEPTH_MM = 8.0
"""Depth of a discrete PRESS (the paper's 8 mm)."""
RESET_TAP_DEPTH_MM = 4.0
"""Depth of the tap that gives the first observation of a continuous episode."""

_G = NONE_KEY
KEY_GRIDS: dict[str, tuple[tuple[str, ...], ...]] = {
    "arrows": ((_G, "UP", _G), ("LEFT", "DOWN", "RIGHT")),
    "alphabet": (
        tuple("QWERTYUIOP"),
        (*"ASDFGHJKL", _G),
        (*"ZXCVBNM", _G, _G, _G),
        (_G, _G, *(["SPACE"] * 6), _G, _G),
    ),
}
"""The discrete tasks' key grids (the original robot's): NONE cells are off the keys."""

GRIDS = ("rig", "released")
"""The discrete tasks' key grids by name: ``"rig"``, the original robot's (:data:`KEY_GRIDS`: the
alphabet's third row starts under A), and ``"released"``, the released simulator's
(:data:`RELEASED_KEY_GRIDS`: that row one column right, Z under S); the arrows' grid is the same in
both."""
RELEASED_KEY_GRIDS: dict[str, tuple[tuple[str, ...], ...]] = {
    **KEY_GRIDS,
    "alphabet": (
        tuple("QWERTYUIOP"),
        (*"ASDFGHJKL", _G),
        (_G, *"ZXCVBNM", _G, _G),
        (_G, _G, *(["SPACE"] * 6), _G, _G),
    ),
}
"""The released simulator's key grids (``envs/sim/disc_sim_braille_env/mock_kb.py``)."""


@dataclass(frozen=True)
class Task:
    """What to type and how the sensor may move.

    Attributes:
        keys: key set name (``"arrows"`` or ``"alphabet"``).
        continuous: continuous (dx, dy, depth) actions instead of grid moves.
        grid: the discrete tasks' key grid, one of :data:`GRIDS` (``"rig"``: the robot's).
    """

    keys: str
    continuous: bool
    grid: str = "rig"

    def __post_init__(self) -> None:
        if self.keys not in KEY_GRIDS:
            raise ValueError(f"keys must be one of {sorted(KEY_GRIDS)}, got {self.keys!r}")
        if self.grid not in GRIDS:
            raise ValueError(f"key_grid must be one of {GRIDS}, got {self.grid!r}")
        if self.grid != "rig" and self.continuous:
            raise ValueError(
                f"key_grid={self.grid!r} is the discrete tasks': a continuous task moves over the keyboard"
            )

    @property
    def goal_keys(self) -> tuple[str, ...]:
        """The keys a goal is drawn from, in one-hot order."""
        return key_set(self.keys)

    @property
    def key_grid(self) -> np.ndarray:
        """(rows, columns) array of key names of the discrete grid."""
        return np.array((RELEASED_KEY_GRIDS if self.grid == "released" else KEY_GRIDS)[self.keys])

    @property
    def max_move_mm(self) -> float:
        """Bound of a continuous move in x and y: 10 mm (arrows) or 20 mm (alphabet)."""
        return 10.0 if self.keys == "arrows" else 20.0

    @property
    def workspace_mm(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """Continuous workspace (x, y) in the task's work frame."""
        return ((-20.0, 0.0), (-20.0, 20.0)) if self.keys == "arrows" else ((-30.0, 30.0), (-90.0, 90.0))

    @property
    def depth_range_mm(self) -> tuple[float, float]:
        """Bounds of the continuous tap depth: 2..8 mm (the original's 0..6 plus its 2 mm)."""
        return RIG_TAP_OFFSET_MM, RIG_TAP_OFFSET_MM + 6.0

    @property
    def frame_origin_mm(self) -> tuple[float, float]:
        """Keyboard-frame position of the continuous work frame's origin."""
        return work_frame_origin_mm(self.keys)

    @property
    def action_size(self) -> int:
        return 3 if self.continuous else len(DISCRETE_ACTIONS)
