"""The paper's networks: an Atari-style encoder with the goal and previous action joined after it.

Encoder: conv 32/64/64 filters, kernels 8/4/3, strides 4/2/1, ReLU, no pooling,
on the 100x100x1 tactile image (5,184 features); it is
:class:`tactile_braille.supervised.networks.Encoder`, the paper's convolutions
written once for the classifier, the touch encoder and the agents. The goal
one-hot, the previous action (and, for continuous critics, the action) are
concatenated to the features, then dense layers (the paper's single layer of
512 units; the released continuous SAC used 1024 then 512). Weights use
variance-scaling (He) initialisation; output layers start near zero.

On *features* (``features=n``: the observation is already a vector of ``n``
features, such as those of a pretrained touch encoder,
:mod:`~tactile_braille.supervised.touch`) the encoder is left out and the
vectors join the features directly. ``layer_norm=True`` puts a LayerNorm
before each dense ReLU (as DroQ's critics), for high update-to-data ratios.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from tactile_braille.supervised.networks import Encoder, he_init

LOG_STD_MIN, LOG_STD_MAX = -5.0, 2.0
RELEASED_LOG_STD_MIN = -20.0
"""The released SAC's lower bound of the log deviation, reached through a tanh (``log_std="tanh"``)."""
LOG_STD_RULES = ("clamp", "tanh")


class GoalConditionedTrunk(nn.Module):
    """Image features joined with vectors (goal, previous action, ...), then dense ReLU layers.

    Args:
        vector_size: total length of the vectors joined after the encoder.
        hidden: units of each dense layer.
        features: the observation is a vector of this many features (no encoder).
        layer_norm: a LayerNorm before each dense layer's ReLU.
        channels: channels of the image its own encoder reads (more than one: stacked taps,
            :class:`~tactile_braille.envs.memory.TapMemory`).
        unit_features: the encoder's features are scaled to unit length before the vectors join
            them, so that a loss that grows them (an auxiliary head's) cannot drown the goal.
    """

    def __init__(
        self,
        vector_size: int,
        hidden: Sequence[int] = (512,),
        features: int | None = None,
        layer_norm: bool = False,
        channels: int = 1,
        unit_features: bool = False,
    ):
        super().__init__()
        self.unit_features = bool(unit_features)
        if not hidden or min(hidden) < 1:
            raise ValueError(f"hidden needs at least one positive layer size, got {hidden}")
        if features is not None and features < 1:
            raise ValueError(f"features={features} needs a positive size")
        self.encoder = None if features is not None else Encoder(channels)
        sizes = [(features or Encoder.output_size) + vector_size, *hidden]
        layers: list[nn.Module] = []
        for inputs, outputs in itertools.pairwise(sizes):
            layers += [
                nn.Linear(inputs, outputs),
                *([nn.LayerNorm(outputs)] if layer_norm else []),
                nn.ReLU(),
            ]
        self.dense = nn.Sequential(*layers)
        self.dense.apply(he_init)
        self.features = sizes[-1]
        self.encoded = features or Encoder.output_size
        """Length of :meth:`encode`'s features."""

    def encode(self, images: torch.Tensor) -> torch.Tensor:
        """The features the dense layers take before the vectors: the encoder's, or the vector given."""
        if self.encoder is None:
            return images.float()
        features = self.encoder(images)
        return F.normalize(features, dim=-1) if self.unit_features else features

    def forward(self, images: torch.Tensor, *vectors: torch.Tensor) -> torch.Tensor:
        return self.dense(torch.cat([self.encode(images), *vectors], dim=-1))

    def every_goal(
        self, images: torch.Tensor, previous_actions: torch.Tensor, goal_size: int, *vectors: torch.Tensor
    ) -> torch.Tensor:
        """The dense layers' output under every goal one-hot, shape (B, goal_size, features), from one
        pass of the encoder (for a trunk whose vectors are the goal, the previous action, then
        ``vectors``: each (B, n), the same under every goal, or (B, goal_size, n), one per goal)."""
        features = self.encode(images)
        batch = len(features)
        goals = torch.eye(goal_size, dtype=features.dtype, device=features.device).expand(batch, -1, -1)
        per_goal = [
            vector.to(features.dtype)
            if vector.dim() == 3
            else vector.to(features.dtype)[:, None].expand(-1, goal_size, -1)
            for vector in (features, previous_actions, *vectors)
        ]
        return self.dense(torch.cat([per_goal[0], goals, *per_goal[1:]], dim=-1))


def _small_head(inputs: int, outputs: int) -> nn.Linear:
    """A linear output layer initialised near zero (Q near 0, policy near uniform)."""
    head = nn.Linear(inputs, outputs)
    nn.init.normal_(head.weight, std=0.01)
    nn.init.zeros_(head.bias)
    return head


def _dueling(value: torch.Tensor | None, advantage: torch.Tensor) -> torch.Tensor:
    """``Q = V + A - mean(A)`` over the last (action) axis; ``value`` has a size-1 axis in its place.
    Without a value head (``None``: plain Q heads) the advantage head's outputs are the Q-values."""
    if value is None:
        return advantage
    return value + advantage - advantage.mean(dim=-1, keepdim=True)


TRUNCATED_NORMAL_STD = 0.87962566103423978
"""The deviation of a unit normal truncated at +-2: TensorFlow divides by it so that the truncated
draws keep the wanted variance."""


def released_init(module: nn.Module) -> None:
    """The released code's initial weights for a convolution or dense layer, else nothing: variance
    scaling 1.0 over the fan-in from a normal truncated at two deviations (TensorFlow's
    ``variance_scaling(scale=1.0)``, LeCun's), zero biases. For ``module.apply(released_init)``."""
    if isinstance(module, nn.Conv2d | nn.Linear):
        std = math.sqrt(1.0 / module.weight[0].numel()) / TRUNCATED_NORMAL_STD
        nn.init.trunc_normal_(module.weight, std=std, a=-2 * std, b=2 * std)
        if module.bias is not None:
            nn.init.zeros_(module.bias)


def check_weights_init(weights_init: str) -> None:
    """Refuse an initialisation other than ``"he"`` (ours) and ``"released"``."""
    if weights_init not in ("he", "released"):
        raise ValueError(f"weights_init must be 'he' or 'released', got {weights_init!r}")


def released_head_init(head: nn.Linear) -> None:
    """The released code's initial weights for an output layer of its continuous agents (TensorFlow's
    dense default): Glorot-uniform weights, zero biases."""
    nn.init.xavier_uniform_(head.weight)
    nn.init.zeros_(head.bias)


def _released_continuous(trunk: nn.Module, heads: Sequence[nn.Linear], weights_init: str) -> None:
    """Give a continuous agent's network the released code's initial weights where asked: variance
    scaling for the encoder and dense layers, Glorot for the heads (else leave ours)."""
    check_weights_init(weights_init)
    if weights_init == "released":
        trunk.apply(released_init)
        for head in heads:
            released_head_init(head)


def _check_action_scale(action_scale: float) -> None:
    if not action_scale > 0:
        raise ValueError(f"action_scale must be positive, got {action_scale}")


def _goal_row(every: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
    """Each observation's row of ``every`` (B, goal_size, ...) for its goal one-hot (B, goal_size)."""
    return (every * goals.to(every.dtype).reshape(*goals.shape, *[1] * (every.dim() - 2))).sum(dim=1)


class DuelingQNetwork(nn.Module):
    """Q-values of discrete actions with a dueling head: ``Q = V + A - mean(A)`` (or, with
    ``dueling=False``, a plain head of Q-values).

    With ``goal_heads`` the goal does not join the trunk: the heads give every goal's
    values at once (``V`` per goal, ``A`` per goal and action), and the goal one-hot
    picks its row. Either way :meth:`every_goal` gives the values of each observation
    under every goal from one pass of the encoder, which an update on every goal needs.

    Args:
        num_actions: discrete actions.
        goal_size: length of the goal one-hot.
        previous_action_size: length of the previous-action vector.
        hidden: units of the dense layers (the paper's 512).
        goal_heads: heads for every goal instead of the goal as an input.
        dueling_split: the value head reads the first half of the last dense layer's units, the
            advantage head the rest (the released code's); otherwise both read all of them.
        weights_init: ``"he"`` (ours) or ``"released"`` (:func:`released_init` for every layer).
        dueling: a value and an advantage head; ``False``: one head of Q-values (the released
            discrete SAC's critics), which leaves ``dueling_split`` nothing to split.
        goal_difference: the goal does not join the trunk: a linear layer gives the observation a
            learnt *place* of this many numbers, a linear embedding gives the goal one, and a dense
            ReLU layer reads their difference (the heads read it): values that depend on where the
            goal lies from the sensor, the same rule for every pair of keys (a two-stream UVFA with
            a difference). 0: the goal is an input (the paper's).
        options: ``features`` and ``layer_norm`` of :class:`GoalConditionedTrunk`.
    """

    def __init__(
        self,
        num_actions: int,
        goal_size: int,
        previous_action_size: int,
        hidden: Sequence[int] = (512,),
        goal_heads: bool = False,
        dueling_split: bool = False,
        weights_init: str = "he",
        dueling: bool = True,
        goal_difference: int = 0,
        **options,
    ) -> None:
        super().__init__()
        check_weights_init(weights_init)
        if dueling_split and not dueling:
            raise ValueError("dueling_split splits a dueling network's units: it needs dueling=True")
        if goal_difference and goal_heads:
            raise ValueError("a network takes the goal through goal_heads or goal_difference, not both")
        self.goal_heads, self.goal_size, self.num_actions = goal_heads, goal_size, num_actions
        goal_input = not (goal_heads or goal_difference)
        vector_size = goal_size + previous_action_size if goal_input else previous_action_size
        heads = goal_size if goal_heads else 1
        self.trunk = GoalConditionedTrunk(vector_size, hidden, **options)
        units = self.trunk.features
        self.difference = None
        if goal_difference:
            self.difference = GoalDifference(units, goal_size, goal_difference)
        self.split = units // 2 if dueling_split else 0
        self.value = _small_head(self.split or units, heads) if dueling else None
        self.advantage = _small_head(units - self.split, heads * num_actions)
        if weights_init == "released":
            self.apply(released_init)

    def forward(
        self, images: torch.Tensor, goals: torch.Tensor, previous_actions: torch.Tensor
    ) -> torch.Tensor:
        if self.goal_heads:
            return _goal_row(self.every_goal(images, previous_actions), goals)
        if self.difference is not None:
            return _dueling(*self._heads(self.difference(self.trunk(images, previous_actions), goals)))
        return _dueling(*self._heads(self.trunk(images, goals, previous_actions)))

    def every_goal(self, images: torch.Tensor, previous_actions: torch.Tensor) -> torch.Tensor:
        """Q-values under every goal, shape (B, goal_size, num_actions), from one pass of the
        encoder: with ``goal_heads`` from every head, else the dense layers run once per goal."""
        if self.goal_heads:
            value, advantage = self._heads(self.trunk(images, previous_actions))
            value = None if value is None else value[..., None]
            return _dueling(value, advantage.unflatten(-1, (self.goal_size, self.num_actions)))
        if self.difference is not None:
            return _dueling(*self._heads(self.difference.every_goal(self.trunk(images, previous_actions))))
        return _dueling(*self._heads(self.trunk.every_goal(images, previous_actions, self.goal_size)))

    def _heads(self, hidden: torch.Tensor) -> tuple[torch.Tensor | None, torch.Tensor]:
        """The value and advantage heads' outputs, each on its half of the units where split (no
        value without a value head)."""
        if self.split:
            return self.value(hidden[..., : self.split]), self.advantage(hidden[..., self.split :])
        return (None if self.value is None else self.value(hidden)), self.advantage(hidden)


class GoalDifference(nn.Module):
    """Dense ReLU units on the difference of two learnt places, the observation's (a linear layer on
    the trunk's units) and the goal's (a linear embedding of its one-hot): ``ReLU(W (place(h) -
    embed(g)) + b)``, as many units as the trunk's."""

    def __init__(self, units: int, goal_size: int, size: int) -> None:
        super().__init__()
        self.place = nn.Linear(units, size)
        self.goal_place = nn.Linear(goal_size, size, bias=False)
        self.dense = nn.Sequential(nn.Linear(size, units), nn.ReLU())
        he_init(self.place)
        he_init(self.dense[0])
        nn.init.kaiming_normal_(self.goal_place.weight, nonlinearity="relu")

    def forward(self, hidden: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
        return self.dense(self.place(hidden) - self.goal_place(goals.to(hidden.dtype)))

    def every_goal(self, hidden: torch.Tensor) -> torch.Tensor:
        """The units under every goal, shape (B, goal_size, units): each goal's place is its column."""
        places = self.goal_place.weight.T.to(hidden.dtype)  # (goal_size, size)
        return self.dense(self.place(hidden)[:, None] - places[None])


class PolicyNetwork(nn.Module):
    """Categorical policy over discrete actions (same trunk, a logits head).

    ``goal_heads`` and :meth:`every_goal` as :class:`DuelingQNetwork`'s: a logits head per goal
    instead of the goal as an input, and every goal's probabilities from one pass of the encoder;
    ``weights_init`` as its too.
    """

    def __init__(
        self,
        num_actions: int,
        goal_size: int,
        previous_action_size: int,
        hidden: Sequence[int] = (512,),
        goal_heads: bool = False,
        weights_init: str = "he",
        **options,
    ) -> None:
        super().__init__()
        check_weights_init(weights_init)
        self.goal_heads, self.goal_size, self.num_actions = goal_heads, goal_size, num_actions
        vector_size = previous_action_size if goal_heads else goal_size + previous_action_size
        self.trunk = GoalConditionedTrunk(vector_size, hidden, **options)
        self.logits = _small_head(self.trunk.features, (goal_size if goal_heads else 1) * num_actions)
        if weights_init == "released":
            self.apply(released_init)

    def forward(self, images, goals, previous_actions) -> tuple[torch.Tensor, torch.Tensor]:
        """Action probabilities and their logs."""
        if self.goal_heads:
            logits = _goal_row(self._every_logits(images, previous_actions), goals)
        else:
            logits = self.logits(self.trunk(images, goals, previous_actions)).float()
        return F.softmax(logits, dim=-1), F.log_softmax(logits, dim=-1)

    def every_goal(self, images, previous_actions) -> tuple[torch.Tensor, torch.Tensor]:
        """Probabilities and their logs under every goal, shape (B, goal_size, num_actions)."""
        logits = self._every_logits(images, previous_actions)
        return F.softmax(logits, dim=-1), F.log_softmax(logits, dim=-1)

    def _every_logits(self, images, previous_actions) -> torch.Tensor:
        if self.goal_heads:
            hidden = self.trunk(images, previous_actions)
            return self.logits(hidden).float().unflatten(-1, (self.goal_size, self.num_actions))
        return self.logits(self.trunk.every_goal(images, previous_actions, self.goal_size)).float()


class ContinuousQNetwork(nn.Module):
    """Q(s, g, a) of a continuous action: the action joins the goal after the encoder.

    ``pose_size`` > 0 makes it an *asymmetric* critic: it also takes a privileged
    state vector (the sensor pose), which the actor never sees. ``action_scale``
    multiplies the actions (previous and valued) before they join: the released
    code's networks read them in mm, ours in [-1, 1] (scale 1). ``weights_init``:
    ``"released"`` gives every layer variance scaling and the head Glorot weights.
    """

    def __init__(
        self,
        action_size: int,
        goal_size: int,
        previous_action_size: int,
        hidden: Sequence[int] = (512,),
        pose_size: int = 0,
        weights_init: str = "he",
        action_scale: float = 1.0,
        **options,
    ) -> None:
        super().__init__()
        if pose_size < 0:
            raise ValueError(f"pose_size must be at least 0, got {pose_size}")
        _check_action_scale(action_scale)
        vector_size = goal_size + previous_action_size + action_size + pose_size
        self.trunk = GoalConditionedTrunk(vector_size, hidden, **options)
        self.q = _small_head(self.trunk.features, 1)
        self.pose_size, self.action_scale, self.goal_size = pose_size, action_scale, goal_size
        _released_continuous(self.trunk, [self.q], weights_init)

    def forward(self, images, goals, previous_actions, actions, poses=None) -> torch.Tensor:
        """Q-values, shape (B,); ``poses`` (B, pose_size) for an asymmetric critic, else None."""
        self._check_poses(poses)
        previous_actions, actions = previous_actions * self.action_scale, actions * self.action_scale
        vectors = (
            (goals, previous_actions, actions) if poses is None else (goals, previous_actions, actions, poses)
        )
        return self.q(self.trunk(images, *vectors)).squeeze(-1).float()

    def every_goal(self, images, previous_actions, actions, poses=None) -> torch.Tensor:
        """Q-values under every goal, shape (B, goal_size), from one pass of the encoder; ``actions``
        (B, n), the same action under every goal, or (B, goal_size, n), one per goal."""
        self._check_poses(poses)
        vectors = (actions * self.action_scale,) if poses is None else (actions * self.action_scale, poses)
        hidden = self.trunk.every_goal(images, previous_actions * self.action_scale, self.goal_size, *vectors)
        return self.q(hidden).squeeze(-1).float()

    def _check_poses(self, poses: torch.Tensor | None) -> None:
        if poses is None and self.pose_size:
            raise ValueError(f"this asymmetric critic needs poses of size {self.pose_size}, got none")
        if poses is not None and not self.pose_size:
            raise ValueError("this critic takes no poses (pose_size=0), but was given some")


class GaussianPolicy(nn.Module):
    """SAC's tanh-squashed Gaussian policy over actions in [-1, 1].

    ``log_std``: ``"clamp"`` (ours) clips the log deviation to [-5, 2]; ``"tanh"`` (the
    released code's) maps it through a tanh onto [-20, 2] (-9 where the head's output is 0).
    ``action_scale`` and ``weights_init`` as :class:`ContinuousQNetwork`'s (the
    previous action is scaled; the policy's own actions stay in [-1, 1]).
    """

    def __init__(
        self,
        action_size: int,
        goal_size: int,
        previous_action_size: int,
        hidden: Sequence[int] = (512,),
        weights_init: str = "he",
        log_std: str = "clamp",
        action_scale: float = 1.0,
        **options,
    ) -> None:
        super().__init__()
        if log_std not in LOG_STD_RULES:
            raise ValueError(f"log_std must be one of {LOG_STD_RULES}, got {log_std!r}")
        _check_action_scale(action_scale)
        self.trunk = GoalConditionedTrunk(goal_size + previous_action_size, hidden, **options)
        self.mean = _small_head(self.trunk.features, action_size)
        self.log_std = _small_head(self.trunk.features, action_size)
        self.log_std_rule, self.action_scale, self.goal_size = log_std, action_scale, goal_size
        _released_continuous(self.trunk, [self.mean, self.log_std], weights_init)

    def forward(self, images, goals, previous_actions) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """A reparameterised sample, its log-probability (B,), and the deterministic action."""
        return self._sample(self.trunk(images, goals, previous_actions * self.action_scale))

    def every_goal(self, images, previous_actions) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The same under every goal, from one pass of the encoder: samples and deterministic actions
        (B, goal_size, n), log-probabilities (B, goal_size)."""
        previous_actions = previous_actions * self.action_scale
        return self._sample(self.trunk.every_goal(images, previous_actions, self.goal_size))

    def _sample(self, hidden: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        mean, log_std = self.mean(hidden).float(), self.log_deviation(hidden)
        std = log_std.exp()
        noise = torch.randn_like(mean)
        raw = mean + std * noise
        action = torch.tanh(raw)
        # Gaussian log-density, minus the tanh Jacobian in its stable form:
        # log(1 - tanh(u)^2) = 2 (log 2 - u - softplus(-2u)).
        log_prob = (-0.5 * noise.pow(2) - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)
        log_prob = log_prob - (2 * (math.log(2) - raw - F.softplus(-2 * raw))).sum(-1)
        return action, log_prob, torch.tanh(mean)

    def log_deviation(self, hidden: torch.Tensor) -> torch.Tensor:
        """The log deviation of each action's Gaussian, from the dense layers' output, within bounds."""
        raw = self.log_std(hidden).float()
        if self.log_std_rule == "tanh":
            low = RELEASED_LOG_STD_MIN
            return low + 0.5 * (LOG_STD_MAX - low) * (torch.tanh(raw) + 1)
        return raw.clamp(LOG_STD_MIN, LOG_STD_MAX)


class DeterministicPolicy(nn.Module):
    """TD3's deterministic policy: ``tanh`` of a linear head, actions in [-1, 1]. ``action_scale``
    and ``weights_init`` as :class:`ContinuousQNetwork`'s."""

    def __init__(
        self,
        action_size: int,
        goal_size: int,
        previous_action_size: int,
        hidden: Sequence[int] = (512,),
        weights_init: str = "he",
        action_scale: float = 1.0,
        **options,
    ) -> None:
        super().__init__()
        _check_action_scale(action_scale)
        self.trunk = GoalConditionedTrunk(goal_size + previous_action_size, hidden, **options)
        self.action = _small_head(self.trunk.features, action_size)
        self.action_scale = action_scale
        _released_continuous(self.trunk, [self.action], weights_init)

    def forward(self, images, goals, previous_actions) -> torch.Tensor:
        hidden = self.trunk(images, goals, previous_actions * self.action_scale)
        return torch.tanh(self.action(hidden).float())


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
    online_params, target_params = list(online.parameters()), list(target.parameters())
    if len(online_params) != len(target_params):
        raise ValueError("online and target networks differ")
    torch._foreach_lerp_(target_params, online_params, tau)
