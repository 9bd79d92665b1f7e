"""What a run may add to the training loop, through one small interface.

The loop (:func:`~tactile_braille.agents.training.train`) asks its extension
for the labels of every frame it stores (:meth:`RunExtension.label`) and
calls it after every environment step (:meth:`RunExtension.after_step`).
The paper's runs add nothing (:class:`RunExtension` itself); a touch-encoder
run (``touch.enabled``, the ``fast`` preset) labels each frame with what the
robot knows and fits its encoder on the labelled frames at its fit steps
(:class:`TouchEncoderFits`).
"""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np

from tactile_braille._io import atomic_path
from tactile_braille.agents.config import TrainConfig
from tactile_braille.envs.core import action_effects
from tactile_braille.supervised.touch import (
    KeyLocator,
    LabelledTaps,
    TouchEncoderConfig,
    Transitions,
    fit_touch_encoder,
    fit_touch_odometry,
    observation_label,
)


class RunExtension:
    """The loop's hooks, doing nothing: the paper's runs."""

    def label(self, observation: dict[str, np.ndarray], info: dict) -> np.ndarray | None:
        """The labels the replay stores with this observation's frame (None: no labels)."""
        return None

    def after_step(self, env_steps: int) -> None:
        """Called after each environment step (and its storing), before the updates."""


class TouchEncoderFits(RunExtension):
    """Fit the touch encoder on every tap so far at :func:`touch_fit_steps`.

    With ``touch.labels="robot"`` every frame is labelled with the sensor pose, the pressed key and the
    key under the sensor (what a calibrated robot knows) and the encoder is fitted to predict them.
    With ``touch.labels="observation"`` nothing outside the observations is recorded: the encoder is
    fitted by touch odometry on the replay's steps (their previous actions and achieved goals,
    :func:`~tactile_braille.supervised.touch.fit_touch_odometry`).

    The first fit starts from fresh weights, each refit from the current ones with as many gradient
    steps as the first (so its cost stays flat as taps accumulate). Each fit replaces the features in
    the replay and is logged in ``touch.json``. A resumed run whose encoder was fitted takes its
    features at once.

    Args:
        config: the run's settings.
        env: its environment (a braille task gives the keyboard to locate keys on).
        agent: a :class:`~tactile_braille.agents.touch.TouchAgent`.
        buffer: its replay buffer (storing images).
        run_dir: the run folder (``touch.json``).
    """

    def __init__(self, config: TrainConfig, env, agent, buffer, run_dir: Path) -> None:
        self.config, self.agent, self.buffer, self.run_dir = config, agent, buffer, run_dir
        self.robot = config.touch.labels == "robot"
        self.continuous = isinstance(env.action_space, gym.spaces.Box)
        braille = hasattr(env.unwrapped, "layout")  # goal-conditioned toys have no keyboard
        locate = braille and self.robot
        self.locate = KeyLocator(env.unwrapped.layout, env.unwrapped.goal_keys) if locate else None
        self.fit_steps = touch_fit_steps(config)
        if agent.fitted:
            buffer.set_encoder(agent.encode, agent.input_size)

    def label(self, observation: dict[str, np.ndarray], info: dict) -> np.ndarray | None:
        return observation_label(observation, info, self.locate) if self.robot else None

    def after_step(self, env_steps: int) -> None:
        if env_steps in self.fit_steps:
            self.fit(env_steps)

    def fit(self, env_steps: int) -> None:
        """Fit (or refit, from the current weights) the encoder on every labelled frame so far."""
        if self.robot:
            taps = LabelledTaps.from_arrays(*self.buffer.labelled_frames())
            fit, count = fit_touch_encoder, len(taps)
        else:
            images, pairs, previous, pressed = self.buffer.frame_pairs()
            effects = action_effects(previous, self.continuous)
            taps = Transitions(images, pairs, effects, pressed)
            fit, count = fit_touch_odometry, len(pairs)
        first = not self.agent.fitted
        epochs = self.config.touch.epochs
        if not first:
            epochs = max(1, round(epochs * self.fit_steps[0] / count))
        encoder, metrics = fit(
            taps, self.buffer.goal_size, TouchEncoderConfig(epochs=epochs), self.config.seed + env_steps,
            self.agent.device, init=None if first else self.agent.touch,
        )  # fmt: skip
        self.agent.fit(encoder)
        self.buffer.set_encoder(self.agent.encode, self.agent.input_size)
        path = self.run_dir / "touch.json"
        fits = json.loads(path.read_text())["fits"] if path.exists() else []
        fits = [
            fit for fit in fits if fit["env_steps"] < env_steps
        ]  # a fit redone after a resume replaces it
        fits.append({**metrics, "env_steps": env_steps})
        with atomic_path(path) as temporary:
            temporary.write_text(json.dumps({"fits": fits}, indent=2))


def touch_fit_steps(config: TrainConfig) -> tuple[int, ...]:
    """Environment steps after which a touch-encoder run fits its encoder: the start steps, then every
    ``touch.refit_every`` steps, ``touch.refits`` times."""
    every = config.touch.refit_every or config.start_steps
    return tuple(config.start_steps + k * every for k in range(config.touch.refits + 1))


def make_extension(config: TrainConfig, env, agent, buffer, run_dir: Path) -> RunExtension:
    """The run's extension: touch-encoder fits for ``touch.enabled``, else none."""
    if config.touch.enabled:
        return TouchEncoderFits(config, env, agent, buffer, run_dir)
    return RunExtension()
