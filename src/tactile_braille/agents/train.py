"""The training loop: epochs of environment steps, replay updates, a test each epoch, checkpoints.

A run lives in ``runs/{task}__{algo}__{seed}__{time}/`` with ``config.json``
(the resolved settings), ``progress.csv`` (one row per epoch) and, after every
epoch, an atomic checkpoint (``checkpoint.pt``: networks, optimiser, counters
and generator states; ``replay.npz``: the replay buffer). ``train(...,
resume=True)`` continues a run from its last checkpoint: a crash or ``kill -9``
costs at most the epoch in progress (its episode restarts on resume).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

from tactile_braille._io import atomic_path
from tactile_braille._registration import ENV_IDS
from tactile_braille.agents.dqn import DQNAgent, DQNConfig
from tactile_braille.agents.replay import EpisodeReplayBuffer
from tactile_braille.agents.sac_discrete import DiscreteSACAgent, DiscreteSACConfig

AGENTS = {"dqn": (DQNAgent, DQNConfig), "sac_discrete": (DiscreteSACAgent, DiscreteSACConfig)}
"""Implemented algorithms: the agent class and its hyperparameter dataclass."""
ALGORITHMS = tuple(AGENTS)
PROGRESS_FIELDS = (
    "epoch", "env_steps", "updates", "train/episodes", "train/episodic_return", "test/episodic_return",
    "test/episode_length", "losses/q_loss", "losses/q_values", "losses/qf_loss", "losses/actor_loss",
    "losses/alpha", "losses/entropy", "charts/SPS", "time_s",
)  # fmt: skip


@dataclass(frozen=True)
class TrainConfig:
    """A training run (defaults: the paper's settings).

    Attributes:
        task: environment id (``tactile_braille/DiscreteArrows-v0``...).
        algo: ``"dqn"`` (double + dueling) or ``"sac_discrete"``.
        seed: seeds networks, exploration, environments.
        epochs: epochs to run.
        steps_per_epoch: environment steps per epoch (250).
        start_steps: uniformly random actions before the policy acts (200).
        updates_per_step: gradient updates per environment step (2).
        replay_capacity: transitions kept (100,000).
        her: hindsight relabelling of wrong presses.
        test_episodes: deterministic test episodes after each epoch.
        backend: environment backend (``dataset`` or ``render``).
        dataset: dataset path for the dataset backend (default: the cached one).
        device: torch device.
        threads: torch CPU threads.
        agent: the algorithm's hyperparameters (default: the paper's for ``algo``).
    """

    task: str = "tactile_braille/DiscreteArrows-v0"
    algo: str = "dqn"
    seed: int = 0
    epochs: int = 25
    steps_per_epoch: int = 250
    start_steps: int = 200
    updates_per_step: int = 2
    replay_capacity: int = 100_000
    her: bool = True
    test_episodes: int = 10
    backend: str = "dataset"
    dataset: str | None = None
    device: str = "cpu"
    threads: int = 2
    agent: DQNConfig | DiscreteSACConfig | None = None

    def __post_init__(self) -> None:
        if self.algo not in ALGORITHMS:
            raise ValueError(f"unknown algorithm {self.algo!r}; implemented: {ALGORITHMS}")
        config_class = AGENTS[self.algo][1]
        if self.agent is None:
            object.__setattr__(self, "agent", config_class())
        elif not isinstance(self.agent, config_class):
            raise ValueError(f"{self.algo} takes a {config_class.__name__}, got {type(self.agent).__name__}")
        if self.task not in gym.registry:
            raise ValueError(f"unknown task {self.task!r}; choose one of {ENV_IDS}")
        if "Continuous" in self.task:
            raise ValueError(f"{self.algo} needs a discrete task, got {self.task}")
        for name in ("epochs", "steps_per_epoch", "test_episodes", "replay_capacity"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")

    def to_json(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, data: dict) -> TrainConfig:
        data = dict(data)
        data["agent"] = AGENTS[data["algo"]][1](**data["agent"])
        return cls(**data)


def _make_env(config: TrainConfig) -> gym.Env:
    kwargs = {"backend": config.backend}
    if config.dataset is not None:
        kwargs["dataset"] = config.dataset
    return gym.make(config.task, **kwargs)


def evaluate(agent, env: gym.Env, episodes: int, seed: int) -> tuple[float, float]:
    """Mean return and length of deterministic (greedy) episodes."""
    rng = np.random.default_rng(seed)
    returns, lengths = [], []
    for episode in range(episodes):
        observation, _ = env.reset(seed=seed + episode)
        total, steps, done = 0.0, 0, False
        while not done:
            action = agent.policy_action(observation, 0, explore=False, rng=rng)
            observation, reward, terminated, truncated, _ = env.step(action)
            total, steps, done = total + reward, steps + 1, terminated or truncated
        returns.append(total)
        lengths.append(steps)
    return float(np.mean(returns)), float(np.mean(lengths))


def train(
    config: TrainConfig | None = None,
    run_dir: str | Path | None = None,
    resume: bool = False,
    progress: bool = True,
) -> Path:
    """Train (or, with ``resume``, continue) a run; returns its folder."""
    if resume:
        if run_dir is None:
            raise ValueError("resume needs the run folder")
        run_dir = Path(run_dir)
        try:
            config = TrainConfig.from_json(json.loads((run_dir / "config.json").read_text()))
        except (OSError, ValueError, KeyError, TypeError) as error:
            raise ValueError(f"{run_dir} is not a resumable run: {error}") from None
    else:
        config = config or TrainConfig()
        stamp = time.strftime("%Y%m%d-%H%M%S")
        run_dir = Path(run_dir or f"runs/{config.task.split('/')[-1]}__{config.algo}__{config.seed}__{stamp}")
        if (run_dir / "config.json").exists():
            raise FileExistsError(f"{run_dir} holds a run already; pass resume=True to continue it")
        run_dir.mkdir(parents=True, exist_ok=True)
        with atomic_path(run_dir / "config.json") as temporary:
            temporary.write_text(json.dumps(config.to_json(), indent=2))
    torch.set_num_threads(config.threads)

    env, test_env = _make_env(config), _make_env(config)
    spaces = env.observation_space
    goal_size = spaces["desired_goal"].shape[0]
    previous_size = spaces["previous_action"].shape[0]
    agent_class = AGENTS[config.algo][0]
    agent = agent_class(env.action_space.n, goal_size, previous_size, config.agent, config.device)
    buffer = EpisodeReplayBuffer(config.replay_capacity, goal_size, (), previous_size, her=config.her)
    rng = np.random.default_rng(config.seed)
    torch.manual_seed(config.seed)
    start_epoch, env_steps, updates = 0, 0, 0
    checkpoint = run_dir / "checkpoint.pt"
    if resume and checkpoint.exists():
        state = torch.load(checkpoint, weights_only=False)
        agent.load_state_dict(state["agent"])
        rng.bit_generator.state = state["rng"]
        torch.set_rng_state(state["torch_rng"])
        start_epoch, env_steps, updates = state["epoch"] + 1, state["env_steps"], state["updates"]
        buffer.load(run_dir / "replay.npz")

    observation, _ = env.reset(seed=int(rng.integers(2**31)))
    buffer.start_episode(observation)
    episode_return, recent_returns, losses = 0.0, [], {}
    for epoch in range(start_epoch, config.epochs):
        started = time.perf_counter()
        for _ in range(config.steps_per_epoch):
            if env_steps < config.start_steps:
                action = int(rng.integers(env.action_space.n))
            else:
                action = agent.policy_action(observation, env_steps, explore=True, rng=rng)
            observation, reward, terminated, truncated, _ = env.step(action)
            buffer.add_step(action, reward, observation, terminated)
            episode_return += reward
            env_steps += 1
            if terminated or truncated:
                buffer.end_episode()
                recent_returns.append(episode_return)
                episode_return = 0.0
                observation, _ = env.reset(seed=int(rng.integers(2**31)))
                buffer.start_episode(observation)
            if env_steps >= config.start_steps and buffer.size >= config.agent.batch_size:
                for _ in range(config.updates_per_step):
                    losses = agent.update(buffer.sample(config.agent.batch_size, rng))
                    updates += 1
        test_return, test_length = evaluate(agent, test_env, config.test_episodes, seed=10_000 * (epoch + 1))
        elapsed = time.perf_counter() - started
        row = {
            "epoch": epoch, "env_steps": env_steps, "updates": updates, "train/episodes": len(recent_returns),
            "train/episodic_return": float(np.mean(recent_returns)) if recent_returns else float("nan"),
            "test/episodic_return": test_return, "test/episode_length": test_length,
            **losses, "charts/SPS": config.steps_per_epoch / elapsed, "time_s": elapsed,
        }  # fmt: skip
        recent_returns = []
        _append_progress(run_dir / "progress.csv", row)
        if progress:
            print(f"epoch {epoch:4d}  steps {env_steps:6d}  test return {test_return:.2f}  "
                  f"length {test_length:4.1f}  {row['charts/SPS']:.0f} steps/s")  # fmt: skip
        buffer.save(run_dir / "replay.npz")  # committed episodes; the one in progress restarts
        with atomic_path(checkpoint, fsync=True) as temporary:
            torch.save(
                {
                    "agent": agent.state_dict(), "rng": rng.bit_generator.state,
                    "torch_rng": torch.get_rng_state(), "epoch": epoch, "env_steps": env_steps,
                    "updates": updates,
                },
                temporary,
            )  # fmt: skip
    return run_dir


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
