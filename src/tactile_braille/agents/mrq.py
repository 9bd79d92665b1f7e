"""MR.Q (Fujimoto et al. 2025, "Towards general-purpose model-free reinforcement learning"), for the
goal-conditioned braille tasks, discrete and continuous.

Reads top to bottom: the networks (an encoder of state and state-action embeddings trained by a
model-based loss and by the value's, a twin value on the state-action embedding and the goal, a
deterministic policy on the state embedding and the goal: tanh for continuous actions, logits over
discrete ones), the reward model's two-hot encoding, the agent's prioritised sampling (LAP), and
its updates.

As in the paper: every ``target_every`` updates the targets are copied, and the encoder then learns
for ``target_every`` updates on sub-trajectories (the model unrolled over ``encoder_horizon`` steps:
next state embedding, reward and episode end, masked after the episode's end); the value learns a
``value_horizon``-step return, scaled by the mean absolute reward of the replay, with clipped double
Q and target-policy smoothing; the replay samples by the value's TD errors (LAP).

What differs, for goal-conditioned tasks with a sparse reward:

- The state is the tactile image with the goal and the previous action, which join the image's
  convolutional features before the state embedding (the paper's state is the image alone). The
  goal is also given to the value and the policy beside their embeddings, as goal-conditioned
  values are built.
- The value's loss trains the encoder too, at every update (the paper's encoder learns from its
  model alone and is fixed between copies). Alone, the model's next-embedding loss shrinks the
  embeddings towards one point, and a reward that is non-zero on a few presses does not keep in
  them whether the key under the sensor is the goal.
- The discrete policy learns the value's best one-hot action by cross-entropy (the paper's climbs
  the value of its Gumbel-softmax relaxation, a point between the one-hot actions the value never
  learnt); it explores by sampling its softmax (Gumbel-max), its target is its greedy action, and
  it acts on its argmax in test episodes and typing (the released code samples when it evaluates).
- A sub-trajectory that a truncated episode cuts short is masked past its end (the paper does not
  sample it). Priorities are the TD errors of the value's update; the released code takes them
  after its policy step, from the policy's actions.
"""

from __future__ import annotations

import copy

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from tactile_braille.agents.common import Agent, observation_features, spaces_sizes
from tactile_braille.agents.config import MRQConfig
from tactile_braille.agents.networks import observation_tensors
from tactile_braille.agents.replay import SubTrajectories, random_shift


# ================================================================= networks
def _init(module: nn.Module) -> None:
    if isinstance(module, nn.Linear | nn.Conv2d):
        nn.init.xavier_uniform_(module.weight, nn.init.calculate_gain("relu"))
        nn.init.zeros_(module.bias)


def _norm(x: torch.Tensor, activation=F.elu) -> torch.Tensor:
    """LayerNorm without parameters, then the activation: MR.Q's hidden layers."""
    return activation(F.layer_norm(x, x.shape[-1:]))


class _MLP(nn.Module):
    """Three linear layers, the first two normalised and activated."""

    def __init__(self, inputs: int, outputs: int, hidden: int, activation=F.elu) -> None:
        super().__init__()
        self.layers = nn.ModuleList(
            [nn.Linear(inputs, hidden), nn.Linear(hidden, hidden), nn.Linear(hidden, outputs)]
        )
        self.activation = activation
        self.apply(_init)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        for layer in self.layers[:-1]:
            x = _norm(layer(x), self.activation)
        return self.layers[-1](x)


class MRQEncoder(nn.Module):
    """The state embedding ``zs`` of (image, goal, previous action), the state-action embedding ``zsa``
    and the model on it (episode end, next ``zs``, reward logits).

    Args:
        goal_size, previous_size, action_size: lengths of the goal one-hot, the previous action and
            the action (a one-hot for discrete actions).
        config: the hyperparameters (embedding sizes, hidden units, reward bins).
        features: the observation is a vector of this many features (an MLP in place of the
            convolutions).
        channels: channels of the image.
    """

    def __init__(self, goal_size: int, previous_size: int, action_size: int, config: MRQConfig,
                 features: int | None = None, channels: int = 1) -> None:  # fmt: skip
        super().__init__()
        if features is None:
            self.convolutions = nn.Sequential(
                nn.Conv2d(channels, 32, 3, stride=2), nn.ELU(), nn.Conv2d(32, 32, 3, stride=2), nn.ELU(),
                nn.Conv2d(32, 32, 3, stride=2), nn.ELU(), nn.Conv2d(32, 32, 3, stride=1), nn.ELU(),
                nn.Flatten(),
            )  # fmt: skip
            with torch.no_grad():
                seen = self.convolutions(torch.zeros(1, channels, 100, 100)).shape[1]
        else:
            self.convolutions = _MLP(features, config.hidden_units, config.hidden_units)
            seen = config.hidden_units
        self.state = nn.Linear(seen + goal_size + previous_size, config.state_size)
        self.action = nn.Linear(action_size, config.action_size)
        self.state_action = _MLP(config.state_size + config.action_size, config.state_action_size,
                                 config.hidden_units)  # fmt: skip
        self.model = nn.Linear(config.state_action_size, 1 + config.state_size + config.reward_bins)
        self.state_size = config.state_size
        self.apply(_init)

    def zs(self, images: torch.Tensor, goals: torch.Tensor, previous: torch.Tensor) -> torch.Tensor:
        if images.dtype == torch.uint8:
            images = images.float().div_(255.0).sub_(0.5)
        features = self.convolutions(images)
        if not isinstance(self.convolutions, nn.Sequential):
            features = _norm(features)
        return _norm(
            self.state(torch.cat([features, goals.to(features.dtype), previous.to(features.dtype)], -1))
        )

    def zsa(self, zs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        return self.state_action(torch.cat([zs, F.elu(self.action(actions.to(zs.dtype)))], -1))

    def predict(self, zs: torch.Tensor, actions: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """The model: (episode-end prediction (B,), next ``zs`` (B, state_size), reward logits)."""
        out = self.model(self.zsa(zs, actions))
        return out[:, 0], out[:, 1 : 1 + self.state_size], out[:, 1 + self.state_size :]


class MRQValue(nn.Module):
    """Twin action values of a state-action embedding and the goal, (B, 2)."""

    def __init__(self, goal_size: int, config: MRQConfig) -> None:
        super().__init__()
        hidden, inputs = config.hidden_units, config.state_action_size + goal_size
        self.trunks = nn.ModuleList([_MLP(inputs, hidden, hidden) for _ in range(2)])
        self.heads = nn.ModuleList([nn.Linear(hidden, 1) for _ in range(2)])
        self.apply(_init)

    def forward(self, zsa: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
        x = torch.cat([zsa, goals.to(zsa.dtype)], -1)
        return torch.cat(
            [head(_norm(trunk(x))) for trunk, head in zip(self.trunks, self.heads, strict=True)], -1
        )


class MRQPolicy(nn.Module):
    """The policy on ``zs`` and the goal: pre-activations, (B, action_size); the action is their tanh
    for continuous actions, and for discrete ones they are the logits of a softmax."""

    def __init__(self, goal_size: int, action_size: int, config: MRQConfig) -> None:
        super().__init__()
        self.layers = _MLP(config.state_size + goal_size, action_size, config.hidden_units, F.relu)

    def forward(self, zs: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
        return self.layers(torch.cat([zs, goals.to(zs.dtype)], -1))


# ================================================================= the reward model's encoding
class TwoHot:
    """Rewards as two-hot vectors over ``bins`` values spaced evenly in symlog space over
    [-``bound``, ``bound``]."""

    def __init__(self, bins: int, bound: float, device: torch.device) -> None:
        grid = torch.linspace(-bound, bound, bins, device=device)
        self.values = grid.sign() * grid.abs().expm1()  # symexp

    def encode(self, x: torch.Tensor) -> torch.Tensor:
        """(B,) values -> (B, bins): weights on the two bins around each (clipped to the range)."""
        values = self.values
        x = x.float().clamp(values[0], values[-1])
        upper = torch.searchsorted(values, x.contiguous()).clamp(1, len(values) - 1)
        low, high = values[upper - 1], values[upper]
        weight = ((x - low) / (high - low)).clamp(0, 1)
        encoded = torch.zeros(len(x), len(values), device=x.device)
        encoded.scatter_(1, (upper - 1)[:, None], (1 - weight)[:, None])
        encoded.scatter_add_(1, upper[:, None], weight[:, None])
        return encoded

    def cross_entropy(self, logits: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        """(B,) cross-entropy of the logits against the values' two-hot encodings."""
        return -(self.encode(x) * F.log_softmax(logits.float(), -1)).sum(-1)


# ================================================================= the agent
class MRQAgent(Agent):
    """MR.Q on the braille tasks (the module docstring), actions discrete or in [-1, 1].

    Args:
        observation_space: the task's Dict observation space.
        action_space: its ``Discrete`` or ``Box(-1, 1, (n,))`` action space.
        config: hyperparameters.
        device: torch device.
        precision: ``"fp32"`` or ``"bf16"`` (autocast in the networks' passes).
    """

    policy_parts = ("encoder", "policy")
    checkpointed = (
        "encoder", "encoder_target", "policy", "policy_target", "value", "value_target",
        "encoder_optimiser", "policy_optimiser", "value_optimiser", "priorities", "counters",
    )  # fmt: skip

    @classmethod
    def replay_extras(cls, config: MRQConfig) -> tuple:
        """Each sampled transition's sub-trajectory, for the encoder's unroll and the value's return."""
        return (SubTrajectories(max(config.encoder_horizon, config.value_horizon)),)

    def __init__(
        self,
        observation_space: gym.spaces.Dict,
        action_space: gym.Space,
        config: MRQConfig | None = None,
        device: str = "cpu",
        precision: str = "fp32",
    ) -> None:
        super().__init__(device, precision)
        self.config = config = config or MRQConfig()
        self.discrete = isinstance(action_space, gym.spaces.Discrete)
        if self.discrete:
            self.action_size = int(action_space.n)
        elif isinstance(action_space, gym.spaces.Box) and len(action_space.shape) == 1:
            self.action_size = int(action_space.shape[0])
        else:
            raise ValueError(
                f"MR.Q needs a Discrete or a one-dimensional Box action space, got {action_space}"
            )
        goal_size, previous_size = spaces_sizes(observation_space)
        shape = observation_space["observation"].shape
        channels = int(shape[-1]) if len(shape) == 3 else 1
        features = observation_features(observation_space)
        self.encoder = MRQEncoder(goal_size, previous_size, self.action_size, config, features, channels)
        self.encoder.to(self.device)
        self.policy = MRQPolicy(goal_size, self.action_size, config).to(self.device)
        self.value = MRQValue(goal_size, config).to(self.device)
        self.encoder_target, self.policy_target, self.value_target = (
            copy.deepcopy(part).requires_grad_(False) for part in (self.encoder, self.policy, self.value)
        )
        self.encoder_optimiser, self.policy_optimiser, self.value_optimiser = (
            _adamw(part.parameters(), rate, config.weight_decay)
            for part, rate in ((self.encoder, config.encoder_learning_rate),
                               (self.policy, config.policy_learning_rate),
                               (self.value, config.value_learning_rate))
        )  # fmt: skip
        self.two_hot = TwoHot(config.reward_bins, config.reward_bound, self.device)
        self.priorities = torch.zeros(0)  # one per replay slot, made at the first sample
        # updates, reward scale, target reward scale, largest priority, next replay slot marked, size
        self.counters = torch.tensor([0.0, 1.0, 0.0, config.min_priority, 0.0, 0.0], dtype=torch.float64)
        self.encoder_losses: dict[str, float] = {}

    # ------------------------------------------------------------- acting
    @torch.no_grad()
    def policy_action(self, observation: dict, step: int, explore: bool, rng: np.random.Generator,
                      deterministic: bool = False):  # fmt: skip
        """The policy's action while exploring (continuous: with Gaussian noise; discrete: a sample of
        its softmax, by Gumbel-max); its greedy action otherwise."""
        images, goals, previous = observation_tensors(observation, self.device)
        with self.autocast():
            pre = self.policy(self.encoder.zs(images, goals, previous), goals)
        pre = pre.float().cpu().numpy()[0]
        explore = explore and not deterministic
        if self.discrete:
            if explore:
                pre = pre - np.log(-np.log(rng.uniform(1e-10, 1.0, size=pre.shape)))
            return int(pre.argmax())
        action = np.tanh(pre)
        if explore:
            action = action + rng.normal(0.0, self.config.exploration_noise, size=action.shape)
        return np.clip(action, -1.0, 1.0).astype(np.float32)

    # ------------------------------------------------------------- sampling (LAP)
    def sample(self, buffer, batch_size: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """A batch drawn by priority. At every ``target_every``-th update the targets are copied and
        the reward scale renewed first, and the encoder learns for ``target_every`` updates."""
        self._mark_new(buffer)
        updates = int(self.counters[0])
        if updates % self.config.target_every == 0:
            for online, target in ((self.encoder, self.encoder_target), (self.policy, self.policy_target),
                                   (self.value, self.value_target)):  # fmt: skip
                target.load_state_dict(online.state_dict())
            rewards = np.abs(buffer.rewards[: buffer.size])
            self.counters[2] = self.counters[1]
            self.counters[1] = max(float(rewards.mean()), 1e-8)
            for _ in range(self.config.target_every):
                self.encoder_losses = self._train_encoder(self._draw(buffer, batch_size, rng))
        return self._draw(buffer, batch_size, rng)

    def _mark_new(self, buffer) -> None:
        """New transitions take the largest priority so far."""
        if len(self.priorities) != buffer.capacity:
            if len(self.priorities):
                raise ValueError(f"priorities for {len(self.priorities)} slots, replay of {buffer.capacity}")
            self.priorities = torch.zeros(buffer.capacity)
        marked, marked_size = int(self.counters[4]), int(self.counters[5])
        new = (buffer.next_slot - marked) % buffer.capacity
        if new == 0 and buffer.size != marked_size:
            new = buffer.capacity
        slots = (marked + np.arange(new)) % buffer.capacity
        self.priorities[torch.as_tensor(slots)] = float(self.counters[3])
        self.counters[4], self.counters[5] = buffer.next_slot, buffer.size

    def _draw(self, buffer, batch_size: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """A batch at slots drawn by priority, its images shifted (``image_shift``)."""
        cumulative = np.cumsum(self.priorities[: buffer.size].numpy(), dtype=np.float64)
        slots = np.searchsorted(cumulative, rng.random(batch_size) * cumulative[-1], side="right")
        slots = np.minimum(slots, buffer.size - 1)
        batch = buffer.sample(batch_size, rng, index=slots)
        pixels = self.config.image_shift
        if pixels:
            if batch["images"].ndim != 4:
                raise ValueError(f"image_shift={pixels} moves images, but this replay serves features")
            batch["images"] = random_shift(batch["images"], pixels, rng)
            frames = batch["horizon_next_images"]
            batch["horizon_next_images"] = random_shift(
                frames.reshape(-1, *frames.shape[2:]), pixels, rng
            ).reshape(frames.shape)
        del batch["next_images"]  # MR.Q bootstraps from the sub-trajectories' frames
        return {**batch, "slots": slots}

    # ------------------------------------------------------------- updates
    def _actions(self, actions: torch.Tensor) -> torch.Tensor:
        return F.one_hot(actions.long(), self.action_size).float() if self.discrete else actions.float()

    def _train_encoder(self, batch: dict[str, np.ndarray]) -> dict[str, float]:
        """One step of the encoder's loss over the sub-trajectories' first ``encoder_horizon`` steps."""
        config, t = self.config, self.tensors(batch)
        horizon = config.encoder_horizon
        images = t["horizon_next_images"][:, :horizon]
        batch_size = len(images)
        with torch.no_grad(), self.autocast():
            targets = self.encoder_target.zs(
                images.flatten(0, 1), t["goals"].repeat_interleave(horizon, 0),
                t["horizon_next_previous_actions"][:, :horizon].flatten(0, 1),
            ).float().view(batch_size, horizon, -1)  # fmt: skip
        parts = torch.zeros(3, device=self.device)
        with self.autocast():
            zs = self.encoder.zs(t["images"], t["goals"], t["previous_actions"])
            actions = self._actions(t["horizon_actions"])
            for step in range(horizon):
                done, zs, reward = self.encoder.predict(zs, actions[:, step])
                mask = t["horizon_valid"][:, step]
                parts = parts + torch.stack([
                    ((zs.float() - targets[:, step]) ** 2 * mask[:, None]).mean(),
                    (self.two_hot.cross_entropy(reward, t["horizon_rewards"][:, step]) * mask).mean(),
                    ((done.float() - t["horizon_dones"][:, step]) ** 2 * mask).mean(),
                ])  # fmt: skip
        weights = torch.tensor(
            [config.dynamics_weight, config.reward_weight, config.done_weight], device=self.device
        )
        loss = (parts * weights).sum()
        self.encoder_optimiser.zero_grad(set_to_none=True)
        loss.backward()
        self.encoder_optimiser.step()
        dynamics, reward, done = parts.tolist()
        return {
            "losses/encoder_dynamics": dynamics,
            "losses/encoder_reward": reward,
            "losses/encoder_done": done,
        }

    def _targets(self, t: dict[str, torch.Tensor]) -> torch.Tensor:
        """The value's targets: the ``value_horizon``-step return under the batch goal, then the
        target networks' clipped double Q of the smoothed target policy, in reward-scaled units."""
        config = self.config
        horizon = config.value_horizon
        valid = t["horizon_valid"][:, :horizon]
        span = valid.sum(-1).long()  # steps within the episode, >= 1
        discounts = config.gamma ** torch.arange(horizon, device=self.device, dtype=torch.float32)
        returns = (t["horizon_rewards"][:, :horizon] * discounts).sum(-1)
        rows, last = torch.arange(len(span), device=self.device), span - 1
        with self.autocast():
            next_zs = self.encoder_target.zs(t["horizon_next_images"][rows, last], t["goals"],
                                             t["horizon_next_previous_actions"][rows, last])  # fmt: skip
            pre = self.policy_target(next_zs, t["goals"]).float()
            if self.discrete:
                action = F.one_hot(pre.argmax(-1), self.action_size).float()
            else:
                noise = torch.randn_like(pre) * config.target_noise
                action = (pre.tanh() + noise.clamp(-config.noise_clip, config.noise_clip)).clamp(-1.0, 1.0)
            next_zsa = self.encoder_target.zsa(next_zs, action)
            next_value = self.value_target(next_zsa, t["goals"]).float().min(-1).values
        _, reward_scale, target_reward_scale = self.counters[:3].tolist()
        not_done = 1.0 - t["horizon_dones"][rows, last]
        bootstrap = not_done * config.gamma ** span.float() * next_value * target_reward_scale
        return (returns + bootstrap) / reward_scale

    @torch.no_grad()
    def _best_actions(self, zs: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
        """The value's best one-hot action in each state (the mean of the twins), (B,)."""
        batch, actions = len(zs), torch.eye(self.action_size, device=self.device)
        zsa = self.encoder.zsa(zs.repeat_interleave(self.action_size, 0), actions.repeat(batch, 1))
        q = self.value(zsa, goals.repeat_interleave(self.action_size, 0)).float().mean(-1)
        return q.view(batch, self.action_size).argmax(-1)

    def update(self, batch: dict[str, np.ndarray]) -> dict[str, float]:
        """One step of the value and the encoder (Huber towards :meth:`_targets`) and of the policy (the
        value of its actions, or for discrete actions the cross-entropy to the value's best; its
        pre-activations penalised); the sampled transitions' priorities renewed."""
        config, t = self.config, self.tensors(batch)
        with torch.no_grad():
            target = self._targets(t)
        with self.autocast():
            zs = self.encoder.zs(t["images"], t["goals"], t["previous_actions"])
            zsa = self.encoder.zsa(zs, self._actions(t["actions"]))
            q = self.value(zsa, t["goals"]).float()
        value_loss = F.smooth_l1_loss(q, target[:, None].expand_as(q))
        self.value_optimiser.zero_grad(set_to_none=True)
        self.encoder_optimiser.zero_grad(set_to_none=True)
        value_loss.backward()
        nn.utils.clip_grad_norm_(self.value.parameters(), config.value_grad_clip)
        self.value_optimiser.step()
        self.encoder_optimiser.step()
        zs = zs.detach()

        with self.autocast():
            pre = self.policy(zs, t["goals"]).float()
            if self.discrete:
                policy_loss = F.cross_entropy(pre, self._best_actions(zs, t["goals"]))
            else:
                policy_loss = -self.value(self.encoder.zsa(zs, pre.tanh()), t["goals"]).float().mean()
        policy_loss = policy_loss + config.pre_activation_weight * pre.float().pow(2).mean()
        self.policy_optimiser.zero_grad(set_to_none=True)
        policy_loss.backward(inputs=list(self.policy.parameters()))
        self.policy_optimiser.step()

        priority = (q.detach() - target[:, None]).abs().max(-1).values.clamp(min=config.min_priority)
        priority = priority.pow(config.priority_alpha).cpu()
        self.priorities[torch.as_tensor(batch["slots"])] = priority
        self.counters[3] = max(float(self.counters[3]), float(priority.max()))
        self.counters[0] += 1
        return {"losses/q_loss": value_loss.item(), "losses/q_values": q.mean().item(),
                "losses/policy_loss": policy_loss.item(), **self.encoder_losses}  # fmt: skip

    def load_state_dict(self, state: dict) -> None:
        if "priorities" in state:  # made at the first sample, so its size comes from the checkpoint
            self.priorities = torch.zeros_like(state["priorities"])
        super().load_state_dict(state)


def _adamw(parameters, learning_rate: float, weight_decay: float) -> torch.optim.AdamW:
    """AdamW, fused where the device has the kernel."""
    parameters = list(parameters)
    try:
        return torch.optim.AdamW(parameters, lr=learning_rate, weight_decay=weight_decay, fused=True)
    except (RuntimeError, ValueError):
        return torch.optim.AdamW(parameters, lr=learning_rate, weight_decay=weight_decay)
