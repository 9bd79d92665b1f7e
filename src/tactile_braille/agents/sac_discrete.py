"""Soft actor-critic for discrete actions (Christodoulou 2019), the paper's SAC_DISC.

Reads top to bottom: hyperparameters, a categorical policy over the paper's
encoder, twin critics with Polyak-averaged targets, and the three updates
(critics, actor, temperature). Expectations over actions are exact sums over
the categorical distribution, so no reparameterisation is needed.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from tactile_braille.agents.networks import (
    DuelingQNetwork,
    PolicyNetwork,
    observation_tensors,
    soft_update,
)


@dataclass(frozen=True)
class DiscreteSACConfig:
    """Hyperparameters (defaults: the paper's Table II).

    Attributes:
        gamma: discount (the paper's 0.6 for discrete SAC).
        learning_rate: actor and critic step size.
        alpha_learning_rate: temperature step size.
        target_entropy_ratio: target entropy as a share of the maximum,
            ``ln(num_actions)`` (the released code's 0.1; the paper quotes
            the resulting 0.139, i.e. 0.1 ln 4).
        tau: Polyak factor of the target critics (per update).
        batch_size: transitions per update.
    """

    gamma: float = 0.6
    learning_rate: float = 5e-4
    alpha_learning_rate: float = 1e-3
    target_entropy_ratio: float = 0.1
    tau: float = 0.005
    batch_size: int = 32


class DiscreteSACAgent:
    """Discrete soft actor-critic with automatic temperature.

    Args:
        num_actions, goal_size, previous_action_size: sizes of the task.
        config: hyperparameters.
        device: torch device.
    """

    def __init__(
        self,
        num_actions: int,
        goal_size: int,
        previous_action_size: int,
        config: DiscreteSACConfig | None = None,
        device: str = "cpu",
    ) -> None:
        self.config = config or DiscreteSACConfig()
        self.device = torch.device(device)
        self.num_actions = num_actions
        self.actor = PolicyNetwork(num_actions, goal_size, previous_action_size).to(self.device)
        self.critics = nn.ModuleList(
            [DuelingQNetwork(num_actions, goal_size, previous_action_size) for _ in range(2)]
        ).to(self.device)
        self.targets = copy.deepcopy(self.critics).requires_grad_(False)
        self.log_alpha = torch.zeros(1, device=self.device, requires_grad=True)
        self.target_entropy = self.config.target_entropy_ratio * math.log(num_actions)
        self.actor_optimiser = torch.optim.Adam(self.actor.parameters(), lr=self.config.learning_rate)
        self.critic_optimiser = torch.optim.Adam(self.critics.parameters(), lr=self.config.learning_rate)
        self.alpha_optimiser = torch.optim.Adam([self.log_alpha], lr=self.config.alpha_learning_rate)

    @torch.no_grad()
    def policy_action(self, observation: dict, step: int, explore: bool, rng: np.random.Generator) -> int:
        """A sampled action while exploring, the most probable one otherwise."""
        probabilities = self.actor(*observation_tensors(observation, self.device))[0][0].cpu().numpy()
        if explore:
            return int(rng.choice(self.num_actions, p=probabilities / probabilities.sum()))
        return int(probabilities.argmax())

    def update(self, batch: dict[str, np.ndarray]) -> dict[str, float]:
        """One update of the critics, the actor and the temperature."""
        t = {name: torch.as_tensor(value, device=self.device) for name, value in batch.items()}
        alpha = self.log_alpha.exp().detach()
        with torch.no_grad():
            next_probs, next_log_probs = self.actor(t["next_images"], t["goals"], t["next_previous_actions"])
            next_q = torch.min(
                *(target(t["next_images"], t["goals"], t["next_previous_actions"]) for target in self.targets)
            )
            next_value = (next_probs * (next_q - alpha * next_log_probs)).sum(-1)
            target = t["rewards"] + self.config.gamma * (1.0 - t["dones"]) * next_value
        q_values = [critic(t["images"], t["goals"], t["previous_actions"]) for critic in self.critics]
        taken = t["actions"][:, None]
        critic_loss = sum(F.mse_loss(q.gather(-1, taken).squeeze(-1), target) for q in q_values)
        self.critic_optimiser.zero_grad(set_to_none=True)
        critic_loss.backward()
        self.critic_optimiser.step()

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

    def state_dict(self) -> dict:
        return {
            "actor": self.actor.state_dict(),
            "critics": self.critics.state_dict(),
            "targets": self.targets.state_dict(),
            "log_alpha": self.log_alpha.detach().clone(),
            "optimisers": [
                o.state_dict() for o in (self.actor_optimiser, self.critic_optimiser, self.alpha_optimiser)
            ],
        }

    def load_state_dict(self, state: dict) -> None:
        self.actor.load_state_dict(state["actor"])
        self.critics.load_state_dict(state["critics"])
        self.targets.load_state_dict(state["targets"])
        with torch.no_grad():
            self.log_alpha.copy_(state["log_alpha"])
        optimisers = (self.actor_optimiser, self.critic_optimiser, self.alpha_optimiser)
        for optimiser, saved in zip(optimisers, state["optimisers"], strict=True):
            optimiser.load_state_dict(saved)
