"""The training loop: epochs of environment steps, replay updates, a test each epoch, checkpoints.

:func:`train` reads top to bottom: open the run folder, make the
environments, the agent and its replay, restore the last checkpoint, then
for each epoch collect ``steps_per_epoch`` steps into the replay (random
actions for the first ``start_steps``) with bursts of updates, test the
policy, log the epoch and checkpoint. What the files are and when they are
written: :mod:`~tactile_braille.agents.run`. A run's extensions (the touch
encoder) plug in through :mod:`~tactile_braille.agents.extensions`.
``train(run_dir=..., resume=True)`` continues a run from its last checkpoint;
a config with ``init_from`` starts a new run from another run's agent (a warm start).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from tactile_braille._io import exclusive_lock
from tactile_braille.agents.config import TrainConfig
from tactile_braille.agents.extensions import RunExtension, make_extension
from tactile_braille.agents.registry import agent_spec
from tactile_braille.agents.replay import EpisodeReplayBuffer
from tactile_braille.agents.rollout import evaluate
from tactile_braille.agents.run import (
    LOCK_FILE,
    Counters,
    EpochLog,
    check_init_from,
    check_progress,
    open_run,
    read_config,
    record_world,
    restore_checkpoint,
    run_folder,
    save_checkpoint,
    save_snapshot,
    snapshot_epochs,
    warm_start,
    write_config,
)
from tactile_braille.agents.touch import TouchAgent, feature_space, touch_input_size
from tactile_braille.envs.memory import TapMemory
from tactile_braille.envs.registry import task_of
from tactile_braille.envs.tasks import DISCRETE_ACTIONS
from tactile_braille.supervised.touch import TouchEncoder, TouchEncoderConfig


def train(
    config: TrainConfig | None = None,
    run_dir: str | Path | None = None,
    resume: bool = False,
    progress: bool = True,
    rig=None,
    after_epoch: Callable[[int, Any], None] | None = None,
) -> Path:
    """Train (or, with ``resume``, continue) a run; returns its folder. ``rig``: see :func:`make_env`.
    ``after_epoch(env_steps, agent)``: called after each epoch is logged and checkpointed, with the
    environment steps trained so far and the agent (a search types with it to prune; an exception it
    raises stops the run there; it resumes from its last checkpoint).

    A resume continues from the last checkpoint with the stored settings; a ``config`` given with it
    may change only :data:`~tactile_braille.agents.run.MACHINE_SETTINGS` (``epochs`` extends the run).
    The run's folder is locked for the call: a second writer is refused (``LockedError``).
    """
    run_dir = run_folder(config, run_dir, resume)
    if resume:
        read_config(run_dir)  # a folder that holds no run is refused before its lock is made
        check_progress(run_dir)  # and one whose log lost, tore or changed rows its checkpoint covers
    else:  # a new run's folder is made only for settings that can run
        (config or TrainConfig()).check_rig(rig)
        check_init_from(config or TrainConfig(), run_dir)
    if config is not None:
        check_device(config.device)
        check_dataset(config)
    with exclusive_lock(run_dir / LOCK_FILE, f"the run {run_dir}"):
        config = open_run(config, run_dir, resume, rig)
        check_device(config.device)  # a resume's stored device
        return _train(config, run_dir, resume, progress, rig, after_epoch)


def _train(config: TrainConfig, run_dir: Path, resume: bool, progress: bool, rig, after_epoch) -> Path:
    """The loop of :func:`train`, in the run's folder, its lock held."""
    torch.set_num_threads(config.threads)
    env, test_env = make_env(config, rig), make_env(config, rig)
    record_world(run_dir, env, resume)
    torch.manual_seed(config.seed)  # before the networks are made: the seed fixes their initial weights
    agent = make_agent(config, env)
    buffer = make_replay(config, env)
    rng = np.random.default_rng(config.seed)
    counters = restore_checkpoint(run_dir, agent, buffer, rng) if resume else Counters()
    if config.init_from is not None and counters.env_steps == 0:  # not yet checkpointed: start warm
        warm_start(run_dir, config, agent)
    write_config(run_dir, config)  # a resume's new epochs or machine, once its world and checkpoint are read
    extension = make_extension(config, env, agent, buffer, run_dir)
    episodes = Episodes(env, buffer, extension, rng, config.keep_pose_fraction, config.final_press,
                        resume=counters.episode)  # fmt: skip
    burst, batch_size = config.update_every * config.updates_per_step, config.agent.batch_size
    losses: dict[str, float] = counters.losses
    with EpochLog(
        run_dir, config.epochs, counters.epoch, progress, counters.env_steps if resume else None
    ) as log:
        for epoch in range(counters.epoch, config.epochs):
            started = time.perf_counter()
            for _ in range(config.steps_per_epoch):
                if counters.env_steps < config.start_steps:
                    action = agent.random_action(env.action_space, rng)
                else:
                    action = agent.policy_action(
                        episodes.observation, counters.env_steps, explore=True, rng=rng
                    )
                episodes.step(action)
                counters.env_steps += 1
                extension.after_step(counters.env_steps)
                if updates_due(config, counters.env_steps, buffer):
                    for _ in range(burst):
                        # Merged, so that a loss some updates skip (TD3's delayed actor) keeps its last value.
                        losses.update(agent.update(agent.sample(buffer, batch_size, rng)))
                        counters.updates += 1
            agent.end_epoch()
            train_time = time.perf_counter() - started
            tests = evaluate(agent, test_env, config.evaluation.test_episodes, seed=10_000 * (epoch + 1))
            counters.epoch = epoch
            log.write({
                "epoch": epoch, "env_steps": counters.env_steps, "updates": counters.updates,
                **episodes.take_returns(), **tests, **losses,
                "charts/SPS": config.steps_per_epoch / train_time, "time_s": time.perf_counter() - started,
            })  # fmt: skip
            if epoch in snapshot_epochs(config.epochs, config.evaluation.snapshots):
                save_snapshot(run_dir, agent, epoch)
            if (epoch + 1) % config.checkpoint_every == 0 or epoch + 1 == config.epochs:
                counters.episode, counters.losses = episodes.state(), losses
                save_checkpoint(run_dir, agent, buffer, rng, counters)
            if after_epoch is not None:
                after_epoch(counters.env_steps, agent)
    return run_dir


def check_device(device: str) -> None:
    """Refuse a device this machine does not have, before anything is written."""
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise ValueError(
            f"device {device!r}: CUDA is not available here (torch {torch.__version__}); use cpu"
        )
    if device.startswith("cuda:") and int(device.split(":")[1]) >= torch.cuda.device_count():
        raise ValueError(f"device {device!r}: this machine has {torch.cuda.device_count()} CUDA devices")
    if device == "mps" and not torch.backends.mps.is_available():
        raise ValueError("device 'mps': Apple's Metal backend is not available here; use cpu")


def check_dataset(config: TrainConfig) -> None:
    """Refuse a dataset that is neither a file nor a default dataset's name, before anything is written."""
    from tactile_braille.datasets.cache import DEFAULT_DATASETS

    dataset = config.dataset
    if (
        dataset is None
        or config.backend != "dataset"
        or Path(dataset).exists()
        or dataset in DEFAULT_DATASETS
    ):
        return
    raise ValueError(
        f"dataset {dataset!r}: no such file, nor a default dataset's name ({', '.join(DEFAULT_DATASETS)})"
    )


def updates_due(config: TrainConfig, env_steps: int, buffer: EpisodeReplayBuffer) -> bool:
    """Whether a burst of updates follows this step: after the start steps (or ``update_after``),
    every ``update_every`` steps, once the replay holds a batch."""
    first = config.start_steps if config.update_after is None else config.update_after
    return (
        env_steps >= first and env_steps % config.update_every == 0 and buffer.size >= config.agent.batch_size
    )


class Episodes:
    """The training environment's episodes as they are collected into the replay.

    :meth:`step` acts, stores the transition (with the extension's labels of
    its frame) and starts the next episode when one ends; goals and start poses
    are drawn from the run's generator. With ``keep_pose_fraction`` that share
    of the episodes after the first starts where the last one left the sensor
    (``reset(options={"keep_pose": True})``, as between the keys the paper's
    typing evaluation asks in a row). With ``final_press`` the last step an
    episode's time limit allows presses (:func:`pressing`), whatever was asked.

    :meth:`state` is the episode in progress as a checkpoint keeps it: its
    reset (seed, whether it kept the pose, and the pose it kept) and the
    actions taken so far. ``resume`` (such a state) plays that episode again
    into the environment and the replay, drawing nothing from ``rng``: on the
    dataset backend, whose taps draw only from the environment's own generator,
    it ends where the interrupted run stood.
    """

    def __init__(
        self,
        env: gym.Env,
        buffer: EpisodeReplayBuffer,
        extension: RunExtension,
        rng,
        keep_pose_fraction: float = 0.0,
        final_press: bool = False,
        resume: dict | None = None,
    ) -> None:
        self.env, self.buffer, self.extension, self.rng = env, buffer, extension, rng
        self.keep_pose_fraction = keep_pose_fraction
        self.last_step = env.spec.max_episode_steps if final_press else None
        self.returns: list[float] = []
        self.kept_starts = self.final_presses = 0
        if resume is None:
            self._start(first=True)
            return
        self.kept_starts, self.final_presses = resume["kept_starts"], resume["final_presses"]
        if resume["kept_pose"] is not None:  # the pose the episode kept: where the one before it ended
            self.env.unwrapped.place_sensor(resume["kept_pose"])
        self._reset(resume["seed"], resume["kept_pose"] is not None)
        final_presses = self.final_presses
        for action in resume["actions"]:
            self.step(action)
        self.final_presses = final_presses  # counted when they were first taken

    def _start(self, first: bool = False) -> None:
        seed = int(self.rng.integers(2**31))
        keep = not first and self.keep_pose_fraction > 0 and self.rng.random() < self.keep_pose_fraction
        self.kept_starts += keep
        self._reset(seed, keep)

    def _reset(self, seed: int, keep: bool) -> None:
        kept = self.env.unwrapped.sensor_placement() if keep else None
        self.observation, info = self.env.reset(seed=seed, options={"keep_pose": True} if keep else None)
        self.buffer.start_episode(self.observation, self.extension.label(self.observation, info))
        self.episode_return, self.episode_steps = 0.0, 0
        self._episode = {"seed": seed, "kept_pose": kept, "actions": []}

    def state(self) -> dict:
        """The episode in progress, as ``resume`` takes it (JSON-ready but for NumPy actions)."""
        return {**self._episode, "actions": list(self._episode["actions"]),
                "kept_starts": self.kept_starts, "final_presses": self.final_presses}  # fmt: skip

    def step(self, action) -> None:
        """One environment step, stored; a new episode if it ended."""
        self._episode["actions"].append(np.array(action, copy=True))
        self.episode_steps += 1
        if self.episode_steps == self.last_step:
            action = pressing(self.env.action_space, action)
            self.final_presses += 1
        observation, reward, terminated, truncated, info = self.env.step(action)
        self.buffer.add_step(action, reward, observation, terminated, self.extension.label(observation, info))
        self.observation, self.episode_return = observation, self.episode_return + reward
        if terminated or truncated:
            self.buffer.end_episode()
            self.returns.append(self.episode_return)
            self._start()

    def take_returns(self) -> dict[str, float]:
        """Episodes ended and their mean return since the last call (the epoch's training figures)."""
        returns, self.returns = self.returns, []
        mean = float(np.mean(returns)) if returns else float("nan")
        return {"train/episodes": len(returns), "train/episodic_return": mean}


def pressing(space: gym.Space, action):
    """``action`` made a press: the discrete tasks' PRESS; on the continuous tasks the same move
    with the deepest tap (depth 1 in [-1, 1])."""
    if isinstance(space, gym.spaces.Box):
        action = np.array(action, dtype=np.float32, copy=True)
        action[-1] = 1.0
        return action
    return DISCRETE_ACTIONS.index("PRESS")


def make_env(config: TrainConfig, rig=None, **kwargs: Any) -> gym.Env:
    """The task's environment as the run configures it (other goal-conditioned ids are made as they are).

    ``rig`` is the :class:`~tactile_braille.rigs.base.Rig` that ``backend="rig"`` taps: hardware is
    handed in, not configured, so a run folder never names one. ``kwargs`` go to ``gym.make``
    (``render_mode`` for figures).
    """
    config.check_rig(rig)
    if task_of(config.task) is not None:
        kwargs["backend"] = config.backend
        if config.frame_noise is not None:
            kwargs["frame_noise"] = config.frame_noise
        if config.edges != "stop":
            kwargs["edges"] = config.edges
        if config.tap_depth != "commanded":
            kwargs["tap_depth"] = config.tap_depth
        if config.key_grid != "rig":
            kwargs["key_grid"] = config.key_grid
        if config.dataset is not None:
            kwargs["dataset"] = config.dataset
        if rig is not None:
            kwargs["rig"] = rig
        if config.touch.pose_inputs:
            kwargs["proprio"] = True  # the proprio track's observation: with the arm's pose
    if config.max_episode_steps is not None:
        kwargs["max_episode_steps"] = config.max_episode_steps
    env = gym.make(config.task, **kwargs)
    return TapMemory(env, config.taps) if config.taps > 1 else env


def make_agent(config: TrainConfig, env: gym.Env):
    """The run's agent (:func:`~tactile_braille.agents.registry.agent_spec`'s class) for the task's spaces
    (a :class:`TouchAgent` around it with ``touch.enabled``)."""
    spec = agent_spec(config.algo)
    if not spec.acts_in(isinstance(env.action_space, gym.spaces.Box)):
        raise ValueError(f"{config.algo} cannot act in {config.task}'s action space {env.action_space}")
    agent_class = spec.agent_class
    if not config.touch.enabled:
        return agent_class(
            env.observation_space, env.action_space, config.agent, config.device, config.precision
        )
    keys = env.observation_space["desired_goal"].shape[0]
    touch = config.touch
    encoder = TouchEncoder(keys, TouchEncoderConfig().features, TouchEncoderConfig().hidden, touch.labels)
    positions = None
    learnt = touch.goal_positions and touch.labels == "observation"  # where the goal lies, from touch
    if touch.goal_positions and not learnt:
        layout = env.unwrapped.layout
        positions = np.array([layout.centre_mm(key) for key in env.unwrapped.goal_keys])
    size = touch_input_size(encoder, touch.inputs, touch.pose_inputs, goal_offsets=learnt)
    space = feature_space(env.observation_space, size, goal_positions=positions is not None)
    agent = agent_class(space, env.action_space, config.agent, config.device, config.precision)
    return TouchAgent(
        agent,
        encoder,
        key_positions_mm=positions,
        inputs=touch.inputs,
        pose_inputs=touch.pose_inputs,
        goal_offsets=learnt,
    )


def make_replay(config: TrainConfig, env: gym.Env) -> EpisodeReplayBuffer:
    """The run's replay buffer for the task's spaces, serving what the agent's updates read
    (:meth:`~tactile_braille.agents.common.Agent.replay_extras`)."""
    spaces = env.observation_space
    extras = agent_spec(config.algo).agent_class.replay_extras(config.agent)
    return EpisodeReplayBuffer(
        config.replay.capacity,
        spaces["desired_goal"].shape[0],
        env.action_space.shape if isinstance(env.action_space, gym.spaces.Box) else (),
        spaces["previous_action"].shape[0],
        her=config.replay.her,
        max_episode_steps=max(getattr(env.spec, "max_episode_steps", None) or 0, 100),
        relabel=config.replay.relabel,
        observation_shape=spaces["observation"].shape,
        n_step=config.replay.n_step,
        gamma=config.agent.gamma if config.replay.n_step > 1 else None,
        shift=config.replay.shift,
        extras=extras,
    )
