"""Soft actor-critic for discrete actions (Christodoulou 2019), the paper's SAC_DISC.

Reads top to bottom: hyperparameters, a categorical policy over the paper's
encoder, twin critics with Polyak-averaged targets, and the three updates
(critics, actor, temperature). Expectations over actions are exact sums over
the categorical distribution, so no reparameterisation is needed. With
``all_goals`` each of the three is computed under every goal at once (values
of shape (batch, goals, actions) where the single-goal update has (batch,
actions)), as DQN's all-goals update.
"""

from __future__ import annotations

import copy
import math

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from tactile_braille.agents.common import Agent, chosen, every_goal_rewards, network_options, spaces_sizes
from tactile_braille.agents.config import DiscreteSACConfig
from tactile_braille.agents.networks import DuelingQNetwork, PolicyNetwork, observation_tensors, soft_update
from tactile_braille.agents.replay import GoalOutcomes
from tactile_braille.supervised.fit import adam


class DiscreteSACAgent(Agent):
    """Discrete soft actor-critic with automatic temperature.

    Args:
        observation_space: the task's Dict observation space.
        action_space: its ``Discrete`` action space.
        config: hyperparameters.
        device: torch device.
        precision: ``"fp32"`` or ``"bf16"`` (autocast in the update).
    """

    policy_parts = ("actor",)
    checkpointed = (
        "actor", "critics", "targets", "log_alpha", "actor_optimiser", "critic_optimiser", "alpha_optimiser"
    )  # fmt: skip

    @classmethod
    def replay_extras(cls, config: DiscreteSACConfig) -> tuple:
        """Every goal's outcome where it updates every goal (``all_goals``)."""
        return (GoalOutcomes(),) if config.all_goals else ()

    def __init__(
        self,
        observation_space: gym.spaces.Dict,
        action_space: gym.spaces.Discrete,
        config: DiscreteSACConfig | None = None,
        device: str = "cpu",
        precision: str = "fp32",
    ) -> None:
        super().__init__(device, precision)
        if not isinstance(action_space, gym.spaces.Discrete):
            raise ValueError(f"discrete SAC needs a Discrete action space, got {action_space}")
        self.config = config = config or DiscreteSACConfig()
        self.num_actions = int(action_space.n)
        sizes = (self.num_actions, *spaces_sizes(observation_space), config.hidden)
        actor_options, critic_options = network_options(observation_space, config.layer_norm)
        actor_options["goal_heads"] = critic_options["goal_heads"] = config.goal_heads
        actor_options["weights_init"] = critic_options["weights_init"] = config.weights_init
        critic_options["dueling"] = config.dueling
        self.critics = nn.ModuleList([DuelingQNetwork(*sizes, **critic_options) for _ in range(2)]).to(
            self.device
        )
        self.actor = PolicyNetwork(*sizes, **actor_options).to(self.device)
        self.targets = copy.deepcopy(self.critics).requires_grad_(False)
        self.log_alpha = torch.full(
            (1,), math.log(config.initial_alpha), device=self.device, requires_grad=True
        )
        self.target_entropy = config.target_entropy_ratio * math.log(self.num_actions)
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
    ) -> int:
        """A sampled action while exploring, the most probable one otherwise (or if ``deterministic``)."""
        probabilities = self.actor(*observation_tensors(observation, self.device))[0][0].cpu().numpy()
        if explore and not deterministic:
            return int(rng.choice(self.num_actions, p=probabilities / probabilities.sum()))
        return int(probabilities.argmax())

    def update(self, batch: dict[str, np.ndarray]) -> dict[str, float]:
        """One update of the critics, the actor and the temperature."""
        t = self.tensors(batch)
        alpha = self.log_alpha.exp().detach()
        values = self._every_goal_values if self.config.all_goals else self._values
        with self.autocast():
            q_values, target = values(t, alpha)
            critic_loss = sum(F.mse_loss(chosen(q, t["actions"]), target) for q in q_values)
        self.critic_optimiser.zero_grad(set_to_none=True)
        critic_loss.backward()
        self.critic_optimiser.step()

        with self.autocast():
            if self.config.all_goals:
                probs, log_probs = self.actor.every_goal(t["images"], t["previous_actions"])
            else:
                probs, log_probs = self.actor(t["images"], t["goals"], t["previous_actions"])
            q_min = torch.min(q_values[0], q_values[1]).detach()
            actor_loss = (probs * (alpha * log_probs - q_min)).sum(-1).mean()
        self.actor_optimiser.zero_grad(set_to_none=True)
        actor_loss.backward()
        self.actor_optimiser.step()

        entropy = -(probs * log_probs).sum(-1).detach()
        alpha_loss = (self.log_alpha * (entropy - self.target_entropy)).mean()
        self.alpha_optimiser.zero_grad(set_to_none=True)
        alpha_loss.backward()
        self.alpha_optimiser.step()

        soft_update(self.critics, self.targets, self.config.tau)
        return {
            "losses/qf_loss": critic_loss.item() / 2,
            "losses/actor_loss": actor_loss.item(),
            "losses/alpha": alpha.item(),
            "losses/entropy": entropy.mean().item(),
        }

    def _values(self, t: dict[str, torch.Tensor], alpha: torch.Tensor) -> tuple[list, torch.Tensor]:
        """Both critics' values of every action under the batch's goals (B, actions), and the soft
        targets of the batch's actions (B,)."""
        next_state = (t["next_images"], t["goals"], t["next_previous_actions"])
        with torch.no_grad():
            next_probs, next_log_probs = self.actor(*next_state)
            next_q = torch.min(*(target(*next_state) for target in self.targets)).float()
            target = self._target(t, next_probs, next_log_probs, next_q, t["rewards"], alpha)
        q_values = [critic(t["images"], t["goals"], t["previous_actions"]).float() for critic in self.critics]
        return q_values, target

    def _every_goal_values(
        self, t: dict[str, torch.Tensor], alpha: torch.Tensor
    ) -> tuple[list, torch.Tensor]:
        """The same under every goal: values (B, goals, actions) and targets (B, goals); the reward
        of goal g is 1 where the transition pressed key g, and the end does not depend on g."""
        rewards = every_goal_rewards(t, self.critics[0].goal_size)
        next_state = (t["next_images"], t["next_previous_actions"])
        with torch.no_grad():
            next_probs, next_log_probs = self.actor.every_goal(*next_state)
            next_q = torch.min(*(target.every_goal(*next_state) for target in self.targets)).float()
            target = self._target(t, next_probs, next_log_probs, next_q, rewards, alpha)
        q_values = [critic.every_goal(t["images"], t["previous_actions"]).float() for critic in self.critics]
        return q_values, target

    def _target(self, t, next_probs, next_log_probs, next_q, rewards, alpha) -> torch.Tensor:
        """``r + discount (1 - done) V(s')``, with the soft value ``V`` summed exactly over actions."""
        next_value = (next_probs * (next_q - alpha * next_log_probs)).sum(-1)
        continues = self.discount(t) * (1.0 - t["dones"])
        return rewards + (continues if next_value.dim() == 1 else continues[..., None]) * next_value
