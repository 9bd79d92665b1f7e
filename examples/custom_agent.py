"""Bring your own agent: define, register, train and score it, all in this one file.

The agent below is a small Q-learner that reads each tactile image pooled to
10 x 10, next to the goal and the previous action. It keeps the
:class:`tactile_braille.agents.Agent` contract (``policy_action``, ``update``,
the parts to checkpoint), takes its hyperparameters from an
:class:`~tactile_braille.agents.AgentConfig` dataclass, and is registered with
one :class:`~tactile_braille.agents.AgentSpec`. The project's own training loop
then trains it (replay with hindsight relabelling, test episodes, checkpoints,
``progress.csv``), and :func:`~tactile_braille.evaluation.scoring.evaluate_policy`
types the paper's sequences with it. Nothing under ``src/`` names it.

    python examples/custom_agent.py --epochs 1 --run-dir runs/pooled_q

docs/extending.md walks through it.
"""

from __future__ import annotations

import argparse
import copy
import sys
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from tactile_braille.agents import Agent, AgentConfig, AgentSpec, TrainConfig, register_agent, train
from tactile_braille.agents.report import load_run
from tactile_braille.evaluation.scoring import evaluate_policy


@dataclass(frozen=True)
class PooledQConfig(AgentConfig):
    """Hyperparameters of the pooled-image Q-learner (each becomes an ``--agent.*`` option).

    Attributes:
        gamma: discount.
        learning_rate: Adam's step size.
        batch_size: transitions per update.
        hidden: units of the hidden layer.
        pool: the 100 x 100 image is averaged over blocks of this many pixels a side.
        epsilon_start, epsilon_end: exploration at the start and end of its linear schedule.
        epsilon_decay_steps: environment steps over which epsilon decays.
    """

    gamma: float = 0.9
    learning_rate: float = 1e-3
    batch_size: int = 32
    hidden: tuple[int, ...] = (64,)
    pool: int = 10
    epsilon_start: float = 1.0
    epsilon_end: float = 0.1
    epsilon_decay_steps: int = 1000

    def __post_init__(self) -> None:
        super().__post_init__()  # types, and the usual ranges (gamma, learning_rate, batch_size, ...)
        if 100 % self.pool:
            raise ValueError(f"pool must divide the image's 100 pixels, got {self.pool}")


class PooledQAgent(Agent):
    """Double Q-learning on average-pooled tactile images, the goal and the previous action."""

    checkpointed = ("q", "target", "optimiser")
    policy_parts = ("q",)

    def __init__(self, observation_space, action_space, config=None, device="cpu", precision="fp32") -> None:
        super().__init__(device, precision)
        self.config = config or PooledQConfig()
        self.actions = int(action_space.n)
        cells = (100 // self.config.pool) ** 2
        inputs = (
            cells + observation_space["desired_goal"].shape[0] + observation_space["previous_action"].shape[0]
        )
        layers, size = [], inputs
        for units in self.config.hidden:
            layers += [nn.Linear(size, units), nn.ReLU()]
            size = units
        self.q = nn.Sequential(*layers, nn.Linear(size, self.actions)).to(self.device)
        self.target = copy.deepcopy(self.q).requires_grad_(False)
        self.optimiser = torch.optim.Adam(self.q.parameters(), lr=self.config.learning_rate)

    def _inputs(self, images, goals, previous) -> torch.Tensor:
        """(B, inputs) from images (B, 1, 100, 100) or (B, 100, 100, 1) uint8, goals and previous actions."""
        images = torch.as_tensor(np.asarray(images), device=self.device).float().reshape(-1, 1, 100, 100)
        pooled = F.avg_pool2d(images / 255.0, self.config.pool).flatten(1)
        goals = torch.as_tensor(np.asarray(goals), device=self.device).float().reshape(len(pooled), -1)
        previous = torch.as_tensor(np.asarray(previous), device=self.device).float().reshape(len(pooled), -1)
        return torch.cat([pooled, goals, previous], dim=1)

    @torch.no_grad()
    def policy_action(self, observation, step, explore, rng, deterministic=False) -> int:
        config = self.config
        fraction = min(step / config.epsilon_decay_steps, 1.0)
        epsilon = config.epsilon_start + fraction * (config.epsilon_end - config.epsilon_start)
        if explore and not deterministic and rng.random() < epsilon:
            return int(rng.integers(self.actions))
        inputs = self._inputs(
            observation["observation"], observation["desired_goal"], observation["previous_action"]
        )
        return int(self.q(inputs).argmax(dim=1).item())

    def update(self, batch) -> dict[str, float]:
        t = self.tensors(batch)
        inputs = self._inputs(batch["images"], batch["goals"], batch["previous_actions"])
        following = self._inputs(batch["next_images"], batch["goals"], batch["next_previous_actions"])
        with torch.no_grad():  # double Q: the online network chooses, the target values
            best = self.q(following).argmax(dim=1, keepdim=True)
            bootstrap = self.target(following).gather(1, best).squeeze(1)
            target = t["rewards"] + self.discount(t) * (1.0 - t["dones"]) * bootstrap
        q = self.q(inputs).gather(1, t["actions"].long().unsqueeze(1)).squeeze(1)
        loss = F.smooth_l1_loss(q, target)
        self.optimiser.zero_grad(set_to_none=True)
        loss.backward()
        self.optimiser.step()
        return {"losses/q_loss": float(loss.item())}

    def end_epoch(self) -> None:
        self.target.load_state_dict(self.q.state_dict())  # the target follows once per epoch


POOLED_Q = register_agent(
    AgentSpec(
        name="pooled_q", config=PooledQConfig, agent=PooledQAgent, actions={"discrete"}, label="Pooled Q"
    ),
    replace=True,  # this file may be run or imported more than once in one process
)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--epochs", type=int, default=1)
    parser.add_argument("--steps-per-epoch", type=int, default=250)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--dataset", help="the task's dataset (default: generated and cached on first use)")
    parser.add_argument("--run-dir", default="runs/DiscreteArrows__pooled_q")
    args = parser.parse_args(argv)
    config = TrainConfig(
        task="tactile_braille/DiscreteArrows-v0", algo="pooled_q", seed=args.seed, epochs=args.epochs,
        steps_per_epoch=args.steps_per_epoch, start_steps=min(200, args.steps_per_epoch // 2),
        dataset=args.dataset, threads=1, evaluation={"test_episodes": 5},
    )  # fmt: skip
    run_dir = train(config, run_dir=args.run_dir, resume=False, progress=False)
    _, env, agent = load_run(run_dir)
    report = evaluate_policy(agent, "DiscreteArrows-v0", env=env, seed=args.seed)
    keys, steps = report.keys_asked, report.total_steps
    print(f"{run_dir}: typing accuracy {report.accuracy:.3f} over {keys} keys in {steps} steps")
    return 0


if __name__ == "__main__":
    sys.exit(main())
