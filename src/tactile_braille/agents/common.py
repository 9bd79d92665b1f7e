"""What every agent shares: spaces, optimisers, precision, batches as tensors, checkpoints.

Speed decisions (measured by ``benchmarks/train_throughput.py``): Adam runs
*fused* (one kernel over all parameters; the per-parameter loop cost about as
much as the network's forward and backward together on a CPU), and
``precision="bf16"`` runs the networks under bfloat16 autocast (losses,
log-probabilities and targets stay float32). Neither changes the algorithm.
bf16 is fast only where the processor computes it natively (AVX512-BF16 or
AMX on x86, a CUDA device of compute capability 8 or more); elsewhere, as on
a CPU with AVX2 alone, torch emulates it and an update runs several times
slower than in float32 (``benchmarks/precision_cost.py``), so an agent made
with bf16 there warns once (:func:`native_bf16`).
"""

from __future__ import annotations

import abc
import contextlib
import functools
import warnings
from typing import ClassVar

import gymnasium as gym
import numpy as np
import torch

from tactile_braille.agents.config import PRECISIONS


def spaces_sizes(observation_space: gym.spaces.Dict) -> tuple[int, int]:
    """Lengths of the goal one-hot and of the previous-action vector."""
    try:
        return observation_space["desired_goal"].shape[0], observation_space["previous_action"].shape[0]
    except (KeyError, TypeError) as error:
        raise ValueError(
            f"agents need a goal-conditioned Dict observation space with 'observation', "
            f"'desired_goal' and 'previous_action', got {observation_space}"
        ) from error


def observation_features(observation_space: gym.spaces.Dict) -> int | None:
    """Length of a feature-vector observation, or None for the tactile image (networks add the encoder)."""
    shape = observation_space["observation"].shape
    return int(shape[0]) if len(shape) == 1 else None


def network_options(
    observation_space: gym.spaces.Dict, layer_norm: bool = False, unit_features: bool = False
) -> tuple[dict, dict]:
    """Keyword options of the actor's and the critics' networks: features (or the image's channels where
    it stacks several taps), and in critics LayerNorm and features scaled to unit length if asked."""
    actor: dict = {"features": observation_features(observation_space)}
    shape = observation_space["observation"].shape
    if len(shape) == 3 and shape[-1] > 1:
        actor["channels"] = int(shape[-1])
    critic = {**actor, "layer_norm": bool(layer_norm)}
    if unit_features:
        critic["unit_features"] = True
    return actor, critic


POSE_SIZE = 3
"""Length of the privileged pose an asymmetric critic sees: sensor x, y and tap depth."""


def critic_poses(batch: dict[str, torch.Tensor], wanted: bool) -> tuple[tuple, tuple]:
    """``((poses,), (next_poses,))`` of a batch for asymmetric critics, ``((), ())`` otherwise."""
    if not wanted:
        return (), ()
    if "poses" not in batch or "next_poses" not in batch:
        raise ValueError(
            "critic_pose needs batches with 'poses' and 'next_poses' (a replay with the SensorPoses extra)"
        )
    return (batch["poses"],), (batch["next_poses"],)


def every_goal_rewards(batch: dict[str, torch.Tensor], goal_size: int) -> torch.Tensor:
    """Each transition's reward under every goal, shape (B, goal_size), for an all-goals update:
    1 where it pressed key g (``achieved``, its achieved goal; -1 for no press), else 0."""
    if "achieved" not in batch:
        raise ValueError("all_goals needs batches with 'achieved' (a replay with the GoalOutcomes extra)")
    achieved = batch["achieved"]
    return (achieved[:, None] == torch.arange(goal_size, device=achieved.device)).float()


@functools.cache
def _cpu_flags() -> frozenset[str]:
    """The processor's feature flags as Linux reports them (empty elsewhere)."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as cpuinfo:
            for line in cpuinfo:
                if line.startswith("flags"):
                    return frozenset(line.partition(":")[2].split())
    except OSError:
        pass
    return frozenset()


def native_bf16(device: str | torch.device = "cpu") -> bool:
    """Whether ``device`` computes bfloat16 natively, so that bf16 autocast speeds its updates up.

    CUDA: ``torch.cuda.is_bf16_supported()``. CPU: oneDNN's own check where torch has it, else the
    processor's flags (``avx512_bf16`` or ``amx_bf16``). Elsewhere torch emulates bf16.
    """
    device = torch.device(device)
    if device.type == "cuda":
        return bool(torch.cuda.is_available() and torch.cuda.is_bf16_supported())
    if device.type != "cpu":
        return True  # no check known: take the user's word
    check = getattr(torch.ops.mkldnn, "_is_mkldnn_bf16_supported", None)
    if check is not None:
        try:
            return bool(check())
        except RuntimeError:
            pass
    return bool({"avx512_bf16", "amx_bf16"} & _cpu_flags())


BF16_EMULATED = (
    "bf16 autocast on this {device} is emulated (no native bfloat16: AVX512-BF16 or AMX on x86, compute "
    "capability 8 or more on CUDA), so updates run several times slower than in fp32 (python "
    "benchmarks/precision_cost.py measures it); pass --precision fp32 for speed. The committed Table III "
    "rows ran in bf16, and a run in fp32 makes a row of its own."
)


def chosen(values: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    """The values of the batch's actions: ``values`` (B, ..., actions) and ``actions`` (B,) give (B, ...)."""
    index = actions.reshape(-1, *[1] * (values.dim() - 1)).expand(*values.shape[:-1], 1)
    return values.gather(-1, index).squeeze(-1)


class Agent(abc.ABC):
    """The agent contract: what the training loop, checkpoints and evaluation call.

    An agent is registered with :func:`~tactile_braille.agents.registry.register_agent` and made by
    the training loop as ``AgentClass(observation_space, action_space, config, device, precision)``:
    the task's goal-conditioned Dict observation space (``observation``, ``desired_goal``,
    ``achieved_goal``, ``previous_action``), its action space, the agent's
    :class:`~tactile_braille.agents.config.AgentConfig`, a torch device and ``"fp32"`` or ``"bf16"``
    (call ``super().__init__(device, precision)``).

    The loop, each environment step: :meth:`random_action` during the run's start steps, else
    :meth:`policy_action` with ``explore=True``; the transition goes into the replay (the buffer
    :meth:`replay_extras` asks for). Each burst of updates: :meth:`update` on :meth:`sample`'s
    batch, whose returned losses are logged. Each epoch: :meth:`end_epoch`, then test episodes and
    typing with ``policy_action(..., explore=False)``. Checkpoints: :meth:`state_dict` /
    :meth:`load_state_dict` over the attributes named in ``checkpointed``; policy snapshots:
    :meth:`policy_state_dict` over ``policy_parts``.

    Subclasses must implement :meth:`policy_action` and :meth:`update`, and list their state in
    ``checkpointed`` (modules, optimisers, tensors) and what acting needs in ``policy_parts``.
    """

    checkpointed: ClassVar[tuple[str, ...]] = ()
    """The attributes that make up the agent's state (modules, optimisers, tensors), for checkpoints."""
    policy_parts: ClassVar[tuple[str, ...]] = ()
    """The parts that acting needs (a policy snapshot: no optimisers, no targets)."""

    @abc.abstractmethod
    def policy_action(
        self,
        observation: dict,
        step: int,
        explore: bool,
        rng: np.random.Generator,
        deterministic: bool = False,
    ):
        """The action for one observation dict: an ``int`` for a ``Discrete`` space, a float32 array in
        [-1, 1] for a ``Box``. ``step`` counts the run's environment steps (for exploration schedules);
        ``explore`` is True while training and False in test episodes and typing; ``deterministic``
        asks for the greedy action whatever the agent's test exploration. Draw randomness from ``rng``
        only, so that runs repeat exactly."""

    @abc.abstractmethod
    def update(self, batch: dict[str, np.ndarray]) -> dict[str, float]:
        """Learn from one batch of :meth:`sample`; returns the losses to log by name (namespaced, e.g.
        ``losses/q``). A name left out of one update keeps its last logged value."""

    @classmethod
    def replay_extras(cls, config) -> tuple:
        """What this agent's updates read from the replay beyond the transitions, for its ``config``: a
        tuple of :class:`~tactile_braille.agents.replay.BatchExtra` (the base: none)."""
        return ()

    def __init__(self, device: str | torch.device, precision: str) -> None:
        if precision not in PRECISIONS:
            raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
        self.device = torch.device(device)
        self.precision = precision
        if precision == "bf16" and not native_bf16(self.device):
            warnings.warn(BF16_EMULATED.format(device=self.device.type.upper()), RuntimeWarning, stacklevel=2)

    def autocast(self) -> contextlib.AbstractContextManager:
        """bfloat16 autocast for ``precision="bf16"``, nothing otherwise."""
        if self.precision == "bf16":
            return torch.autocast(self.device.type, dtype=torch.bfloat16)
        return contextlib.nullcontext()

    def tensors(self, batch: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
        """A replay batch on the agent's device."""
        return {
            name: torch.as_tensor(value).to(self.device, non_blocking=True) for name, value in batch.items()
        }

    def discount(self, t: dict[str, torch.Tensor]) -> torch.Tensor | float:
        """The discount of each target's bootstrapped value: ``gamma``, or ``gamma ** steps`` where the
        batch holds n-step returns (a buffer with ``n_step`` > 1: its batches carry ``steps``)."""
        return self.config.gamma if "steps" not in t else self.config.gamma ** t["steps"]

    def random_action(self, space: gym.Space, rng: np.random.Generator):
        """A uniformly random action of the start steps (in [-1, 1] for continuous actions)."""
        if isinstance(space, gym.spaces.Box):
            return rng.uniform(-1.0, 1.0, size=space.shape).astype(np.float32)
        return int(rng.integers(space.n))

    def sample(self, buffer, batch_size: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """What an update learns from: a batch of the replay's transitions (a model-based agent, the
        planner, reads its own from the replay)."""
        return buffer.sample(batch_size, rng)

    def end_epoch(self) -> None:  # noqa: B027 - an optional hook: most agents do nothing here
        """Called by the training loop after each epoch's steps and updates, before its test."""

    def state_dict(self) -> dict:
        state = {}
        for name in self.checkpointed:
            part = getattr(self, name)
            state[name] = part.detach().clone() if isinstance(part, torch.Tensor) else part.state_dict()
        return state

    def policy_state_dict(self) -> dict:
        """What :meth:`policy_action` needs, for policy snapshots."""
        return {name: getattr(self, name).state_dict() for name in self.policy_parts}

    def load_policy_state_dict(self, state: dict) -> None:
        """Restore a :meth:`policy_state_dict` (enough to act, not to train on)."""
        missing = set(self.policy_parts) - set(state)
        if missing:
            raise ValueError(f"policy snapshot lacks {sorted(missing)} for {type(self).__name__}")
        for name, part in state.items():
            getattr(self, name).load_state_dict(part)

    def load_state_dict(self, state: dict) -> None:
        missing = set(self.checkpointed) - set(state)
        if missing:
            raise ValueError(f"checkpoint lacks {sorted(missing)} for {type(self).__name__}")
        for name in self.checkpointed:
            part = getattr(self, name)
            if isinstance(part, torch.Tensor):
                with torch.no_grad():
                    part.copy_(state[name])
            else:
                part.load_state_dict(state[name])
