"""Double + dueling DQN (the paper's discrete agent), for goal-conditioned braille tasks.

Reads top to bottom: hyperparameters, acting (epsilon-greedy with the paper's
linear schedule), and the update (double-DQN target from the online network's
argmax, evaluated by a target network that moves towards the online one after
every update, as the paper's Table II, or once per epoch, as the released
code: ``target_update``).
"""

from __future__ import annotations

import copy

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from tactile_braille.agents.common import Agent, chosen, every_goal_rewards, network_options, spaces_sizes
from tactile_braille.agents.config import DQNConfig
from tactile_braille.agents.networks import (
    DuelingQNetwork,
    observation_tensors,
    soft_update,
)
from tactile_braille.agents.replay import GoalOutcomes, PressFrames, ReturnBounds
from tactile_braille.supervised.fit import adam


class DQNAgent(Agent):
    """Double + dueling DQN.

    Args:
        observation_space: the task's Dict observation space.
        action_space: its ``Discrete`` action space.
        config: hyperparameters.
        device: torch device.
        precision: ``"fp32"`` or ``"bf16"`` (autocast in the update).
    """

    policy_parts = ("q",)
    checkpointed = ("q", "target", "optimiser")

    @classmethod
    def replay_extras(cls, config: DQNConfig) -> tuple:
        """Every goal's outcome (``all_goals``), return bounds (``return_bound``) and press frames
        (``pressed_key``), as its settings ask."""
        return (
            *([GoalOutcomes()] if config.all_goals else []),
            *([ReturnBounds(config.gamma, config.return_bound_after)] if config.return_bound else []),
            *([PressFrames()] if config.pressed_key > 0 else []),
        )

    def __init__(
        self,
        observation_space: gym.spaces.Dict,
        action_space: gym.spaces.Discrete,
        config: DQNConfig | None = None,
        device: str = "cpu",
        precision: str = "fp32",
    ) -> None:
        super().__init__(device, precision)
        if not isinstance(action_space, gym.spaces.Discrete):
            raise ValueError(f"DQN needs a Discrete action space, got {action_space}")
        self.config = config or DQNConfig()
        self.num_actions = int(action_space.n)
        goal_size, previous_size = spaces_sizes(observation_space)
        _, options = network_options(observation_space, self.config.layer_norm, self.config.unit_features)
        self.q = DuelingQNetwork(
            self.num_actions, goal_size, previous_size, self.config.hidden,
            goal_heads=self.config.goal_heads, dueling_split=self.config.dueling_split,
            weights_init=self.config.weights_init, goal_difference=self.config.goal_difference, **options,
        ).to(self.device)  # fmt: skip
        self.target = copy.deepcopy(self.q).requires_grad_(False)
        learnt = list(self.q.parameters())
        self.key_head = None
        if self.config.pressed_key > 0:
            self.key_head = nn.Linear(self.q.trunk.encoded, goal_size).to(self.device)
            learnt += list(self.key_head.parameters())
            self.checkpointed = (*self.checkpointed, "key_head")
        self.optimiser = adam(learnt, self.config.learning_rate, self.config.adam_eps)

    def epsilon(self, step: int) -> float:
        """Exploration rate after ``step`` environment steps (held for ``schedule_interval`` steps)."""
        config = self.config
        step -= step % config.schedule_interval
        fraction = min(step / max(config.epsilon_decay_steps, 1), 1.0)
        return config.epsilon_start + fraction * (config.epsilon_end - config.epsilon_start)

    @torch.no_grad()
    def act(self, observation: dict[str, np.ndarray], epsilon: float, rng: np.random.Generator) -> int:
        """Epsilon-greedy action for one observation."""
        if rng.random() < epsilon:
            return int(rng.integers(self.num_actions))
        return int(self.q(*observation_tensors(observation, self.device)).argmax(dim=-1).item())

    def policy_action(
        self,
        observation: dict,
        step: int,
        explore: bool,
        rng: np.random.Generator,
        deterministic: bool = False,
    ) -> int:
        """Epsilon-greedy: the paper's schedule exploring, else ``test_epsilon``; 0 if ``deterministic``."""
        if deterministic:
            return self.act(observation, 0.0, rng)
        return self.act(observation, self.epsilon(step) if explore else self.config.test_epsilon, rng)

    def update(self, batch: dict[str, np.ndarray]) -> dict[str, float]:
        """One gradient step on a batch from the replay buffer; returns losses."""
        t = self.tensors(batch)
        with self.autocast():
            q, target = self._all_goals_values(t) if self.config.all_goals else self._values(t)
            loss = self._loss(q, target, t)
            key_loss = self._pressed_key_loss(t) if self.key_head is not None else None
        total = loss
        if key_loss is not None:
            total = total + self.config.pressed_key * key_loss
        self.optimiser.zero_grad(set_to_none=True)
        total.backward()
        self.optimiser.step()
        if self.config.target_update == "update":
            soft_update(self.q, self.target, self.config.tau)
        losses = {"losses/q_loss": loss.item(), "losses/q_values": q.mean().item()}
        if key_loss is not None:
            losses["losses/pressed_key_loss"] = key_loss.item()
        return losses

    def _pressed_key_loss(self, t: dict[str, torch.Tensor]) -> torch.Tensor | None:
        """Cross-entropy of the key head's reading of the frames presses were chosen on, against the
        keys they pressed (the replay's ``press_images`` and ``press_keys``); None before any press."""
        if "press_keys" not in t:
            raise ValueError(
                "pressed_key needs batches with press frames (a replay with the PressFrames extra)"
            )
        if len(t["press_keys"]) == 0:
            return None
        logits = self.key_head(self.q.trunk.encode(t["press_images"])).float()
        return F.cross_entropy(logits, t["press_keys"])

    def _loss(self, q: torch.Tensor, target: torch.Tensor, t: dict[str, torch.Tensor]) -> torch.Tensor:
        """The TD loss, averaged over the batch and its goals (alike, or as ``all_goals_weights``)."""
        if self.config.loss == "huber":
            error = F.smooth_l1_loss(q, target, reduction="none")
        else:
            error = 0.5 * (q - target) ** 2
        if not self.config.all_goals or self.config.all_goals_weights == "uniform":
            return error.mean()
        return (error * t["goal_weights"]).sum(-1).mean()

    def _values(self, t: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """Q of the batch's actions under its goals, and their double-DQN targets, shape (B,)."""
        with torch.no_grad():
            next_online = self.q(t["next_images"], t["goals"], t["next_previous_actions"])
            next_action = next_online.argmax(dim=-1, keepdim=True)
            next_target = self.target(t["next_images"], t["goals"], t["next_previous_actions"])
            next_value = next_target.gather(-1, next_action).squeeze(-1).float()
            target = t["rewards"] + self.discount(t) * (1.0 - t["dones"]) * next_value
            if self.config.return_bound:
                if "return_bounds" not in t:
                    raise ValueError(
                        "return_bound needs batches with 'return_bounds' (the ReturnBounds extra)"
                    )
                target = torch.maximum(target, t["return_bounds"])
        q_all = self.q(t["images"], t["goals"], t["previous_actions"])
        return chosen(q_all, t["actions"]).float(), target

    def _all_goals_values(self, t: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """The same under every goal, shape (B, goals): the reward of goal g is 1 where the
        transition pressed key g (``achieved``, -1 for none), and the end does not depend on g."""
        rewards = every_goal_rewards(t, self.q.goal_size)
        with torch.no_grad():
            next_online = self.q.every_goal(t["next_images"], t["next_previous_actions"])
            next_action = next_online.argmax(dim=-1, keepdim=True)
            next_target = self.target.every_goal(t["next_images"], t["next_previous_actions"])
            next_value = next_target.gather(-1, next_action).squeeze(-1).float()
            target = rewards + (self.discount(t) * (1.0 - t["dones"]))[..., None] * next_value
        q_all = self.q.every_goal(t["images"], t["previous_actions"])
        return chosen(q_all, t["actions"]).float(), target

    def end_epoch(self) -> None:
        """The released code's target update: once per epoch, ``tau`` of the way to the online net."""
        if self.config.target_update == "epoch":
            soft_update(self.q, self.target, self.config.tau)
