"""The paper's networks: an Atari-style encoder with the goal and previous action joined after it.

Encoder: conv 32/64/64 filters, kernels 8/4/3, strides 4/2/1, ReLU, no pooling,
on the 100x100x1 tactile image (5,184 features). The goal one-hot and the
previous action are concatenated to the features, then a dense layer of 512
units. Weights use variance-scaling (He) initialisation.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

IMAGE_FEATURES = 64 * 9 * 9


def _init(module: nn.Module) -> None:
    if isinstance(module, nn.Conv2d | nn.Linear):
        nn.init.kaiming_normal_(module.weight, nonlinearity="relu")
        nn.init.zeros_(module.bias)


class Encoder(nn.Module):
    """Conv 32/64/64 (8/4/3, strides 4/2/1) over a (B, 1, 100, 100) uint8 or float image."""

    def __init__(self) -> None:
        super().__init__()
        self.layers = nn.Sequential(
            nn.Conv2d(1, 32, 8, stride=4),
            nn.ReLU(),
            nn.Conv2d(32, 64, 4, stride=2),
            nn.ReLU(),
            nn.Conv2d(64, 64, 3, stride=1),
            nn.ReLU(),
            nn.Flatten(),
        )
        self.apply(_init)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        if images.dtype == torch.uint8:
            images = images.float().div_(255.0)
        return self.layers(images)


class GoalConditionedTrunk(nn.Module):
    """The encoder's features joined with the goal and previous action, then a dense layer."""

    def __init__(self, goal_size: int, previous_action_size: int, hidden: int = 512) -> None:
        super().__init__()
        self.encoder = Encoder()
        self.dense = nn.Sequential(
            nn.Linear(IMAGE_FEATURES + goal_size + previous_action_size, hidden), nn.ReLU()
        )
        self.dense.apply(_init)

    def forward(
        self, images: torch.Tensor, goals: torch.Tensor, previous_actions: torch.Tensor
    ) -> torch.Tensor:
        return self.dense(torch.cat([self.encoder(images), goals, previous_actions], dim=-1))


def _small_head(inputs: int, outputs: int) -> nn.Linear:
    """A linear output layer initialised near zero (Q near 0, policy near uniform)."""
    head = nn.Linear(inputs, outputs)
    nn.init.normal_(head.weight, std=0.01)
    nn.init.zeros_(head.bias)
    return head


class DuelingQNetwork(nn.Module):
    """Q-values with a dueling head: ``Q = V + A - mean(A)``.

    Args:
        num_actions: discrete actions.
        goal_size: length of the goal one-hot.
        previous_action_size: length of the previous-action vector.
        hidden: units of the dense layer (the paper's 512).
    """

    def __init__(
        self, num_actions: int, goal_size: int, previous_action_size: int, hidden: int = 512
    ) -> None:
        super().__init__()
        self.trunk = GoalConditionedTrunk(goal_size, previous_action_size, hidden)
        self.value = _small_head(hidden, 1)
        self.advantage = _small_head(hidden, num_actions)

    def forward(
        self, images: torch.Tensor, goals: torch.Tensor, previous_actions: torch.Tensor
    ) -> torch.Tensor:
        hidden = self.trunk(images, goals, previous_actions)
        advantage = self.advantage(hidden)
        return self.value(hidden) + advantage - advantage.mean(dim=-1, keepdim=True)


class PolicyNetwork(nn.Module):
    """Categorical policy over discrete actions (same trunk, a logits head)."""

    def __init__(
        self, num_actions: int, goal_size: int, previous_action_size: int, hidden: int = 512
    ) -> None:
        super().__init__()
        self.trunk = GoalConditionedTrunk(goal_size, previous_action_size, hidden)
        self.logits = _small_head(hidden, num_actions)

    def forward(self, images, goals, previous_actions) -> tuple[torch.Tensor, torch.Tensor]:
        """Action probabilities and their logs."""
        logits = self.logits(self.trunk(images, goals, previous_actions))
        return F.softmax(logits, dim=-1), F.log_softmax(logits, dim=-1)


def observation_tensors(observation: dict[str, np.ndarray], device: torch.device) -> tuple[torch.Tensor, ...]:
    """One environment observation as a batch of one: (image, goal, previous action)."""
    return (
        torch.as_tensor(np.moveaxis(observation["observation"], -1, 0)[None], device=device),
        torch.as_tensor(observation["desired_goal"][None], device=device),
        torch.as_tensor(observation["previous_action"][None], device=device),
    )


@torch.no_grad()
def soft_update(online: nn.Module, target: nn.Module, tau: float) -> None:
    """Polyak averaging: ``target <- (1 - tau) target + tau online``."""
    for online_param, target_param in zip(online.parameters(), target.parameters(), strict=True):
        target_param.lerp_(online_param, tau)
