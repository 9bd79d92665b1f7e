"""Typing with continuous moves and tap depths."""

from __future__ import annotations

from typing import ClassVar

from tactile_braille.envs.braille_env import BrailleEnv


class ContinuousBrailleEnv(BrailleEnv):
    """Type a goal key by moving a TacTip freely over a braille keyboard and tapping.

    ## Description
    The continuous tasks of Church et al. (RA-L 2020). Each step moves the
    sensor in the plane and taps to a chosen depth: shallow taps feel the
    braille, deep ones press whatever key lies under the dome, which the
    calibrated switch model (``render``/``rig`` backends) or the stored label
    of the nearest grid sample (``dataset`` backend) decides.

    * ``keys="arrows"`` (``tactile_braille/ContinuousArrows-v0``): workspace
      x in [-20, 0], y in [-20, 20] mm around the arrow block.
    * ``keys="alphabet"`` (``tactile_braille/ContinuousAlphabet-v0``):
      x in [-30, 30], y in [-90, 90] mm around the letters.

    ## Action Space
    ``Box(-1, 1, (3,))`` float32, normalised: ``(dx, dy, depth)`` maps to a
    move of ``dx * m``, ``dy * m`` mm with ``m`` = 10 (arrows) or 20 (alphabet)
    and a tap depth of ``5 + 3 * depth`` mm, i.e. [2, 8] (the paper's 0..6
    plus its constant 2 mm). Actions beyond [-1, 1] are clipped; the position
    is clipped to the workspace. NaN, wrong shapes and non-numeric actions
    raise ``ValueError``.

    ## Observation Space
    ``Dict`` with ``observation`` (100x100x1 uint8 tactile image),
    ``previous_action`` (the last clipped normalised action, zeros at reset),
    ``achieved_goal`` (one-hot of the pressed key among the task's keys; zeros
    if none or another key) and ``desired_goal`` (one-hot of the goal).

    ## Rewards
    1 for pressing the goal key, 0 otherwise; ``compute_reward`` is batch-safe.

    ## Starting State
    A random goal and a uniformly random position in the workspace; the first
    observation is a 4 mm tap there.

    ## Episode End
    Terminated on any key press; truncated after 25 steps (registry).

    ## Arguments
    * ``keys``: ``"arrows"`` or ``"alphabet"``.
    * ``backend``: ``"dataset"`` (nearest sample of the cached dense grid, the
      paper's simulation; default), ``"render"`` (live renderer at the exact
      pose, no grid quantisation) or ``"rig"`` (``rig=...``).
    * ``dataset``: a grid dataset or its path (default: cached ``grid-<keys>``).
    * ``sensor``, ``render_mode``: as for the discrete environments.
    * ``proprio``: the observation also holds ``sensor_pose`` (float32 keyboard-frame
      x, y and tap depth in mm, what the arm reports): the ``proprio`` track's
      observation (docs/benchmark.md). Default False: the paper's.
    * ``frame_noise``: ``(mm, degrees)``, ``backend="render"`` only: the work
      frame is off by an error drawn anew at each reset (not with
      ``keep_pose``), offsets uniform within +-mm along x and y and a turn
      within +-degrees about the task's origin; observations report the
      commanded pose. Domain randomisation against calibration errors
      (docs/evaluation.md). Default None: no error.
    * ``edges``: what the workspace's edge does to a move that would cross it.
      ``"stop"`` (default): the sensor stops at the edge, as the real rig's
      safety limits (and the released robot environment) stop the arm.
      ``"overrun"``: the released simulator's rule: the commanded position
      runs on past the edge, the tap is made at the nearest point inside, and
      a move back must first undo the overrun. ``info["sensor_pose_mm"]``
      (and ``sensor_pose``) report the tap's pose either way.
    * ``tap_depth`` (dataset backend): which stored depth a tap reads.
      ``"commanded"`` (default): the sample at the commanded depth.
      ``"released"``: the released simulator's lookup, which compared the
      commanded 2-8 mm with its data's 0-6 mm depth labels: every tap
      (the reset's too) reads the sample 2 mm deeper, the deepest from 6 mm
      on, so shallow taps feel and press like deeper ones.
      ``info["sensor_pose_mm"]`` reports the commanded depth either way.

    ``info`` holds ``is_success``, ``pressed_key``, ``sensor_pose_mm`` and ``goal_key``.

    ## Version History
    * v0: initial release.

    Example:
        >>> import gymnasium as gym
        >>> import tactile_braille
        >>> env = gym.make("tactile_braille/ContinuousArrows-v0")
        >>> observation, info = env.reset(seed=0)
        >>> env.action_space.shape, observation["previous_action"].tolist()
        ((3,), [0.0, 0.0, 0.0])
    """

    continuous: ClassVar[bool] = True
