"""The training loop: epochs of environment steps, replay updates, a test each epoch, checkpoints.

A run lives in ``runs/{task}__{algo}__{seed}__{time}/`` with ``config.json``
(the resolved settings), ``world.json`` (the dataset or rig it learns from, with
the generator version and the keyboard's and sensor's parameters: a resume in
another world is refused), ``progress.csv`` (one row per epoch), TensorBoard
events (``charts/...``, ``losses/...``, when TensorBoard is installed) and,
every ``checkpoint_every`` epochs, an atomic checkpoint (``checkpoint.pt``:
networks, optimisers, counters and generator states; ``replay.{epoch}.npz``:
the replay buffer it names). ``train(run_dir=..., resume=True)`` continues a run from its
last checkpoint: a crash or ``kill -9`` costs at most the work since then
(the episode in progress restarts on resume).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np
import torch

from tactile_braille._io import atomic_path
from tactile_braille._registration import ENV_IDS
from tactile_braille.agents.common import PRECISIONS
from tactile_braille.agents.dqn import DQNAgent, DQNConfig
from tactile_braille.agents.replay import RELABELLING, EpisodeReplayBuffer
from tactile_braille.agents.sac import SACAgent, SACConfig
from tactile_braille.agents.sac_discrete import DiscreteSACAgent, DiscreteSACConfig
from tactile_braille.agents.td3 import TD3Agent, TD3Config
from tactile_braille.agents.touch import (
    TOUCH_INPUTS,
    KeyLocator,
    LabelledTaps,
    TouchAgent,
    TouchEncoder,
    TouchEncoderConfig,
    feature_space,
    fit_touch_encoder,
    observation_label,
    touch_input_size,
)


class Algorithm(NamedTuple):
    agent: type
    config: type
    continuous: bool


AGENTS = {
    "dqn": Algorithm(DQNAgent, DQNConfig, continuous=False),
    "sac_discrete": Algorithm(DiscreteSACAgent, DiscreteSACConfig, continuous=False),
    "sac": Algorithm(SACAgent, SACConfig, continuous=True),
    "td3": Algorithm(TD3Agent, TD3Config, continuous=True),
}
"""Implemented algorithms: agent class, hyperparameter dataclass, action kind."""
ALGORITHMS = tuple(AGENTS)
AgentConfig = DQNConfig | DiscreteSACConfig | SACConfig | TD3Config
PROGRESS_FIELDS = (
    "epoch", "env_steps", "updates", "train/episodes", "train/episodic_return", "test/episodic_return",
    "test/episode_length", "test/success_rate", "losses/q_loss", "losses/q_values", "losses/qf_loss",
    "losses/actor_loss", "losses/alpha", "losses/entropy", "charts/SPS", "time_s",
)  # fmt: skip


@dataclass(frozen=True)
class TrainConfig:
    """A training run. Defaults are the paper's; :mod:`~tactile_braille.agents.presets` sets the rest.

    Attributes:
        task: environment id (``tactile_braille/DiscreteArrows-v0``...).
        algo: ``"dqn"``, ``"sac_discrete"``, ``"sac"`` or ``"td3"``.
        seed: seeds networks, exploration and environments.
        epochs: epochs to run.
        steps_per_epoch: environment steps per epoch (250).
        start_steps: uniformly random actions before the policy acts, and
            before updates start (200).
        updates_per_step: gradient updates per environment step (None: 2, TD3 1).
        update_every: updates happen in bursts every this many steps
            (``update_every * updates_per_step`` at a time; the released TD3 used 100).
        replay_capacity: transitions kept (100,000).
        her: hindsight relabelling.
        relabel: ``"paper"`` (copies of wrong-press episodes, the paper's) or
            ``"all"`` (every transition for every goal, relabelled when sampled;
            :mod:`~tactile_braille.agents.replay`).
        touch_encoder: label every frame with the sensor pose and keys (what the robot
            knows), fit a touch encoder on the labelled frames after ``start_steps`` and learn on
            its features (:mod:`~tactile_braille.agents.touch`); not the paper's.
        touch_epochs: passes of the touch encoder's first fit over those taps.
        touch_inputs: what the agent learns on: the encoder's ``"features"`` or its ``"readout"``
            (pose and key probabilities, whose meaning survives a refit; :meth:`TouchEncoder.read`).
        goal_positions: with ``touch_encoder``, the agent also sees where its goal key lies on the
            calibrated layout, in the coordinates of the pose the encoder learns (:class:`TouchAgent`).
        touch_refits: refits of the touch encoder on all labelled frames so far, every
            ``touch_refit_every`` steps after the first fit (each as many gradient steps as the first fit).
        touch_refit_every: environment steps between refits (None: ``start_steps``).
        test_episodes: deterministic test episodes after each epoch.
        max_episode_steps: episode cut (None: the registry's 25).
        backend: environment backend (``dataset``, ``render``, or ``rig``: a robot, ``train(rig=...)``).
        dataset: dataset path for the dataset backend (default: the cached one).
        device: torch device (``cpu``, ``cuda``).
        precision: ``fp32`` or ``bf16`` (autocast in the updates).
        threads: torch CPU threads.
        checkpoint_every: epochs between checkpoints.
        snapshots: policy snapshots kept (``snapshots/epoch_NNNN.pt``), spread
            evenly from the first epoch to the last (for trajectory figures).
        preset: name of the preset the settings came from (a record only).
        agent: the algorithm's hyperparameters (default: the paper's for ``algo``).
    """

    task: str = "tactile_braille/DiscreteArrows-v0"
    algo: str = "dqn"
    seed: int = 0
    epochs: int = 25
    steps_per_epoch: int = 250
    start_steps: int = 200
    updates_per_step: int | None = None
    update_every: int = 1
    replay_capacity: int = 100_000
    her: bool = True
    relabel: str = "paper"
    touch_encoder: bool = False
    touch_epochs: int = 40
    goal_positions: bool = False
    touch_inputs: str = "features"
    touch_refits: int = 0
    touch_refit_every: int | None = None
    test_episodes: int = 20
    max_episode_steps: int | None = None
    backend: str = "dataset"
    dataset: str | None = None
    device: str = "cpu"
    precision: str = "fp32"
    threads: int = 2
    checkpoint_every: int = 1
    snapshots: int = 3
    preset: str | None = None
    agent: AgentConfig | None = None

    def __post_init__(self) -> None:
        if self.algo not in ALGORITHMS:
            raise ValueError(f"unknown algorithm {self.algo!r}; implemented: {ALGORITHMS}")
        algorithm = AGENTS[self.algo]
        if self.agent is None:
            object.__setattr__(self, "agent", algorithm.config())
        elif not isinstance(self.agent, algorithm.config):
            raise ValueError(
                f"{self.algo} takes a {algorithm.config.__name__}, got {type(self.agent).__name__}"
            )
        if self.updates_per_step is None:
            object.__setattr__(self, "updates_per_step", 1 if self.algo == "td3" else 2)
        if self.task not in gym.registry:
            raise ValueError(f"unknown task {self.task!r}; choose one of {ENV_IDS}")
        braille = self.task.startswith("tactile_braille/")
        if braille and ("Continuous" in self.task) != algorithm.continuous:
            kind = "continuous" if algorithm.continuous else "discrete"
            raise ValueError(f"{self.algo} needs a {kind} task, got {self.task}")
        if self.precision not in PRECISIONS:
            raise ValueError(f"precision must be one of {PRECISIONS}, got {self.precision!r}")
        for name in ("epochs", "steps_per_epoch", "test_episodes", "replay_capacity", "update_every",
                     "checkpoint_every", "threads"):  # fmt: skip
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        for name in ("start_steps", "updates_per_step", "snapshots"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must not be negative, got {getattr(self, name)}")
        if self.relabel not in RELABELLING:
            raise ValueError(f"relabel must be one of {RELABELLING}, got {self.relabel!r}")
        if self.touch_encoder and self.start_steps < 10:
            raise ValueError(
                f"a touch encoder learns from the start steps: need at least 10, got {self.start_steps}"
            )
        if getattr(self.agent, "critic_pose", False) and not self.touch_encoder:
            raise ValueError(
                "critic_pose (asymmetric critics) learns from the labelled frames of a touch-encoder run: "
                "set touch_encoder too"
            )
        if self.touch_inputs not in TOUCH_INPUTS:
            raise ValueError(f"touch_inputs must be one of {TOUCH_INPUTS}, got {self.touch_inputs!r}")
        if self.touch_inputs != "features" and not self.touch_encoder:
            raise ValueError(
                f"touch_inputs={self.touch_inputs!r} reads a touch encoder: set touch_encoder too"
            )
        if self.goal_positions and not self.touch_encoder:
            raise ValueError(
                "goal_positions places the goal keys in the touch encoder's pose coordinates: "
                "set touch_encoder too"
            )
        if self.goal_positions and not braille:
            raise ValueError(f"goal_positions needs a braille task (a keyboard layout), got {self.task}")
        if self.touch_refit_every is not None and self.touch_refit_every < 1:
            raise ValueError(f"touch_refit_every must be at least 1, got {self.touch_refit_every}")
        if self.touch_refits < 0:
            raise ValueError(f"touch_refits must not be negative, got {self.touch_refits}")
        if self.touch_epochs < 1:
            raise ValueError(f"touch_epochs must be at least 1, got {self.touch_epochs}")
        if self.max_episode_steps is not None and self.max_episode_steps < 1:
            raise ValueError(f"max_episode_steps must be at least 1, got {self.max_episode_steps}")

    def to_json(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, data: dict) -> TrainConfig:
        data = dict(data)
        agent = {
            key: tuple(value) if isinstance(value, list) else value for key, value in data["agent"].items()
        }
        data["agent"] = AGENTS[data["algo"]].config(**agent)
        return cls(**data)

    def with_changes(self, **changes: Any) -> TrainConfig:
        """A copy with fields changed (``agent`` as a dict of hyperparameters to change)."""
        agent_changes = changes.pop("agent", None)
        if agent_changes:
            changes["agent"] = dataclasses.replace(self.agent, **agent_changes)
        return dataclasses.replace(self, **changes)


def make_env(config: TrainConfig, rig=None) -> gym.Env:
    """The task's environment as the run configures it (other goal-conditioned ids are made as they are).

    ``rig`` is the :class:`~tactile_braille.rigs.base.Rig` that ``backend="rig"`` taps: hardware is
    handed in, not configured, so a run folder never names one.
    """
    kwargs: dict[str, Any] = {}
    if config.task.startswith("tactile_braille/"):
        kwargs["backend"] = config.backend
        if config.dataset is not None:
            kwargs["dataset"] = config.dataset
        if rig is not None:
            kwargs["rig"] = rig
    if config.max_episode_steps is not None:
        kwargs["max_episode_steps"] = config.max_episode_steps
    return gym.make(config.task, **kwargs)


def make_agent(config: TrainConfig, env: gym.Env):
    """The run's agent for the task's spaces (a :class:`TouchAgent` with ``touch_encoder``)."""
    algorithm = AGENTS[config.algo]
    if isinstance(env.action_space, gym.spaces.Box) != algorithm.continuous:
        raise ValueError(f"{config.algo} cannot act in {config.task}'s action space {env.action_space}")
    if not config.touch_encoder:
        return algorithm.agent(
            env.observation_space, env.action_space, config.agent, config.device, config.precision
        )
    keys = env.observation_space["desired_goal"].shape[0]
    encoder = TouchEncoder(keys, TouchEncoderConfig().features, TouchEncoderConfig().hidden)
    positions = None
    if config.goal_positions:
        layout = env.unwrapped.layout
        positions = np.array([layout.centre_mm(key) for key in env.unwrapped.goal_keys])
    size = touch_input_size(encoder, config.touch_inputs)
    space = feature_space(env.observation_space, size, goal_positions=positions is not None)
    agent = algorithm.agent(space, env.action_space, config.agent, config.device, config.precision)
    return TouchAgent(agent, encoder, key_positions_mm=positions, inputs=config.touch_inputs)


def evaluate(agent, env: gym.Env, episodes: int, seed: int) -> dict[str, float]:
    """Mean return, length and success rate of test episodes (the agent's test-time actions)."""
    rng = np.random.default_rng(seed)
    returns, lengths, successes = [], [], []
    for episode in range(episodes):
        observation, _ = env.reset(seed=seed + episode)
        total, steps, done, info = 0.0, 0, False, {}
        while not done:
            action = agent.policy_action(observation, 0, explore=False, rng=rng)
            observation, reward, terminated, truncated, info = env.step(action)
            total, steps, done = total + reward, steps + 1, terminated or truncated
        returns.append(total)
        lengths.append(steps)
        successes.append(float(info.get("is_success", total > 0)))
    return {
        "test/episodic_return": float(np.mean(returns)),
        "test/episode_length": float(np.mean(lengths)),
        "test/success_rate": float(np.mean(successes)),
    }


def _open_run(
    config: TrainConfig | None, run_dir: str | Path | None, resume: bool
) -> tuple[TrainConfig, Path]:
    if resume:
        if run_dir is None:
            raise ValueError("resume needs the run folder")
        run_dir = Path(run_dir)
        try:
            config = TrainConfig.from_json(json.loads((run_dir / "config.json").read_text()))
        except (OSError, ValueError, KeyError, TypeError) as error:
            raise ValueError(f"{run_dir} is not a resumable run: {error}") from None
        return config, run_dir
    config = config or TrainConfig()
    stamp = time.strftime("%Y%m%d-%H%M%S")
    run_dir = Path(run_dir or f"runs/{config.task.split('/')[-1]}__{config.algo}__{config.seed}__{stamp}")
    if (run_dir / "config.json").exists():
        raise FileExistsError(f"{run_dir} holds a run already; resume it or choose another folder")
    run_dir.mkdir(parents=True, exist_ok=True)
    with atomic_path(run_dir / "config.json") as temporary:
        temporary.write_text(json.dumps(config.to_json(), indent=2))
    return config, run_dir


WORLD_FILE = "world.json"
"""Where a run records the world it learns in (:attr:`BrailleEnv.world`)."""


def _record_world(run_dir: Path, env: gym.Env, resume: bool) -> None:
    """Write the run's world, or check that a resumed run continues in the world it started in.

    A run from before worlds were recorded is resumed without a record: what
    it started in is unknown, and recording the present world would claim it.
    """
    from tactile_braille.envs.braille_env import BrailleEnv

    if not isinstance(env.unwrapped, BrailleEnv):  # goal-conditioned toys have no tactile world
        return
    world = json.loads(json.dumps(env.unwrapped.world))  # as stored: tuples become lists
    path = run_dir / WORLD_FILE
    if path.exists():
        stored = json.loads(path.read_text())
        stored.pop("dataset", None)  # where the dataset lies may change; what it holds may not
        differ = _differences(stored, {k: v for k, v in world.items() if k != "dataset"})
        if differ:
            shown = "; ".join(differ[:3]) + (f"; and {len(differ) - 3} more" if len(differ) > 3 else "")
            raise ValueError(
                f"{run_dir} was trained in another world than this one ({shown}); "
                "start a new run instead of resuming it"
            )
        return
    if resume and (run_dir / "checkpoint.pt").exists():
        return
    with atomic_path(path) as temporary:
        temporary.write_text(json.dumps(world, indent=2, sort_keys=True))


def _differences(stored, now, path: str = "") -> list[str]:
    """``path: stored -> now`` for each leaf in which two JSON values differ."""
    if isinstance(stored, dict) and isinstance(now, dict):
        return [
            line
            for key in sorted(set(stored) | set(now))
            for line in _differences(stored.get(key), now.get(key), f"{path}.{key}" if path else key)
        ]
    return [] if stored == now else [f"{path or 'world'}: {json.dumps(stored)} -> {json.dumps(now)}"]


def run_world(run_dir: str | Path) -> dict | None:
    """The world a run recorded, or ``None`` for a run from before worlds were recorded."""
    path = Path(run_dir) / WORLD_FILE
    return json.loads(path.read_text()) if path.exists() else None


def _tensorboard(run_dir: Path):
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError:  # TensorBoard is optional; the CSV log is always written
        return None
    return SummaryWriter(str(run_dir))


def train(
    config: TrainConfig | None = None,
    run_dir: str | Path | None = None,
    resume: bool = False,
    progress: bool = True,
    rig=None,
) -> Path:
    """Train (or, with ``resume``, continue) a run; returns its folder. ``rig``: see :func:`make_env`."""
    config, run_dir = _open_run(config, run_dir, resume)
    torch.set_num_threads(config.threads)
    env, test_env = make_env(config, rig), make_env(config, rig)
    _record_world(run_dir, env, resume)
    torch.manual_seed(config.seed)  # before the networks are made: the seed fixes their initial weights
    agent = make_agent(config, env)
    action_shape = env.action_space.shape if AGENTS[config.algo].continuous else ()  # checked by make_agent
    checkpoint = run_dir / "checkpoint.pt"
    state = None
    if resume and checkpoint.exists():
        state = torch.load(checkpoint, weights_only=False, map_location=agent.device)
        agent.load_state_dict(state["agent"])
    touch = isinstance(agent, TouchAgent)
    buffer = EpisodeReplayBuffer(
        config.replay_capacity,
        env.observation_space["desired_goal"].shape[0],
        action_shape,
        env.observation_space["previous_action"].shape[0],
        her=config.her,
        max_episode_steps=max(getattr(env.spec, "max_episode_steps", None) or 0, 100),
        relabel=config.relabel,
        poses=getattr(config.agent, "critic_pose", False),
    )
    # A touch-encoder run labels every frame with what the robot knows (pose, pressed key, key under
    # the sensor) and fits its encoder on the labelled frames at the fit steps.
    braille = hasattr(env.unwrapped, "layout")  # goal-conditioned toys have no keyboard to locate keys on
    locate = KeyLocator(env.unwrapped.layout, env.unwrapped.goal_keys) if touch and braille else None
    fit_steps = touch_fit_steps(config) if touch else ()
    rng = np.random.default_rng(config.seed)
    start_epoch, env_steps, updates = 0, 0, 0
    if state is not None:
        rng.bit_generator.state = state["rng"]
        torch.set_rng_state(state["torch_rng"].cpu())
        if state.get("cuda_rng") is not None and torch.cuda.is_available():
            torch.cuda.set_rng_state_all([s.cpu() for s in state["cuda_rng"]])
        start_epoch, env_steps, updates = state["epoch"] + 1, state["env_steps"], state["updates"]
        buffer.load(run_dir / state["replay"])
    if touch and agent.fitted:
        buffer.set_encoder(agent.encode, agent.input_size)

    def label(observation: dict[str, np.ndarray], info: dict) -> np.ndarray | None:
        return observation_label(observation, info, locate) if touch else None

    def fit_touch() -> None:
        """Fit (or refit, from the current weights) the touch encoder on every labelled frame so far."""
        taps = LabelledTaps.from_arrays(*buffer.labelled_frames())
        first = not agent.fitted
        # A refit sees more taps: as many gradient steps as the first fit, so its cost stays flat.
        epochs = (
            config.touch_epochs if first else max(1, round(config.touch_epochs * fit_steps[0] / len(taps)))
        )
        encoder, metrics = fit_touch_encoder(
            taps, buffer.goal_size, TouchEncoderConfig(epochs=epochs), config.seed + env_steps, agent.device,
            init=None if first else agent.touch,
        )  # fmt: skip
        agent.fit(encoder)
        buffer.set_encoder(agent.encode, agent.input_size)
        path = run_dir / "touch.json"
        fits = json.loads(path.read_text())["fits"] if path.exists() else []
        fits = [
            fit for fit in fits if fit["env_steps"] < env_steps
        ]  # a fit redone after a resume replaces its first
        fits.append({**metrics, "env_steps": env_steps})
        with atomic_path(path) as temporary:
            temporary.write_text(json.dumps({"fits": fits}, indent=2))

    def random_action():
        if action_shape:
            return rng.uniform(-1.0, 1.0, size=action_shape).astype(np.float32)
        return int(rng.integers(env.action_space.n))

    writer = _tensorboard(run_dir)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=config.epochs, initial=start_epoch, desc=run_dir.name, unit="epoch")
    observation, info = env.reset(seed=int(rng.integers(2**31)))
    buffer.start_episode(observation, label(observation, info))
    episode_return, recent_returns, losses = 0.0, [], {}
    burst = config.update_every * config.updates_per_step
    try:
        for epoch in range(start_epoch, config.epochs):
            started = time.perf_counter()
            for _ in range(config.steps_per_epoch):
                if env_steps < config.start_steps:
                    action = random_action()
                else:
                    action = agent.policy_action(observation, env_steps, explore=True, rng=rng)
                observation, reward, terminated, truncated, info = env.step(action)
                buffer.add_step(action, reward, observation, terminated, label(observation, info))
                episode_return += reward
                env_steps += 1
                if terminated or truncated:
                    buffer.end_episode()
                    recent_returns.append(episode_return)
                    episode_return = 0.0
                    observation, info = env.reset(seed=int(rng.integers(2**31)))
                    buffer.start_episode(observation, label(observation, info))
                if env_steps in fit_steps:
                    fit_touch()
                if (
                    env_steps >= config.start_steps
                    and env_steps % config.update_every == 0
                    and buffer.size >= config.agent.batch_size
                ):
                    for _ in range(burst):
                        # Merged, so that a loss some updates skip (TD3's delayed actor) keeps its last value.
                        losses.update(agent.update(buffer.sample(config.agent.batch_size, rng)))
                        updates += 1
            train_time = time.perf_counter() - started
            tests = evaluate(agent, test_env, config.test_episodes, seed=10_000 * (epoch + 1))
            row = {
                "epoch": epoch, "env_steps": env_steps, "updates": updates,
                "train/episodes": len(recent_returns),
                "train/episodic_return": float(np.mean(recent_returns)) if recent_returns else float("nan"),
                **tests, **losses, "charts/SPS": config.steps_per_epoch / train_time,
                "time_s": time.perf_counter() - started,
            }  # fmt: skip
            recent_returns = []
            _append_progress(run_dir / "progress.csv", row)
            if writer is not None:
                for key, value in row.items():
                    if "/" in key:
                        writer.add_scalar(key if key.startswith(("charts", "losses")) else f"charts/{key}",
                                          value, env_steps)  # fmt: skip
                writer.flush()
            if bar is not None:
                bar.set_postfix(test_return=f"{tests['test/episodic_return']:.2f}",
                                sps=f"{row['charts/SPS']:.0f}")  # fmt: skip
                bar.update(1)
            if epoch in snapshot_epochs(config.epochs, config.snapshots):
                (run_dir / "snapshots").mkdir(exist_ok=True)
                with atomic_path(run_dir / "snapshots" / f"epoch_{epoch:04d}.pt") as temporary:
                    torch.save(agent.policy_state_dict(), temporary)
            if (epoch + 1) % config.checkpoint_every == 0 or epoch + 1 == config.epochs:
                _save_checkpoint(run_dir, agent, buffer, rng, epoch, env_steps, updates)
    finally:
        if bar is not None:
            bar.close()
        if writer is not None:
            writer.close()
    return run_dir


def snapshot_epochs(epochs: int, snapshots: int) -> set[int]:
    """Epochs after which a policy snapshot is kept: ``snapshots`` of them, first to last."""
    if snapshots <= 0:
        return set()
    return {round(float(e)) for e in np.linspace(0, epochs - 1, min(snapshots, epochs))}


def touch_fit_steps(config: TrainConfig) -> tuple[int, ...]:
    """Environment steps after which a touch-encoder run fits its encoder: the start steps, then every
    ``touch_refit_every`` steps, ``touch_refits`` times."""
    every = config.touch_refit_every or config.start_steps
    return tuple(config.start_steps + k * every for k in range(config.touch_refits + 1))


def _save_checkpoint(run_dir: Path, agent, buffer, rng, epoch: int, env_steps: int, updates: int) -> None:
    """Write the replay buffer, then the checkpoint that names it, then drop older buffers.

    Each step is atomic, so a crash anywhere leaves the previous checkpoint and
    the buffer it names intact. The episode in progress is not saved: it
    restarts on resume.
    """
    replay = f"replay.{epoch}.npz"
    buffer.save(run_dir / replay)
    state = {
        "agent": agent.state_dict(), "rng": rng.bit_generator.state, "torch_rng": torch.get_rng_state(),
        "cuda_rng": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else None,
        "epoch": epoch, "env_steps": env_steps, "updates": updates, "replay": replay,
    }  # fmt: skip
    with atomic_path(run_dir / "checkpoint.pt", fsync=True) as temporary:
        torch.save(state, temporary)
    for old in run_dir.glob("replay.*.npz"):
        if old.name != replay:
            old.unlink()


def setting_differences(run_dir: str | Path, config: TrainConfig) -> list[str]:
    """The settings, epochs aside, in which the run in ``run_dir`` differs from ``config``.

    The stored config.json is read through :class:`TrainConfig`, so a run written before a setting
    existed compares with that setting's default (the behaviour it was trained with).
    """
    stored = TrainConfig.from_json(json.loads((Path(run_dir) / "config.json").read_text()))
    stored = json.loads(json.dumps(stored.to_json()))
    wanted = json.loads(json.dumps(config.to_json()))
    return sorted(key for key in wanted if key != "epochs" and stored.get(key) != wanted[key])


def read_progress(run_dir: str | Path) -> list[dict[str, float]]:
    """The run's per-epoch log as a list of rows (numbers as floats, blanks as NaN)."""
    with open(Path(run_dir) / "progress.csv", newline="") as handle:
        return [
            {key: float(value) if value not in ("", None) else float("nan") for key, value in row.items()}
            for row in csv.DictReader(handle)
        ]


def _append_progress(path: Path, row: dict) -> None:
    """Append one epoch to the CSV log (rows of epochs already logged are replaced on resume)."""
    rows = []
    if path.exists():
        with open(path, newline="") as handle:
            rows = [r for r in csv.DictReader(handle) if int(r["epoch"]) < row["epoch"]]
    rows.append(row)
    with atomic_path(path) as temporary, open(temporary, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=PROGRESS_FIELDS, restval="")
        writer.writeheader()
        writer.writerows(rows)
