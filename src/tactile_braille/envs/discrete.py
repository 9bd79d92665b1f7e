"""Typing with discrete moves over the key grid."""

from __future__ import annotations

from typing import ClassVar

from tactile_braille.envs.braille_env import BrailleEnv


class DiscreteBrailleEnv(BrailleEnv):
    """Type a goal key by moving a TacTip over a braille keyboard one key at a time.

    ## Description
    The discrete tasks of Church et al., "Deep Reinforcement Learning for
    Tactile Robotics: Learning to Type on a Braille Keyboard" (RA-L 2020). The
    sensor sits over one cell of a key grid and only feels the key under it:
    it must find the goal key by touch and press it.

    * ``keys="arrows"``: the grid ``[[NONE, UP, NONE], [LEFT, DOWN, RIGHT]]``
      (``tactile_braille/DiscreteArrows-v0``).
    * ``keys="alphabet"``: the QWERTY rows, 4 x 10, SPACE spanning columns
      2-7 of the fourth row (``tactile_braille/DiscreteAlphabet-v0``).

    NONE cells lie off the keys: the sensor touches nothing there.

    ## Action Space
    ``Discrete(5)``: 0 UP, 1 DOWN, 2 LEFT, 3 RIGHT (move to the neighbouring
    cell and tap it; a move off the grid leaves the sensor in place and taps
    again), 4 PRESS (go 8 mm down; the key under the sensor actuates).

    ## Observation Space
    ``Dict`` with ``observation`` (100x100x1 uint8 tactile image, 0 or 255),
    ``previous_action`` (one-hot of the last action, zeros at reset),
    ``achieved_goal`` (one-hot of the pressed key; zeros if none) and
    ``desired_goal`` (one-hot of the goal key), the key order being
    ``env.unwrapped.goal_keys``.

    ## Rewards
    1 for pressing the goal key, 0 otherwise; ``compute_reward(achieved_goal,
    desired_goal, info)`` gives the same for batches (Hindsight Experience Replay).

    ## Starting State
    A random goal key and a random cell, drawn from the environment's
    generator; the first observation is a tap at that cell.

    ## Episode End
    Terminated on any key press (right or wrong); truncated after 25 steps
    (``max_episode_steps`` in the registry).

    ## Arguments
    * ``keys``: ``"arrows"`` or ``"alphabet"``.
    * ``backend``: ``"dataset"`` (the paper's simulation: a random stored image
      of the cell's key, default), ``"render"`` (the live TacTip renderer at
      the perturbed pose) or ``"rig"`` (any ``Rig``, with ``rig=...``).
    * ``dataset``: a perturbed-taps dataset or its path (default: the cached
      ``keys-train``, generated on first use).
    * ``sensor``: sensor preset of the default dataset or renderer.
    * ``render_mode``: ``"rgb_array"`` or ``"human"``.
    * ``proprio``: the observation also holds ``sensor_pose`` (float32 keyboard-frame
      x, y and tap depth in mm, what the arm reports): the ``proprio`` track's
      observation (docs/benchmark.md). Default False: the paper's.
    * ``frame_noise``: ``(mm, degrees)``, ``backend="render"`` only: the work
      frame is off by an error drawn anew at each reset (not with
      ``keep_pose``), offsets uniform within +-mm along x and y and a turn
      within +-degrees about the task's origin; observations report the
      commanded pose. Domain randomisation against calibration errors
      (docs/evaluation.md). Default None: no error.
    * ``edges``: ``"stop"`` only: a move off the key grid leaves the sensor
      where it is, as in the released simulator (``"overrun"`` is the
      continuous tasks').

    ``info`` holds ``is_success``, ``pressed_key``, ``sensor_pose_mm``
    (keyboard frame x, y, depth) and ``goal_key``. ``reset(options={"goal_key":
    "UP"})`` fixes the goal.

    ## Version History
    * v0: initial release.

    Example:
        >>> import gymnasium as gym
        >>> import tactile_braille
        >>> env = gym.make("tactile_braille/DiscreteArrows-v0")
        >>> observation, info = env.reset(seed=0)
        >>> observation["observation"].shape, info["goal_key"] in ("UP", "DOWN", "LEFT", "RIGHT")
        ((100, 100, 1), True)
    """

    continuous: ClassVar[bool] = False
