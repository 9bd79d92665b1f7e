"""Soft actor-critic (Haarnoja et al. 2018) for the continuous tasks, the paper's SAC.

Reads top to bottom: hyperparameters, a tanh-squashed Gaussian policy and twin
Q critics over the paper's encoder (the action joins the goal after the
convolutions), then the three updates: critics towards the soft Bellman
target of the Polyak-averaged targets, the actor through the reparameterised
sample, the temperature towards the target entropy. With ``all_goals`` each
is computed under every goal of each sampled transition, as DQN's and
discrete SAC's all-goals updates.
"""

from __future__ import annotations

import copy
import math

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from tactile_braille.agents.common import (
    POSE_SIZE,
    Agent,
    critic_poses,
    every_goal_rewards,
    network_options,
    spaces_sizes,
)
from tactile_braille.agents.config import SACConfig
from tactile_braille.agents.networks import (
    ContinuousQNetwork,
    GaussianPolicy,
    observation_tensors,
    soft_update,
)
from tactile_braille.agents.replay import GoalOutcomes, SensorPoses
from tactile_braille.supervised.fit import adam


class SACAgent(Agent):
    """SAC with twin critics and automatic temperature, actions in [-1, 1].

    Args:
        observation_space: the task's Dict observation space.
        action_space: its ``Box(-1, 1, (n,))`` action space.
        config: hyperparameters.
        device: torch device.
        precision: ``"fp32"`` or ``"bf16"`` (autocast in the update).
    """

    policy_parts = ("actor",)
    checkpointed = (
        "actor", "critics", "targets", "log_alpha", "actor_optimiser", "critic_optimiser", "alpha_optimiser"
    )  # fmt: skip

    @classmethod
    def replay_extras(cls, config: SACConfig) -> tuple:
        """Every goal's outcome (``all_goals``) and the sensor poses its critics see (``critic_pose``)."""
        return (
            *([GoalOutcomes()] if config.all_goals else []),
            *([SensorPoses()] if config.critic_pose else []),
        )

    def __init__(
        self,
        observation_space: gym.spaces.Dict,
        action_space: gym.spaces.Box,
        config: SACConfig | None = None,
        device: str = "cpu",
        precision: str = "fp32",
    ) -> None:
        super().__init__(device, precision)
        self.action_size = _unit_box_size(action_space, "SAC")
        self.config = config = config or SACConfig()
        sizes = (self.action_size, *spaces_sizes(observation_space), config.hidden)
        actor_options, critic_options = network_options(observation_space, config.layer_norm)
        for options in (actor_options, critic_options):
            options.update(weights_init=config.weights_init, action_scale=config.action_input_scale)
        actor_options["log_std"] = config.log_std
        pose_size = POSE_SIZE if config.critic_pose else 0
        self.critics = nn.ModuleList(
            [ContinuousQNetwork(*sizes, pose_size=pose_size, **critic_options) for _ in range(2)]
        ).to(self.device)
        self.actor = GaussianPolicy(*sizes, **actor_options).to(self.device)
        self.targets = copy.deepcopy(self.critics).requires_grad_(False)
        self.log_alpha = torch.full(
            (1,), math.log(config.initial_alpha), device=self.device, requires_grad=True
        )
        self.actor_optimiser = adam(self.actor.parameters(), config.learning_rate, config.adam_eps)
        self.critic_optimiser = adam(self.critics.parameters(), config.learning_rate, config.adam_eps)
        self.alpha_optimiser = torch.optim.Adam(
            [self.log_alpha], lr=config.alpha_learning_rate, eps=config.adam_eps
        )

    @torch.no_grad()
    def policy_action(
        self,
        observation: dict,
        step: int,
        explore: bool,
        rng: np.random.Generator,
        deterministic: bool = False,
    ) -> np.ndarray:
        """A policy sample while exploring, the squashed mean otherwise (or if ``deterministic``)."""
        sample, _, mean = self.actor(*observation_tensors(observation, self.device))
        return (sample if explore and not deterministic else mean)[0].cpu().numpy().astype(np.float32)

    def update(self, batch: dict[str, np.ndarray]) -> dict[str, float]:
        """One update of the critics, the actor and the temperature (under every goal of each
        transition with ``all_goals``: values (B, goals) where the single-goal update has (B,))."""
        t = self.tensors(batch)
        alpha = self.log_alpha.exp().detach()
        poses, next_poses = critic_poses(t, self.config.critic_pose)
        if self.config.all_goals:
            rewards = every_goal_rewards(t, self.actor.goal_size)
            state = (t["images"], t["previous_actions"])
            next_state = (t["next_images"], t["next_previous_actions"])
            actor, critics = self.actor.every_goal, [critic.every_goal for critic in self.critics]
            targets = [target.every_goal for target in self.targets]
            continues = (self.discount(t) * (1.0 - t["dones"]))[:, None]  # a press ends it under any goal
        else:
            rewards = t["rewards"]
            state = (t["images"], t["goals"], t["previous_actions"])
            next_state = (t["next_images"], t["goals"], t["next_previous_actions"])
            actor, critics, targets = self.actor, list(self.critics), list(self.targets)
            continues = self.discount(t) * (1.0 - t["dones"])
        with self.autocast():
            with torch.no_grad():
                next_actions, next_log_probs, _ = actor(*next_state)
                next_q = torch.min(*(target(*next_state, next_actions, *next_poses) for target in targets))
                target = rewards + continues * (next_q - alpha * next_log_probs)
            critic_loss = sum(F.mse_loss(critic(*state, t["actions"], *poses), target) for critic in critics)
        self.critic_optimiser.zero_grad(set_to_none=True)
        critic_loss.backward()
        self.critic_optimiser.step()

        self.critics.requires_grad_(False)  # the actor's loss moves the actor only
        with self.autocast():
            actions, log_probs, _ = actor(*state)
            q = torch.min(*(critic(*state, actions, *poses) for critic in critics))
            actor_loss = (alpha * log_probs - q).mean()
        self.actor_optimiser.zero_grad(set_to_none=True)
        actor_loss.backward()
        self.actor_optimiser.step()
        self.critics.requires_grad_(True)

        alpha_loss = -(self.log_alpha * (log_probs.detach() + self.config.target_entropy)).mean()
        self.alpha_optimiser.zero_grad(set_to_none=True)
        alpha_loss.backward()
        self.alpha_optimiser.step()

        soft_update(self.critics, self.targets, self.config.tau)
        return {
            "losses/qf_loss": critic_loss.item() / 2,
            "losses/actor_loss": actor_loss.item(),
            "losses/alpha": alpha.item(),
            "losses/entropy": -log_probs.mean().item(),
        }


def _unit_box_size(action_space: gym.Space, algorithm: str) -> int:
    """The size of a flat ``Box(-1, 1)`` action space, or a ValueError."""
    if not (
        isinstance(action_space, gym.spaces.Box)
        and len(action_space.shape) == 1
        and np.all(action_space.low == -1)
        and np.all(action_space.high == 1)
    ):
        raise ValueError(f"{algorithm} needs a flat Box(-1, 1) action space, got {action_space}")
    return int(action_space.shape[0])
