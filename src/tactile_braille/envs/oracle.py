"""Scripted oracles that type with knowledge of the true sensor pose.

They prove every task solvable in simulation and give the best return a
policy can hope for; they are not baselines (they do not read the tactile
images). :func:`oracle_action`: discrete, the shortest path over the key grid
to a goal cell, then PRESS; continuous, a straight move to the goal key's
centre, then a deep tap. :class:`PoseScript`, the typing yardstick: the same,
but a continuous move that lands on the centre presses on that step.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from tactile_braille.envs.core import _MOVES, _PRESS


def oracle_action(env) -> np.ndarray | int:
    """The oracle's next action for a single braille environment (wrapped or not)."""
    braille = env.unwrapped
    core = braille._core
    goal_key = braille.goal_keys[int(core.goal[0])]
    if braille.task.continuous:
        centre = np.array(core.layout.centre_mm(goal_key)) - np.array(braille.task.frame_origin_mm)
        offset = centre - core.position_mm[0]
        max_move = braille.task.max_move_mm
        if np.abs(offset).max() < 0.5:
            return np.array([0.0, 0.0, 1.0], dtype=np.float32)  # press: 8 mm deep
        move = np.clip(offset / max_move, -1.0, 1.0)
        return np.array([move[0], move[1], -1.0], dtype=np.float32)  # a light 2 mm tap
    grid = braille.task.key_grid
    start = tuple(int(v) for v in core.cell[0])
    if grid[start] == goal_key:
        return _PRESS
    # Breadth-first search for the nearest cell of the goal key.
    first_move: dict[tuple[int, int], int] = {start: -1}
    queue = deque([start])
    while queue:
        cell = queue.popleft()
        for action, (dr, dc) in enumerate(_MOVES[:_PRESS]):
            nxt = (cell[0] + int(dr), cell[1] + int(dc))
            if not (0 <= nxt[0] < grid.shape[0] and 0 <= nxt[1] < grid.shape[1]) or nxt in first_move:
                continue
            first_move[nxt] = action if first_move[cell] < 0 else first_move[cell]
            if grid[nxt] == goal_key:
                return first_move[nxt]
            queue.append(nxt)
    raise RuntimeError(f"goal key {goal_key!r} is not on the grid")


class PoseScript:
    """A pose-aware typing script, acting through the agents' interface (``policy_action``).

    Discrete tasks: :func:`oracle_action`. Continuous tasks: a straight move
    towards the goal key's centre, pressing (the deepest tap) on the step that
    lands on it and tapping lightly on the way. Its steps are an upper
    yardstick beside :func:`~tactile_braille.evaluation.bounds.typing_bound`'s
    lower one: it presses at key centres, where the bound may press anywhere a
    tap presses the key.
    """

    def __init__(self, env) -> None:
        self.env = env

    def policy_action(self, observation, step, explore, rng, deterministic=False):
        braille = self.env.unwrapped
        if not braille.task.continuous:
            return oracle_action(self.env)
        core = braille._core
        goal = braille.goal_keys[int(core.goal[0])]
        offset = np.array(core.layout.centre_mm(goal)) - braille.task.frame_origin_mm - core.position_mm[0]
        move = offset / braille.task.max_move_mm
        reaches = np.abs(move).max() <= 1.0
        return np.array([*np.clip(move, -1, 1), 1.0 if reaches else -1.0], dtype=np.float32)
