"""Twin delayed DDPG (Fujimoto et al. 2018) for the continuous tasks, the paper's TD3.

Reads top to bottom: hyperparameters, a deterministic tanh policy and twin Q
critics over the paper's encoder, acting with Gaussian noise whose scale
decays linearly (the paper's 1.0 -> 0.05 over 2,000 steps), and the update:
critics towards the clipped double-Q target with target-policy smoothing,
the actor and the Polyak targets every ``policy_delay`` critic updates.
"""

from __future__ import annotations

import copy

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from tactile_braille.agents.common import (
    POSE_SIZE,
    Agent,
    critic_poses,
    network_options,
    spaces_sizes,
)
from tactile_braille.agents.config import TD3Config
from tactile_braille.agents.networks import (
    ContinuousQNetwork,
    DeterministicPolicy,
    observation_tensors,
    soft_update,
)
from tactile_braille.agents.replay import SensorPoses
from tactile_braille.agents.sac import _unit_box_size
from tactile_braille.supervised.fit import adam


class TD3Agent(Agent):
    """TD3 with the paper's decaying exploration noise, actions in [-1, 1].

    Args:
        observation_space: the task's Dict observation space.
        action_space: its ``Box(-1, 1, (n,))`` action space.
        config: hyperparameters.
        device: torch device.
        precision: ``"fp32"`` or ``"bf16"`` (autocast in the update).
    """

    policy_parts = ("actor",)
    checkpointed = (
        "actor", "actor_target", "critics", "critic_targets", "actor_optimiser", "critic_optimiser",
        "critic_updates",
    )  # fmt: skip

    @classmethod
    def replay_extras(cls, config: TD3Config) -> tuple:
        """The sensor poses its critics see (``critic_pose``)."""
        return (SensorPoses(),) if config.critic_pose else ()

    def __init__(
        self,
        observation_space: gym.spaces.Dict,
        action_space: gym.spaces.Box,
        config: TD3Config | None = None,
        device: str = "cpu",
        precision: str = "fp32",
    ) -> None:
        super().__init__(device, precision)
        self.action_size = _unit_box_size(action_space, "TD3")
        self.config = config = config or TD3Config()
        if config.policy_delay < 1:
            raise ValueError(f"policy_delay must be at least 1, got {config.policy_delay}")
        sizes = (self.action_size, *spaces_sizes(observation_space), config.hidden)
        actor_options, critic_options = network_options(observation_space, config.layer_norm)
        for options in (actor_options, critic_options):
            options.update(weights_init=config.weights_init, action_scale=config.action_input_scale)
        pose_size = POSE_SIZE if config.critic_pose else 0
        self.critics = nn.ModuleList(
            [ContinuousQNetwork(*sizes, pose_size=pose_size, **critic_options) for _ in range(2)]
        ).to(self.device)
        self.actor = DeterministicPolicy(*sizes, **actor_options).to(self.device)
        self.critic_targets = copy.deepcopy(self.critics).requires_grad_(False)
        self.actor_target = DeterministicPolicy(*sizes, **actor_options).to(self.device)
        self.actor_target.load_state_dict(self.actor.state_dict())
        self.actor_target.requires_grad_(False)
        self.actor_optimiser = adam(self.actor.parameters(), config.learning_rate, config.adam_eps)
        self.critic_optimiser = adam(self.critics.parameters(), config.learning_rate, config.adam_eps)
        self.critic_updates = torch.zeros((), dtype=torch.int64)

    def noise(self, step: int) -> float:
        """Exploration noise after ``step`` environment steps (held for ``schedule_interval`` steps)."""
        config = self.config
        step -= step % config.schedule_interval
        fraction = min(step / max(config.noise_decay_steps, 1), 1.0)
        return config.noise_start + fraction * (config.noise_end - config.noise_start)

    @torch.no_grad()
    def policy_action(
        self,
        observation: dict,
        step: int,
        explore: bool,
        rng: np.random.Generator,
        deterministic: bool = False,
    ) -> np.ndarray:
        """The action plus Gaussian noise: the schedule's, else ``test_noise``; none if deterministic."""
        action = self.actor(*observation_tensors(observation, self.device))[0].cpu().numpy()
        scale = 0.0 if deterministic else self.noise(step) if explore else self.config.test_noise
        if scale > 0:
            action = action + scale * rng.standard_normal(action.shape)
        return np.clip(action, -1.0, 1.0).astype(np.float32)

    def update(self, batch: dict[str, np.ndarray]) -> dict[str, float]:
        """One critic update; every ``policy_delay``-th also updates the actor and the targets."""
        config = self.config
        t = self.tensors(batch)
        state = (t["images"], t["goals"], t["previous_actions"])
        next_state = (t["next_images"], t["goals"], t["next_previous_actions"])
        poses, next_poses = critic_poses(t, config.critic_pose)
        with self.autocast():
            with torch.no_grad():
                smoothing = (torch.randn_like(t["actions"]) * config.target_noise).clamp(
                    -config.noise_clip, config.noise_clip
                )
                next_actions = (self.actor_target(*next_state) + smoothing).clamp(-1.0, 1.0)
                next_q = torch.min(
                    *(target(*next_state, next_actions, *next_poses) for target in self.critic_targets)
                )
                target = t["rewards"] + self.discount(t) * (1.0 - t["dones"]) * next_q
            q_values = [critic(*state, t["actions"], *poses) for critic in self.critics]
            critic_loss = sum(F.mse_loss(q, target) for q in q_values)
        self.critic_optimiser.zero_grad(set_to_none=True)
        critic_loss.backward()
        self.critic_optimiser.step()
        self.critic_updates += 1
        losses = {"losses/qf_loss": critic_loss.item() / 2, "losses/q_values": q_values[0].mean().item()}

        if int(self.critic_updates) % config.policy_delay == 0:
            self.critics.requires_grad_(False)
            with self.autocast():
                actor_loss = -self.critics[0](*state, self.actor(*state), *poses).mean()
            self.actor_optimiser.zero_grad(set_to_none=True)
            actor_loss.backward()
            self.actor_optimiser.step()
            self.critics.requires_grad_(True)
            soft_update(self.actor, self.actor_target, config.tau)
            soft_update(self.critics, self.critic_targets, config.tau)
            losses["losses/actor_loss"] = actor_loss.item()
        return losses
