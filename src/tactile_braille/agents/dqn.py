"""Double + dueling DQN (the paper's discrete agent), for goal-conditioned braille tasks.

Reads top to bottom: hyperparameters, acting (epsilon-greedy with the paper's
linear schedule), and the update (double-DQN target from the online network's
argmax, evaluated by a Polyak-averaged target network).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import torch
from torch.nn import functional as F

from tactile_braille.agents.networks import DuelingQNetwork, observation_tensors, soft_update


@dataclass(frozen=True)
class DQNConfig:
    """Hyperparameters (defaults: the paper's Table II).

    Attributes:
        gamma: discount.
        learning_rate: Adam's step size.
        tau: Polyak factor of the soft target update (per update).
        epsilon_start, epsilon_end: exploration at the start and end of the schedule.
        epsilon_decay_steps: environment steps over which epsilon decays linearly.
        batch_size: transitions per update.
    """

    gamma: float = 0.95
    learning_rate: float = 5e-4
    tau: float = 0.005
    epsilon_start: float = 1.0
    epsilon_end: float = 0.1
    epsilon_decay_steps: int = 2000
    batch_size: int = 32


class DQNAgent:
    """Double + dueling DQN.

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
        config: DQNConfig | None = None,
        device: str = "cpu",
    ) -> None:
        self.config = config or DQNConfig()
        self.device = torch.device(device)
        self.num_actions = num_actions
        self.q = DuelingQNetwork(num_actions, goal_size, previous_action_size).to(self.device)
        self.target = copy.deepcopy(self.q).requires_grad_(False)
        self.optimiser = torch.optim.Adam(self.q.parameters(), lr=self.config.learning_rate)

    def epsilon(self, step: int) -> float:
        """Exploration rate after ``step`` environment steps."""
        config = self.config
        fraction = min(step / max(config.epsilon_decay_steps, 1), 1.0)
        return config.epsilon_start + fraction * (config.epsilon_end - config.epsilon_start)

    @torch.no_grad()
    def act(self, observation: dict[str, np.ndarray], epsilon: float, rng: np.random.Generator) -> int:
        """Epsilon-greedy action for one observation."""
        if rng.random() < epsilon:
            return int(rng.integers(self.num_actions))
        return int(self.q(*observation_tensors(observation, self.device)).argmax(dim=-1).item())

    def policy_action(self, observation: dict, step: int, explore: bool, rng: np.random.Generator) -> int:
        """Epsilon-greedy (the paper's schedule) while exploring, greedy otherwise."""
        return self.act(observation, self.epsilon(step) if explore else 0.0, rng)

    def update(self, batch: dict[str, np.ndarray]) -> dict[str, float]:
        """One gradient step on a batch from the replay buffer; returns losses."""
        t = {name: torch.as_tensor(value, device=self.device) for name, value in batch.items()}
        with torch.no_grad():
            next_online = self.q(t["next_images"], t["goals"], t["next_previous_actions"])
            next_action = next_online.argmax(dim=-1, keepdim=True)
            next_target = self.target(t["next_images"], t["goals"], t["next_previous_actions"])
            next_value = next_target.gather(-1, next_action).squeeze(-1)
            target = t["rewards"] + self.config.gamma * (1.0 - t["dones"]) * next_value
        q = (
            self.q(t["images"], t["goals"], t["previous_actions"])
            .gather(-1, t["actions"][:, None])
            .squeeze(-1)
        )
        loss = F.smooth_l1_loss(q, target)
        self.optimiser.zero_grad(set_to_none=True)
        loss.backward()
        self.optimiser.step()
        soft_update(self.q, self.target, self.config.tau)
        return {"losses/q_loss": loss.item(), "losses/q_values": q.mean().item()}

    def state_dict(self) -> dict:
        return {
            "q": self.q.state_dict(),
            "target": self.target.state_dict(),
            "optimiser": self.optimiser.state_dict(),
        }

    def load_state_dict(self, state: dict) -> None:
        self.q.load_state_dict(state["q"])
        self.target.load_state_dict(state["target"])
        self.optimiser.load_state_dict(state["optimiser"])
