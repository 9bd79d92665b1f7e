"""The braille tasks' dynamics, written once over a batch of environments.

:class:`BatchedBraille` holds the state of ``n`` environments as arrays and
steps them together; the single environments (``n = 1``) and the vectorised
environment share it, so both follow exactly the same rules.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from tactile_braille.envs.tasks import (
    DISCRETE_ACTIONS,
    MOVE_TAP_DEPTH_MM,
    PRESS_DEPTH_MM,
    RESET_TAP_DEPTH_MM,
    Task,
)
from tactile_braille.envs.world import EDGES, TAP_DEPTHS, WORLD_RULES  # noqa: F401 - re-exported
from tactile_braille.keyboard.layout import NONE_KEY, KeyboardLayout

OBSERVATION_SIZE_PX = 100
"""Side of the tactile observation (the paper's 100 x 100)."""
PROPRIO_KEY = "sensor_pose"
"""The observation entry the ``proprio`` track adds (``proprio=True``): the sensor's keyboard-frame
x, y and tap depth in mm, as the arm reports it (docs/benchmark.md)."""

# Moves of the discrete actions in (row, column) of the key grid; PRESS stays.
_MOVES = np.array([(-1, 0), (1, 0), (0, -1), (0, 1), (0, 0)], dtype=np.int64)
_PRESS = DISCRETE_ACTIONS.index("PRESS")

RELEASED_DEPTH_SHIFT_MM = 2.0
"""How much deeper than commanded a tap reads with ``tap_depth="released"`` (:data:`TAP_DEPTHS`)."""


def action_effects(previous_actions: np.ndarray, continuous: bool) -> np.ndarray:
    """What each action did, as the action space documents it, from the ``previous_action`` entries of
    observations: (N, 3) float32, the planar move in action units, then the tap's depth code.

    Continuous: the clipped normalised ``(dx, dy)`` and ``depth`` (before the workspace's edge clips the
    move). Discrete: the grid move in (row, column) cells, and 1 for PRESS, 0 for a move's tap (before
    the grid's edge stops a move). A reset's zero vector did nothing known: a row of NaN. Every track
    may use this: it is the action space's documentation, not the sensor's pose or the key layout.
    """
    previous = np.asarray(previous_actions, dtype=np.float32)
    effects = np.full((len(previous), 3), np.nan, dtype=np.float32)
    acted = previous.any(-1)
    if continuous:
        effects[acted] = previous[acted, :3]
    else:
        action = previous[acted].argmax(-1)
        effects[acted, :2] = _MOVES[action]
        effects[acted, 2] = action == _PRESS
    return effects


def cell_positions_mm(task: Task, layout: KeyboardLayout) -> np.ndarray:
    """(rows, columns, 2) keyboard-frame position of each cell of the discrete key grid.

    Each row of cells lies along its first key's row of the keyboard, one key pitch apart, with that
    key's cells centred on it: a key of one cell sits at its centre, and SPACE's six cells spread along
    the bar. NONE cells continue their row's spacing, which puts some over real keys (SEMICOLON,
    RIGHTSHIFT, ...), but they are tapped in the air (depth 0) and a PRESS there presses nothing.
    """
    grid = task.key_grid
    positions = np.zeros((*grid.shape, 2))
    pitch = layout.pitch_mm
    for r, row in enumerate(grid):
        first = next(c for c in range(len(row)) if row[c] != NONE_KEY)
        cells = np.flatnonzero(row == row[first])
        # A key of one cell: its own column; a key over several (SPACE): their middle.
        anchor = first if len(cells) == 1 else (cells[0] + cells[-1]) / 2
        x0, y0 = layout.centre_mm(row[first])
        for c in range(len(row)):
            positions[r, c] = (x0, y0 - (c - anchor) * pitch)
    return positions


class BatchedBraille:
    """State and rules of ``n`` braille-typing environments.

    Args:
        task: what to type and how to move.
        backend: a :class:`DatasetBackend` or :class:`RigBackend`.
        n: number of environments.
        proprio: observations also carry ``sensor_pose`` (the ``proprio`` track's, :data:`PROPRIO_KEY`).
        edges: what the workspace's edge does to a continuous move, one of :data:`EDGES` (the discrete
            tasks' grid edges stop a move, as in the released simulator: ``"stop"`` only).
        tap_depth: which stored depth a continuous tap reads, one of :data:`TAP_DEPTHS` (``"released"``
            on the dataset backend only: it is a property of the released simulator's lookup).

    The environments check ``edges`` and ``tap_depth`` against the task and the backend
    (:func:`~tactile_braille.envs.world.check_world`) before they build one.
    """

    def __init__(
        self,
        task: Task,
        backend,
        n: int,
        proprio: bool = False,
        edges: str = "stop",
        tap_depth: str = "commanded",
    ) -> None:
        if not isinstance(proprio, bool | np.bool_):
            raise TypeError(f"proprio must be True or False, got {proprio!r}")
        self.edges, self.tap_depth = edges, tap_depth
        self._depth_shift_mm = RELEASED_DEPTH_SHIFT_MM if tap_depth == "released" else 0.0
        self.task = task
        self.proprio = bool(proprio)
        self.backend = backend
        self.n = n
        layout = backend.layout
        self.layout = layout
        self.goal_keys = task.goal_keys
        # Layout code -> goal index (or -1 for keys outside the task).
        self._goal_of_code = np.full(len(layout) + 1, -1, dtype=np.int64)
        for i, name in enumerate(self.goal_keys):
            self._goal_of_code[layout.key(name).index] = i
        grid = task.key_grid
        self.grid_codes = np.array(
            [[layout.key(k).index if k != NONE_KEY else -1 for k in row] for row in grid]
        )
        self.cell_positions_mm = cell_positions_mm(task, layout)
        self._frame_origin = np.array(task.frame_origin_mm)
        (x_low, x_high), (y_low, y_high) = task.workspace_mm
        self._workspace_low = np.array([x_low, y_low])
        self._workspace_high = np.array([x_high, y_high])

        goals = len(self.goal_keys)
        self._one_hot_table = np.vstack([np.eye(goals), np.zeros(goals)]).astype(np.float32)
        self._action_one_hot = np.eye(len(DISCRETE_ACTIONS), dtype=np.float32)
        size = OBSERVATION_SIZE_PX
        self.images = np.zeros((n, size, size), dtype=np.uint8)
        self.goal = np.zeros(n, dtype=np.int64)
        self.achieved = np.full(n, -1, dtype=np.int64)  # goal index of the pressed key, -1: none or other
        self.pressed_code = np.full(n, -1, dtype=np.int64)
        self.previous_action = np.zeros((n, task.action_size), dtype=np.float32)
        self.cell = np.zeros((n, 2), dtype=np.int64)  # discrete
        self.position_mm = np.zeros((n, 2))  # continuous, work frame: commanded (past the edge if overrun)
        self.depth_mm = np.full(n, RESET_TAP_DEPTH_MM)

    # ------------------------------------------------------------ spaces
    def observation_space(self) -> spaces.Dict:
        """Space of one environment's observation."""
        goals = len(self.goal_keys)
        size = OBSERVATION_SIZE_PX
        if self.task.continuous:
            previous = spaces.Box(-1.0, 1.0, (3,), dtype=np.float32)
        else:
            previous = spaces.Box(0.0, 1.0, (len(DISCRETE_ACTIONS),), dtype=np.float32)
        observation = {
            "observation": spaces.Box(0, 255, (size, size, 1), dtype=np.uint8),
            "previous_action": previous,
            "achieved_goal": spaces.Box(0.0, 1.0, (goals,), dtype=np.float32),
            "desired_goal": spaces.Box(0.0, 1.0, (goals,), dtype=np.float32),
        }
        if self.proprio:
            if self.task.continuous:
                low_xy, high_xy = (
                    self._workspace_low + self._frame_origin,
                    self._workspace_high + self._frame_origin,
                )
            else:
                cells = self.cell_positions_mm.reshape(-1, 2)
                low_xy, high_xy = cells.min(axis=0), cells.max(axis=0)
            low = np.array([*low_xy, 0.0], dtype=np.float32)
            high = np.array([*high_xy, PRESS_DEPTH_MM], dtype=np.float32)
            observation[PROPRIO_KEY] = spaces.Box(low, high, (3,), dtype=np.float32)
        return spaces.Dict(observation)

    def action_space(self) -> spaces.Space:
        """Space of one environment's action."""
        if not self.task.continuous:
            return spaces.Discrete(len(DISCRETE_ACTIONS))
        return spaces.Box(-1.0, 1.0, (3,), dtype=np.float32)

    def action_to_mm(self, actions: np.ndarray) -> np.ndarray:
        """Normalised continuous actions in [-1, 1] to (dx, dy, depth) in mm."""
        low_depth, high_depth = self.task.depth_range_mm
        scale = np.array([self.task.max_move_mm, self.task.max_move_mm, (high_depth - low_depth) / 2])
        offset = np.array([0.0, 0.0, (high_depth + low_depth) / 2])
        return actions * scale + offset

    # -------------------------------------------------------- positions
    def sensor_pose_mm(self) -> np.ndarray:
        """(n, 3) keyboard-frame x, y and depth of the last tap."""
        if self.task.continuous:
            xy = self._inside(self.position_mm) + self._frame_origin
        else:
            xy = self.cell_positions_mm[self.cell[:, 0], self.cell[:, 1]]
        return np.concatenate([xy, self.depth_mm[:, None]], axis=-1)

    def rules(self) -> dict[str, str]:
        """The world's rules where they are not ours (``edges``, ``tap_depth``, ``key_grid``): part of
        what the environment's ``world`` records, so that results from another world's rules are told
        apart."""
        rules = {}
        if self.edges != "stop":
            rules["edges"] = self.edges
        if self.tap_depth != "commanded":
            rules["tap_depth"] = self.tap_depth
        if self.task.grid != "rig":
            rules["key_grid"] = self.task.grid
        return rules

    def _inside(self, position_mm: np.ndarray) -> np.ndarray:
        """The nearest work-frame positions within the workspace (where a tap is made)."""
        return np.minimum(np.maximum(position_mm, self._workspace_low), self._workspace_high)

    # ------------------------------------------------------------ resets
    def reset(self, mask: np.ndarray, rng: np.random.Generator, keep_pose: bool = False) -> None:
        """Draw a new goal and start pose for the environments in ``mask`` and tap once.

        ``keep_pose`` keeps the sensor where it is (typing a sequence of keys
        without a reset between them) and only taps there again.
        """
        index = np.flatnonzero(mask)
        if not len(index):
            return
        self.goal[index] = rng.integers(len(self.goal_keys), size=len(index))
        self.achieved[index] = -1
        self.pressed_code[index] = -1
        self.previous_action[index] = 0.0
        if self.task.continuous:
            if not keep_pose:
                self.position_mm[index] = rng.uniform(
                    self._workspace_low, self._workspace_high, (len(index), 2)
                )
            self.depth_mm[index] = RESET_TAP_DEPTH_MM
            xy = self._inside(self.position_mm[index]) + self._frame_origin
            depth = self.depth_mm[index] + self._depth_shift_mm
            images, _ = self.backend.continuous_taps(xy[:, 0], xy[:, 1], depth, rng)
        else:
            if not keep_pose:
                rows, cols = self.grid_codes.shape
                self.cell[index] = np.stack(
                    [rng.integers(rows, size=len(index)), rng.integers(cols, size=len(index))], axis=-1
                )
            images, _ = self._discrete_taps(index, np.zeros(len(index), dtype=bool), rng)
        self.images[index] = images

    def _discrete_taps(self, index: np.ndarray, press: np.ndarray, rng: np.random.Generator):
        r, c = self.cell[index, 0], self.cell[index, 1]
        codes = self.grid_codes[r, c]
        # NONE cells are tapped in the air (depth 0).
        self.depth_mm[index] = np.where(codes < 0, 0.0, np.where(press, PRESS_DEPTH_MM, MOVE_TAP_DEPTH_MM))
        return self.backend.discrete_taps(codes, press, self.cell_positions_mm[r, c], rng)

    # ------------------------------------------------------------- steps
    def check_actions(self, actions: np.ndarray) -> np.ndarray:
        """Validate a batch of actions; returns them as an array (clipped if continuous).

        Raises:
            ValueError: wrong shape, wrong dtype, NaN, or a discrete index out of range.
        """
        actions = np.asarray(actions)
        if self.task.continuous:
            if actions.shape != (self.n, 3):
                raise ValueError(f"expected continuous actions of shape {(self.n, 3)}, got {actions.shape}")
            if not np.issubdtype(actions.dtype, np.number) or np.issubdtype(
                actions.dtype, np.complexfloating
            ):
                raise ValueError(f"continuous actions must be real numbers, got dtype {actions.dtype}")
            if not np.isfinite(actions).all():
                raise ValueError(f"continuous actions must be finite, got {actions.tolist()}")
            return np.minimum(np.maximum(actions.astype(np.float64), -1.0), 1.0)
        if actions.shape != (self.n,):
            raise ValueError(f"expected discrete actions of shape {(self.n,)}, got {actions.shape}")
        if actions.dtype.kind not in "iu":
            raise ValueError(f"discrete actions must be integers, got dtype {actions.dtype}")
        if ((actions < 0) | (actions >= len(DISCRETE_ACTIONS))).any():
            raise ValueError(
                f"discrete actions must be in [0, {len(DISCRETE_ACTIONS)}), got {actions.tolist()}"
            )
        return actions.astype(np.int64)

    def step(self, actions: np.ndarray, active: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Apply checked ``actions`` to the environments in ``active``; returns the rewards (n,)."""
        index = np.flatnonzero(active)
        actions = actions[index]
        if self.task.continuous:
            move = self.action_to_mm(actions)
            moved = self.position_mm[index] + move[:, :2]
            self.position_mm[index] = self._inside(moved) if self.edges == "stop" else moved
            self.depth_mm[index] = move[:, 2]
            xy = self._inside(moved) + self._frame_origin
            depth = move[:, 2] + self._depth_shift_mm  # the dataset backend reads the nearest stored depth
            images, pressed = self.backend.continuous_taps(xy[:, 0], xy[:, 1], depth, rng)
            self.previous_action[index] = actions
        else:
            rows, cols = self.grid_codes.shape
            target = self.cell[index] + _MOVES[actions]
            inside = (target[:, 0] >= 0) & (target[:, 0] < rows) & (target[:, 1] >= 0) & (target[:, 1] < cols)
            self.cell[index] = np.where(inside[:, None], target, self.cell[index])
            press = actions == _PRESS
            images, pressed = self._discrete_taps(index, press, rng)
            self.previous_action[index] = self._action_one_hot[actions]
        self.images[index] = images
        self.pressed_code[index] = pressed
        self.achieved[index] = self._goal_of_code[pressed]  # code -1 maps to the table's last entry (-1)
        rewards = np.zeros(self.n)
        rewards[index] = (self.achieved[index] == self.goal[index]) & (self.achieved[index] >= 0)
        return rewards

    @property
    def terminated(self) -> np.ndarray:
        """Any key press ends an episode."""
        return self.pressed_code >= 0

    # ------------------------------------------------------ observations
    def one_hot(self, goal_index: np.ndarray) -> np.ndarray:
        """Goal indices (-1: none) as float32 one-hot rows (zeros for none)."""
        return self._one_hot_table[goal_index]  # index -1 picks the zero row

    def observations(self) -> dict[str, np.ndarray]:
        """Batched observation arrays (fresh copies)."""
        observations = {
            "observation": self.images[..., None].copy(),
            "previous_action": self.previous_action.copy(),
            "achieved_goal": self.one_hot(self.achieved),
            "desired_goal": self.one_hot(self.goal),
        }
        if self.proprio:
            observations[PROPRIO_KEY] = self.sensor_pose_mm().astype(np.float32)
        return observations

    def pressed_key(self, i: int) -> str | None:
        code = int(self.pressed_code[i])
        return None if code < 0 else self.layout.keys[code].name


def compute_reward(achieved_goal: np.ndarray, desired_goal: np.ndarray, info=None) -> np.ndarray:
    """Reward of pressing ``achieved_goal`` when ``desired_goal`` was wanted (batch-safe on axis -1).

    1.0 where the achieved one-hot equals the desired one (a key was pressed,
    the right one), else 0.0.
    """
    achieved_goal = np.asarray(achieved_goal)
    desired_goal = np.asarray(desired_goal)
    same = np.all(achieved_goal == desired_goal, axis=-1)
    pressed = np.any(achieved_goal > 0.5, axis=-1)
    return (same & pressed).astype(np.float64)
