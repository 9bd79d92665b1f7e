"""A braille task: a key set's row of data (:data:`~tactile_braille._tasks.KEY_SETS`) and an action kind.

Each environment is a ``Task`` (what to type, how the sensor moves) played on
a backend (where the tactile images come from). The numbers are the paper's,
in the key sets' table: see ``docs/environments.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tactile_braille._tasks import KEY_SETS, MAX_EPISODE_STEPS, KeySet  # noqa: F401 - re-exported
from tactile_braille.envs.world import GRIDS, check_key_grid  # noqa: F401 - GRIDS re-exported
from tactile_braille.keyboard.calibration import RIG_TAP_OFFSET_MM, work_frame_origin_mm

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

KEY_GRIDS: dict[str, tuple[tuple[str, ...], ...]] = {
    name: row.key_grids["rig"] for name, row in KEY_SETS.items()
}
"""The discrete tasks' key grids (the original robot's), by key set: NONE cells are off the keys."""
RELEASED_KEY_GRIDS: dict[str, tuple[tuple[str, ...], ...]] = {
    name: row.key_grids["released"] for name, row in KEY_SETS.items()
}
"""The released simulator's key grids (``envs/sim/disc_sim_braille_env/mock_kb.py``), by key set."""


@dataclass(frozen=True)
class Task:
    """What to type and how the sensor may move.

    Attributes:
        keys: key set name, a key of :data:`~tactile_braille._tasks.KEY_SETS` (``"arrows"``,
            ``"alphabet"``).
        continuous: continuous (dx, dy, depth) actions instead of grid moves.
        grid: the discrete tasks' key grid, one of :data:`~tactile_braille.envs.world.GRIDS`
            (``"rig"``: the robot's).
    """

    keys: str
    continuous: bool
    grid: str = "rig"

    def __post_init__(self) -> None:
        if self.keys not in KEY_SETS:
            raise ValueError(f"keys must be one of {sorted(KEY_SETS)}, got {self.keys!r}")
        check_key_grid(self.grid, self.continuous)

    @property
    def key_set(self) -> KeySet:
        """The key set's row of data."""
        return KEY_SETS[self.keys]

    @property
    def goal_keys(self) -> tuple[str, ...]:
        """The keys a goal is drawn from, in one-hot order."""
        return self.key_set.keys

    @property
    def key_grid(self) -> np.ndarray:
        """(rows, columns) array of key names of the discrete grid."""
        return np.array(self.key_set.key_grids[self.grid])

    @property
    def max_move_mm(self) -> float:
        """Bound of a continuous move in x and y (10 mm on the arrows, 20 on the alphabet)."""
        return self.key_set.max_move_mm

    @property
    def workspace_mm(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """Continuous workspace (x, y) in the task's work frame."""
        return self.key_set.workspace_mm

    @property
    def depth_range_mm(self) -> tuple[float, float]:
        """Bounds of the continuous tap depth: 2..8 mm (the original's 0..6 plus its 2 mm)."""
        return RIG_TAP_OFFSET_MM, RIG_TAP_OFFSET_MM + 6.0

    @property
    def frame_origin_mm(self) -> tuple[float, float]:
        """Keyboard-frame position of the continuous work frame's origin."""
        return work_frame_origin_mm(self.key_set.work_frame)

    @property
    def action_size(self) -> int:
        return 3 if self.continuous else len(DISCRETE_ACTIONS)
