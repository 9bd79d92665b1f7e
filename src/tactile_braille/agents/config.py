"""A training run's settings as data: nested frozen dataclasses, validated field by field, torch-free.

``TrainConfig`` holds the loop's schedule and the run's environment and
machine settings, and one group per concern: ``agent`` (the algorithm's
hyperparameters, an :class:`AgentConfig`: :class:`DQNConfig`,
:class:`DiscreteSACConfig`, :class:`SACConfig`, :class:`TD3Config`, :class:`MRQConfig`,
:class:`PlannerConfig`, or the class an agent registers with
:mod:`~tactile_braille.agents.registry`), ``replay`` (:class:`ReplayConfig`),
``touch`` (:class:`TouchConfig`, the touch encoder of the ``fast`` preset) and
``evaluation`` (:class:`EvaluationConfig`). Each field's default is the
paper's (Table II, the released code where the table is silent), written
once, here; presets (:mod:`~tactile_braille.agents.presets`) are
``dataclasses.replace`` of these defaults.

Every field is checked against its annotation when a config is made (a
``Literal`` lists the accepted values, ``int | None`` accepts None), then
against its range; a bad value raises a ``ValueError`` that names the field.
The command line is generated from the same annotations
(:func:`tactile_braille.cli` ``train --help``), and this module imports no
torch, so that parsing and validating a command is quick.

>>> config = TrainConfig(algo="sac", task="tactile_braille/ContinuousArrows-v0")
>>> config.agent.gamma, config.replay.relabel, config.updates_per_step
(0.95, 'paper', 2)
>>> replace_settings(config, {"agent": {"hidden": (256, 256)}, "epochs": 3}).agent.hidden
(256, 256)
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal, Union

from tactile_braille.envs.world import (
    BACKENDS,  # noqa: F401 - re-exported for the command line
    Backend,
    Edges,
    KeyGrid,
    TapDepth,
    check_frame_noise,
    check_world,
)

# The world's value sets and rules are the environments' (torch-free).

Precision = Literal["fp32", "bf16"]
RelabelRule = Literal["paper", "all"]
TouchInputs = Literal["features", "readout"]
TouchLabels = Literal["robot", "observation"]
TargetUpdate = Literal["update", "epoch"]
QLoss = Literal["mse", "huber"]
GoalWeights = Literal["uniform", "relabel"]
WeightsInit = Literal["he", "released"]
LogStdRule = Literal["clamp", "tanh"]
Track = Literal["tactile", "proprio"]

PRECISIONS: tuple[str, ...] = typing.get_args(Precision)
RELABELLING: tuple[str, ...] = typing.get_args(RelabelRule)
TOUCH_INPUTS: tuple[str, ...] = typing.get_args(TouchInputs)
TOUCH_LABELS: tuple[str, ...] = typing.get_args(TouchLabels)
TRACKS: tuple[str, ...] = typing.get_args(Track)
"""The benchmark's tracks (docs/benchmark.md). ``tactile``: the paper's rules, the agent and every loss
see only the observation dictionary and the reward. ``proprio``: also what a calibrated robot knows, the
arm's pose at each tap and the calibrated key layout."""


HYPERPARAMETER_RANGES: dict[str, tuple[str, Any]] = {
    "batch_size": ("must be at least 1", lambda v: v >= 1),
    "gamma": ("must be in [0, 1]", lambda v: 0.0 <= v <= 1.0),
    "test_gamma": ("must be in [0, 1] (or None: gamma)", lambda v: v is None or 0.0 <= v <= 1.0),
    "tau": ("must be in (0, 1]", lambda v: 0.0 < v <= 1.0),
    "pressed_key": ("is a loss weight: at least 0", lambda v: v >= 0),
    **dict.fromkeys(
        ("learning_rate", "alpha_learning_rate", "initial_alpha", "adam_eps", "action_input_scale"),
        ("must be positive", lambda v: v > 0),
    ),
    "hidden": ("needs at least one positive layer size", lambda v: bool(v) and min(v) >= 1),
    **dict.fromkeys(
        ("epsilon_decay_steps", "noise_decay_steps", "policy_delay", "schedule_interval"),
        ("must be at least 1", lambda v: v >= 1),
    ),
    **dict.fromkeys(
        ("epsilon_start", "epsilon_end", "test_epsilon", "target_entropy_ratio"),
        ("must be in [0, 1]", lambda v: 0.0 <= v <= 1.0),
    ),
    **dict.fromkeys(
        ("noise_start", "noise_end", "test_noise", "target_noise", "noise_clip"),
        ("must not be negative", lambda v: v >= 0),
    ),
}
"""The ranges of hyperparameters that mean the same in every agent that has them, by field name: what a
value must be, and the check. :class:`AgentConfig` applies each to the fields its subclass has."""


def _check_hyperparameters(config: AgentConfig) -> None:
    """Refuse hyperparameters of a wrong type, or out of :data:`HYPERPARAMETER_RANGES`."""
    check_types(config)
    problems = []
    for spec in dataclasses.fields(config):
        if spec.name in HYPERPARAMETER_RANGES:
            rule, holds = HYPERPARAMETER_RANGES[spec.name]
            value = getattr(config, spec.name)
            if not holds(value):
                problems.append(f"{spec.name} {rule}, got {value}")
    if problems:
        raise ValueError(f"{type(config).__name__}: " + "; ".join(problems))


Choice = tuple
"""A categorical dimension of a search space: its values."""


@dataclass(frozen=True)
class Range:
    """A numeric dimension of a search space: ``low`` to ``high``, on a log scale with ``log``."""

    low: float
    high: float
    log: bool = False


Space = dict[str, "Range | Choice"]
"""A search space: each setting's name and the values a trial may give it."""


@dataclass(frozen=True)
class AgentConfig:
    """Base of every agent's hyperparameters (:class:`~tactile_braille.agents.registry.AgentSpec`'s
    ``config``): a frozen dataclass whose every field has a default.

    The training loop reads ``batch_size`` (samples per update) of every agent's config, and the
    replay ``gamma`` (the discount of n-step returns) where ``replay.n_step`` > 1. Fields are checked
    against their annotations when a config is made, and the usual hyperparameters against their
    ranges (:data:`HYPERPARAMETER_RANGES`). An agent whose settings constrain the rest of the run
    says so in :meth:`check_run`; one whose settings use what only a calibrated robot knows lists
    them in :meth:`proprio_settings`.
    """

    search_space: ClassVar[Space] = {}
    """The hyperparameters the benchmark's search may change (:mod:`tactile_braille.search`): each
    field's name with a :class:`~tactile_braille.search.Range` or a ``Choice`` of its values. Empty:
    the agent has no search (``tactile-braille tune`` refuses it)."""

    def __post_init__(self) -> None:
        _check_hyperparameters(self)

    def check_run(self, run: TrainConfig) -> None:
        """Refuse run settings this agent cannot learn with (a ``ValueError`` that names them); called
        when a :class:`TrainConfig` is made. The base accepts every run."""

    def proprio_settings(self) -> dict[str, str]:
        """This agent's settings that use the arm's pose or the calibrated key layout (the ``proprio``
        track), each with what it uses; the base has none."""
        return {}


@dataclass(frozen=True)
class DQNConfig(AgentConfig):
    """Hyperparameters (defaults: the paper's Table II).

    Attributes:
        gamma: discount.
        learning_rate: Adam's step size.
        adam_eps: Adam's epsilon (the released code's 1e-4; torch's default is 1e-8).
        tau: the share of the way the target network moves towards the online one at each
            target update (the paper's Polyak 0.005 per update; the released code moved it
            0.995 of the way once per epoch).
        target_update: when the target moves: after every gradient ``"update"`` (the paper's
            Table II) or at the end of every ``"epoch"`` (the released code).
        loss: the TD loss: ``"mse"`` (half the mean squared error, the released code's) or
            ``"huber"`` (smooth L1).
        epsilon_start, epsilon_end: exploration at the start and end of the schedule.
        epsilon_decay_steps: environment steps over which epsilon decays linearly.
        schedule_interval: epsilon follows its schedule in steps of this many environment steps
            (1: every step; the released code: once per 250-step epoch, a staircase).
        test_epsilon: exploration during test episodes (the paper: 0, deterministic;
            the released code: 0.05).
        batch_size: transitions per update.
        hidden: units of the dense layers after the encoder.
        layer_norm: LayerNorm in the Q-network's dense layers (as DroQ's critics).
        unit_features: the Q-network's image features are scaled to unit length before the goal
            and the previous action join them (an auxiliary loss on the encoder, such as
            ``pressed_key``'s, otherwise grows them until the goal has no say).
        all_goals: every update teaches every goal (Kaelbling's all-goals update): each sampled
            transition's target is computed for each goal from its pressed key (the achieved
            goal, an observation) and the reward rule; the episode's end does not depend on the
            goal. ``False``: the sampled goal only.
        all_goals_weights: how an all-goals update weighs each transition's goals: ``"uniform"``
            (each goal alike) or ``"relabel"`` (as likely as the replay's relabelling would
            sample it: the update is the relabelling's expected one, every goal computed).
        goal_heads: the goal picks one of the Q-network's heads (one per goal) instead of
            joining its dense layers as an input (the paper's).
        dueling_split: the value head reads the first half of the last dense layer's units and
            the advantage head the second half, as the released code (``False``: both read all).
        weights_init: the networks' initial weights: ``"he"`` (ours: He-normal layers, heads near
            zero) or ``"released"`` (the released code's: variance scaling 1.0 over the fan-in from
            a truncated normal, LeCun's, for every layer and head).
        pressed_key: the weight of an auxiliary loss on the Q-network's encoder: a linear head
            names the key under the sensor from the frames PRESS was chosen on, each labelled with
            the key its press pressed (the achieved goal, an observation: the ``tactile`` track; on
            the discrete tasks a press does not move). Each update adds a batch of such frames
            (``batch_size``) beside the TD batch. 0: none.
        return_bound: each TD target is at least the discounted return the transition's own
            episode went on to get under its (relabelled) goal: ``gamma ** k`` where that episode
            pressed the goal key ``k`` steps later. The moves are deterministic, so it is a lower
            bound of the optimal value (optimality tightening, He et al. 2017), and a press
            teaches every step before it at once where one-step targets spread it a step per
            target update. Elsewhere the bound is 0, which floors the targets at 0 (no reward is
            negative). Single-goal updates only.
        return_bound_after: the bound applies once the replay holds this many transitions (about
            as many environment steps; 0: from the start; before it the targets are still floored at
            0), so that the presses of the first epochs, which teach the key under the sensor, come
            before moving is made to pay.
        goal_difference: the goal leaves the Q-network's input: the dense layers read the
            difference between a learnt place of the observation and one of the goal, of this many
            numbers (:class:`~tactile_braille.agents.networks.GoalDifference`). 0: the goal is an
            input (the paper's).
    """

    gamma: float = 0.95
    learning_rate: float = 5e-4
    adam_eps: float = 1e-4
    tau: float = 0.005
    target_update: TargetUpdate = "update"
    loss: QLoss = "mse"
    epsilon_start: float = 1.0
    epsilon_end: float = 0.1
    epsilon_decay_steps: int = 2000
    schedule_interval: int = 1
    test_epsilon: float = 0.0
    batch_size: int = 32
    hidden: tuple[int, ...] = (512,)
    layer_norm: bool = False
    unit_features: bool = False
    all_goals: bool = False
    all_goals_weights: GoalWeights = "uniform"
    goal_heads: bool = False
    dueling_split: bool = False
    weights_init: WeightsInit = "he"
    pressed_key: float = 0.0
    return_bound: bool = False
    return_bound_after: int = 0
    goal_difference: int = 0

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.goal_difference < 0:
            raise ValueError(f"goal_difference is a size: at least 0, got {self.goal_difference}")
        if self.goal_difference and self.goal_heads:
            raise ValueError("goal_difference and goal_heads each take the goal from the input: choose one")
        if self.return_bound_after < 0 or (self.return_bound_after and not self.return_bound):
            after = self.return_bound_after
            raise ValueError(f"return_bound_after={after} is a number of transitions, at least 0, and needs "
                             "return_bound")  # fmt: skip
        if self.return_bound and self.all_goals:
            raise ValueError("return_bound bounds the sampled goal's target; all_goals computes every goal's")
        if self.all_goals_weights != "uniform" and not self.all_goals:
            raise ValueError(
                "agent.all_goals_weights weighs the goals of an all-goals update: set agent.all_goals"
            )

    def check_run(self, run: TrainConfig) -> None:
        check_goal_inputs(run, self.all_goals, self.goal_heads)


@dataclass(frozen=True)
class SACConfig(AgentConfig):
    """Hyperparameters (defaults: the paper's Table II).

    Attributes:
        gamma: discount.
        learning_rate: actor and critic step size.
        alpha_learning_rate: temperature step size.
        adam_eps: Adam's epsilon, for every optimiser (the released code's 1e-4).
        initial_alpha: the temperature at the start (the paper's 1). The entropy bonus pays
            every step alive, and pressing ends an episode: a high temperature delays the first
            presses until it has fallen (docs/agents.md).
        target_entropy: entropy the temperature steers the policy towards
            (the paper's -6 for a 3-D action; the usual choice is -3).
        tau: Polyak factor of the target critics (the paper's polyak 0.995).
        batch_size: transitions per update.
        hidden: units of the dense layers (the paper's 512; the released code's 1024, 512).
        layer_norm: LayerNorm in the critics' dense layers (as DroQ's critics).
        critic_pose: asymmetric critics that also see the sensor pose (batches then carry
            ``poses`` and ``next_poses``); the actor still acts on touch alone.
        weights_init: ``"he"`` (ours: He-normal layers, heads near zero) or ``"released"`` (the
            released code's: variance scaling 1.0 over the fan-in for the encoder and dense layers,
            Glorot-uniform heads).
        log_std: the policy's log deviation ``"clamp"``-ed to [-5, 2] (ours) or mapped by a
            ``"tanh"`` onto [-20, 2] (the released code's).
        action_input_scale: actions (the previous one, and the one a critic values) are multiplied
            by this before they join the networks: 1 (ours, [-1, 1]) or the task's largest move in
            mm (the released code's networks read actions in mm).
        all_goals: every update teaches every goal, as DQN's: the critics' targets, the actor's
            loss and the temperature's entropy are computed under each goal (the goal one-hot an
            input, the encoder run once) for each sampled transition. ``False``: the sampled goal only.
    """

    gamma: float = 0.95
    learning_rate: float = 5e-4
    alpha_learning_rate: float = 1e-3
    adam_eps: float = 1e-4
    initial_alpha: float = 1.0
    target_entropy: float = -6.0
    tau: float = 0.005
    batch_size: int = 32
    hidden: tuple[int, ...] = (512,)
    layer_norm: bool = False
    critic_pose: bool = False
    weights_init: WeightsInit = "he"
    log_std: LogStdRule = "clamp"
    action_input_scale: float = 1.0
    all_goals: bool = False

    def check_run(self, run: TrainConfig) -> None:
        check_goal_inputs(run, self.all_goals)
        check_critic_pose(run, self.critic_pose)

    def proprio_settings(self) -> dict[str, str]:
        return {"agent.critic_pose": CRITIC_POSE_USES} if self.critic_pose else {}


@dataclass(frozen=True)
class DiscreteSACConfig(AgentConfig):
    """Hyperparameters (defaults: the paper's Table II).

    Attributes:
        gamma: discount (the paper's 0.6 for discrete SAC).
        learning_rate: actor and critic step size.
        alpha_learning_rate: temperature step size.
        adam_eps: Adam's epsilon, for every optimiser (the released code's 1e-4).
        initial_alpha: the temperature at the start (the paper's 1). The entropy bonus pays
            every step alive, and pressing ends an episode: a high temperature delays the first
            presses until it has fallen (docs/agents.md).
        target_entropy_ratio: target entropy as a share of the maximum,
            ``ln(num_actions)`` (the released code's 0.1; the paper quotes
            the resulting 0.139, i.e. 0.1 ln 4).
        tau: Polyak factor of the target critics (per update).
        batch_size: transitions per update.
        hidden: units of the dense layers after the encoder.
        layer_norm: LayerNorm in the critics' dense layers (as DroQ's critics).
        all_goals: every update teaches every goal, as DQN's: the critics' targets, the actor's
            loss and the temperature's entropy are computed under each goal for each sampled
            transition. ``False``: the sampled goal only.
        goal_heads: the goal picks one of the critics' and the actor's heads (one per goal)
            instead of joining their dense layers as an input (the paper's).
        dueling: the critics' heads: dueling (value and advantage; ours) or,
            ``False``, one head of Q-values (the released code's; the paper names dueling heads
            for its DQN only).
        weights_init: the actor's and critics' initial weights, as :class:`DQNConfig`'s.
    """

    gamma: float = 0.6
    learning_rate: float = 5e-4
    alpha_learning_rate: float = 1e-3
    adam_eps: float = 1e-4
    initial_alpha: float = 1.0
    target_entropy_ratio: float = 0.1
    tau: float = 0.005
    batch_size: int = 32
    hidden: tuple[int, ...] = (512,)
    layer_norm: bool = False
    all_goals: bool = False
    goal_heads: bool = False
    dueling: bool = True
    weights_init: WeightsInit = "he"

    def check_run(self, run: TrainConfig) -> None:
        check_goal_inputs(run, self.all_goals, self.goal_heads)


@dataclass(frozen=True)
class TD3Config(AgentConfig):
    """Hyperparameters (defaults: the paper's Table II).

    Attributes:
        gamma: discount.
        learning_rate: actor and critic step size (the paper's 5e-5; the released code's 7.5e-5).
        adam_eps: Adam's epsilon, for both optimisers (the released code's 1e-4).
        tau: Polyak factor of the targets (the paper's polyak 0.995).
        noise_start, noise_end: standard deviation of the exploration noise
            at the start and the end of its linear schedule (in the action's [-1, 1] units).
        noise_decay_steps: environment steps over which the noise decays.
        schedule_interval: the noise follows its schedule in steps of this many environment
            steps (1: every step; the released code: once per 250-step epoch).
        test_noise: noise during test episodes (0: deterministic).
        target_noise: standard deviation of the target-policy smoothing noise.
        noise_clip: bound of the smoothing noise.
        policy_delay: critic updates per actor (and target) update.
        batch_size: transitions per update.
        hidden: units of the dense layers.
        layer_norm: LayerNorm in the critics' dense layers (as DroQ's critics).
        critic_pose: asymmetric critics that also see the sensor pose (as SAC's).
        weights_init: the networks' initial weights, as :class:`SACConfig`'s.
        action_input_scale: the scale of actions inside the networks, as :class:`SACConfig`'s.
    """

    gamma: float = 0.95
    learning_rate: float = 5e-5
    adam_eps: float = 1e-4
    tau: float = 0.005
    noise_start: float = 1.0
    noise_end: float = 0.05
    noise_decay_steps: int = 2000
    schedule_interval: int = 1
    test_noise: float = 0.0
    target_noise: float = 0.05
    noise_clip: float = 0.2
    policy_delay: int = 2
    batch_size: int = 32
    hidden: tuple[int, ...] = (512,)
    layer_norm: bool = False
    critic_pose: bool = False
    weights_init: WeightsInit = "he"
    action_input_scale: float = 1.0

    def check_run(self, run: TrainConfig) -> None:
        check_critic_pose(run, self.critic_pose)

    def proprio_settings(self) -> dict[str, str]:
        return {"agent.critic_pose": CRITIC_POSE_USES} if self.critic_pose else {}


@dataclass(frozen=True)
class MRQConfig(AgentConfig):
    """Hyperparameters of MR.Q (:mod:`~tactile_braille.agents.mrq`); defaults: its paper's (Fujimoto
    et al. 2025, Table 4).

    Attributes:
        gamma: discount.
        batch_size: transitions (or sub-trajectories) per update of the encoder and of the value and
            policy.
        target_every: updates between hard copies of the target networks; at each copy the encoder
            first learns for as many updates, then stays fixed until the next.
        value_horizon: steps of the multi-step return of the value's target.
        encoder_horizon: steps the encoder's model is unrolled over.
        exploration_noise: deviation of the Gaussian noise on the policy's output while exploring
            (continuous actions; a discrete policy explores by sampling its softmax).
        target_noise: deviation of the target policy's smoothing noise (continuous actions; the
            discrete target is the target policy's greedy action).
        noise_clip: bound of the smoothing noise.
        dynamics_weight: weight of the encoder's next-embedding loss.
        reward_weight: weight of its reward loss (cross-entropy over two-hot bins).
        done_weight: weight of its episode-end loss.
        priority_alpha: exponent of the prioritised replay's priorities (LAP; 0: uniform).
        min_priority: the priorities' floor (LAP's).
        state_size: length of the state embedding (image, goal, previous action).
        action_size: length of the action embedding.
        state_action_size: length of the state-action embedding the value reads.
        hidden_units: units of the hidden layers of the encoder, the value and the policy.
        encoder_learning_rate: AdamW's step size for the encoder.
        value_learning_rate: AdamW's step size for the value.
        policy_learning_rate: AdamW's step size for the policy.
        weight_decay: AdamW's weight decay, for all three.
        value_grad_clip: the value's gradient norm is clipped to this.
        pre_activation_weight: penalty on the policy's squared pre-activations.
        reward_bins: bins of the reward model's two-hot encoding.
        reward_bound: the bins span symexp of [-reward_bound, reward_bound].
        image_shift: every image of a batch, the sub-trajectories' too, is moved by up to this many
            pixels along each axis, its edge repeated (MR.Q's augmentation; 0: none; images only).
    """

    search_space: ClassVar[Space] = {
        "gamma": Choice((0.9, 0.95, 0.99)),
        "batch_size": Choice((64, 128, 256)),
        "target_every": Choice((100, 250, 500)),
        "value_horizon": Choice((1, 3, 5)),
        "encoder_learning_rate": Range(3e-5, 3e-4, log=True),
        "value_learning_rate": Range(1e-4, 1e-3, log=True),
        "policy_learning_rate": Range(1e-4, 1e-3, log=True),
        "dynamics_weight": Choice((0.1, 1.0)),
        "reward_weight": Choice((0.1, 1.0)),
    }

    gamma: float = 0.99
    batch_size: int = 256
    target_every: int = 250
    value_horizon: int = 3
    encoder_horizon: int = 5
    exploration_noise: float = 0.2
    target_noise: float = 0.2
    noise_clip: float = 0.3
    dynamics_weight: float = 1.0
    reward_weight: float = 0.1
    done_weight: float = 0.1
    priority_alpha: float = 0.4
    min_priority: float = 1.0
    state_size: int = 512
    action_size: int = 256
    state_action_size: int = 512
    hidden_units: int = 512
    encoder_learning_rate: float = 1e-4
    value_learning_rate: float = 3e-4
    policy_learning_rate: float = 3e-4
    weight_decay: float = 1e-4
    value_grad_clip: float = 20.0
    pre_activation_weight: float = 1e-5
    reward_bins: int = 65
    reward_bound: float = 10.0
    image_shift: int = 4

    def __post_init__(self) -> None:
        super().__post_init__()
        _at_least(self, 1, "target_every", "value_horizon", "encoder_horizon", "state_size", "action_size",
                  "state_action_size", "hidden_units")  # fmt: skip
        _at_least(self, 2, "reward_bins")
        _at_least(self, 0, "image_shift")
        problems = [
            f"{name} must be positive, got {getattr(self, name)}"
            for name in ("encoder_learning_rate", "value_learning_rate", "policy_learning_rate",
                         "min_priority", "value_grad_clip", "reward_bound")
            if not getattr(self, name) > 0
        ] + [
            f"{name} must not be negative, got {getattr(self, name)}"
            for name in ("exploration_noise", "dynamics_weight", "reward_weight", "done_weight",
                         "weight_decay", "pre_activation_weight")
            if not getattr(self, name) >= 0
        ]  # fmt: skip
        if not 0 <= self.priority_alpha <= 1:
            problems.append(f"priority_alpha must be in [0, 1], got {self.priority_alpha}")
        if problems:
            raise ValueError("MRQConfig: " + "; ".join(problems))

    def check_run(self, run: TrainConfig) -> None:
        if run.replay.n_step != 1:
            raise ValueError(
                f"mrq builds its own {self.value_horizon}-step returns from sub-trajectories "
                f"(agent.value_horizon): replay.n_step must be 1, got {run.replay.n_step}"
            )
        if run.replay.shift:
            raise ValueError(
                f"mrq shifts its batches' images itself (agent.image_shift): replay.shift must be 0, "
                f"got {run.replay.shift}"
            )
        if self.image_shift and run.touch.enabled:
            raise ValueError(
                "agent.image_shift moves images, and the touch encoder gives features: set it to 0"
            )


@dataclass(frozen=True)
class PlannerConfig(AgentConfig):
    """Hyperparameters of the key-graph planner (ours, :mod:`~tactile_braille.agents.planner`).

    Attributes:
        gamma: discount of its value iteration (shorter paths are worth more).
        learning_rate: Adam's step size for the key reader.
        adam_eps: Adam's epsilon.
        epsilon_start, epsilon_end: random actions at the start and the end of the schedule.
        epsilon_decay_steps: environment steps over which epsilon decays linearly.
        test_epsilon: random actions during test episodes (0: deterministic).
        test_gamma: the discount of test episodes' and typing's plans (None: ``gamma``): exploring,
            the plan may look further ahead than it does typing.
        batch_size: labelled frames per update of the key reader.
        hidden: units of the key reader's dense layers.
        refit_every: the graph, the labels and the values are refitted from the replay after this
            many new transitions.
        graph_prior: pseudo-count spread evenly over the states a move may lead to.
        nothing_memory: a frame that reads *nothing* after a move off a key is placed by that key and
            that move (a state each); False: every frame that reads nothing is the one state *nothing*.
        backoff: pseudo-counts of a state off the keys' moves, spread as the moves of all the states
            off the keys together.
        refit_passes: passes of each refit: the graph is counted with the labels so far, then the
            labels are backtracked on it (1: the graph from the presses' labels and the reader).
        sharpen: the backtracking reads the graph's probabilities raised to this power (renormalised).
        accept: a frame before a press is labelled while the backtracked class has at least this
            probability.
        optimism: a move the graph has not seen from the believed state is worth ``gamma``; False:
            what the graph's prior says.
        repeat_penalty: the value an action loses for each time it was already taken from the
            believed state in the episode (0: none).
        filter: the belief is the last one carried through the graph and the previous action, weighed
            by the reading (a Bayes filter over the episode); False: the key reader's reading alone.
        planning_sweeps: sweeps of value iteration.
        move: on the continuous tasks, the length of each of its four moves, a share of the task's
            largest (1: 10 mm on the arrows, 20 mm on the alphabet).
        sense_depth: on the continuous tasks, the normalised depth of the tap that ends each move
            (depth ``5 + 3 * sense_depth`` mm, commanded); its presses tap at 1 (8 mm).
        entry_memory: its states are each class as reached by each move or by none (the key and how
            the sensor came onto it), in place of ``nothing_memory``'s.
        explore_press: the probability that a random action presses (None: uniform over the five).
        free_repeats: in the generic *nothing* (an episode's start off the keys, and nothing after
            nothing) an action is taken this many times before ``repeat_penalty`` falls on it; None: never.
        backtrack_prior: the backtracked belief is read weighed by how often each state is occupied in
            the replay (Bayes' rule); False: every state alike.
        lost_value: in the value iteration a move into the generic *nothing* (with ``entry_memory``,
            into any of nothing's states) is worth this share of that state's value; None: all of it.
        press_reading: test episodes (and typing) PRESS only where the reader gives the goal key at
            least this probability on the frame under the sensor, else start the belief again from the
            frame and move; None: off.
        first_press: whether a test episode (and typing) may PRESS on its first frame (False: it moves
            first).
        outcome_memory: in test episodes (and typing), a move taken from a believed state leads, for
            the rest of the episode, to the state it was seen to lead to, and the plan is made again on
            that: the world's moves are deterministic where the sensor stands, so a move that did not
            reach a key is not a draw to be made again. False: every move is the graph's draw.
    """

    search_space: ClassVar[Space] = {
        "gamma": Choice((0.6, 0.7, 0.8, 0.85, 0.9, 0.95)),
        "learning_rate": Range(3e-4, 3e-3, log=True),
        "epsilon_decay_steps": Choice((500, 1000, 2000)),
        "refit_every": Choice((25, 50, 100)),
        "sharpen": Choice((2.0, 4.0, 8.0)),
        "accept": Choice((0.8, 0.9, 0.95)),
        "repeat_penalty": Choice((0.0, 0.05, 0.1, 0.2)),
        "outcome_memory": Choice((False, True)),
    }

    gamma: float = 0.9
    learning_rate: float = 1e-3
    adam_eps: float = 1e-8
    epsilon_start: float = 1.0
    epsilon_end: float = 0.1
    epsilon_decay_steps: int = 1000
    test_epsilon: float = 0.0
    test_gamma: float | None = None
    batch_size: int = 64
    hidden: tuple[int, ...] = (128,)
    refit_every: int = 50
    graph_prior: float = 1e-3
    nothing_memory: bool = True
    backoff: float = 5.0
    refit_passes: int = 1
    sharpen: float = 4.0
    accept: float = 0.9
    optimism: bool = True
    repeat_penalty: float = 0.1
    filter: bool = True
    planning_sweeps: int = 60
    move: float = 1.0
    sense_depth: float = 0.0
    entry_memory: bool = False
    explore_press: float | None = None
    free_repeats: int | None = None
    backtrack_prior: bool = False
    lost_value: float | None = None
    press_reading: float | None = None
    first_press: bool = True
    outcome_memory: bool = False

    def __post_init__(self) -> None:
        super().__post_init__()
        problems = []
        if self.press_reading is not None and not 0.0 < self.press_reading <= 1.0:
            problems.append(f"press_reading is a probability in (0, 1], got {self.press_reading}")
        if min(self.refit_every, self.refit_passes, self.planning_sweeps) < 1:
            problems.append("refit_every, refit_passes and planning_sweeps must be at least 1")
        if self.free_repeats is not None and self.free_repeats < 0:
            problems.append(f"free_repeats must not be negative, got {self.free_repeats}")
        if self.repeat_penalty < 0:
            problems.append(f"repeat_penalty must not be negative, got {self.repeat_penalty}")
        if self.graph_prior <= 0 or self.sharpen <= 0:
            problems.append(
                f"graph_prior and sharpen must be positive, got {self.graph_prior}, {self.sharpen}"
            )
        if not 0.0 < self.accept <= 1.0:
            problems.append(f"accept is a probability in (0, 1], got {self.accept}")
        if not 0.0 < self.move <= 1.0:
            problems.append(f"move is a share of the largest move, in (0, 1], got {self.move}")
        if self.lost_value is not None and not 0.0 <= self.lost_value <= 1.0:
            problems.append(f"lost_value is a share in [0, 1], got {self.lost_value}")
        if self.explore_press is not None and not 0.0 <= self.explore_press <= 1.0:
            problems.append(f"explore_press is a probability in [0, 1], got {self.explore_press}")
        if not -1.0 <= self.sense_depth < 1.0:
            problems.append(
                f"sense_depth is a normalised depth in [-1, 1) (1 presses), got {self.sense_depth}"
            )
        if problems:
            raise ValueError("PlannerConfig: " + "; ".join(problems))

    def check_run(self, run: TrainConfig) -> None:
        task = run.braille_task
        if task is not None and task.continuous and run.final_press:
            raise ValueError(
                f"the planner learns from its own five actions: on {run.task} set final_press=False (it "
                f"presses with the move asked, none of them)"
            )
        if run.touch.enabled or run.taps > 1 or run.replay.shift:
            raise ValueError(
                "the planner reads each single tactile image itself: turn touch.enabled off, and keep "
                "taps=1 and replay.shift=0"
            )


@dataclass(frozen=True)
class ReplayConfig:
    """The replay buffer.

    Attributes:
        capacity: transitions kept (the paper's 100,000).
        her: hindsight relabelling.
        relabel: ``"paper"`` (copies of wrong-press episodes, the paper's) or ``"all"`` (every
            transition for every goal, relabelled when sampled; :mod:`~tactile_braille.agents.replay`).
        n_step: steps of its episode each sampled transition's return spans, discounted by the
            agent's ``gamma`` (1: one-step targets, the paper's; ours above 1).
        shift: each sampled image (and, drawn apart, its next image) moved by up to this many
            pixels along each axis, its edges repeated: DrQ's augmentation (Kostrikov et al.
            2021; 0: none, the paper's). The run's own frames, so on the ``tactile`` track.
    """

    capacity: int = 100_000
    her: bool = True
    relabel: RelabelRule = "paper"
    n_step: int = 1
    shift: int = 0

    def __post_init__(self) -> None:
        check_types(self)
        _at_least(self, 1, "capacity", "n_step")
        _at_least(self, 0, "shift")


@dataclass(frozen=True)
class TouchConfig:
    """The touch encoder (not the paper's; :mod:`~tactile_braille.supervised.touch`).

    Attributes:
        enabled: fit a touch encoder on the run's own taps after ``start_steps`` and learn on its
            features.
        labels: what the encoder learns from. ``"robot"``: every frame labelled with what a calibrated
            robot knows, the sensor pose and the keys the layout places there (the ``proprio``
            track). ``"observation"``: the observation dictionary alone (the ``tactile`` track):
            touch odometry, coordinates in which each step moves by its previous action, and the
            key each achieved goal names (:func:`~tactile_braille.supervised.touch.fit_touch_odometry`).
        epochs: passes of the encoder's first fit over those taps.
        inputs: what the agent learns on: the encoder's ``"features"`` or its ``"readout"`` (pose and
            key probabilities, whose meaning survives a refit).
        goal_positions: the agent also sees where its goal key lies, in the coordinates of the pose
            the encoder learns: on the calibrated layout (``labels="robot"``), or where the run
            itself pressed that key (``labels="observation"``: the layout learnt from touch).
        pose_inputs: the agent (actor and critics) also sees the arm's pose at each tap, in the same
            coordinates: the environment is made with ``proprio=True`` and its observations carry
            ``sensor_pose``.
        refits: refits on all labelled frames so far, every ``refit_every`` steps after the first fit
            (each as many gradient steps as the first fit).
        refit_every: environment steps between refits (None: ``start_steps``).
    """

    enabled: bool = False
    labels: TouchLabels = "robot"
    epochs: int = 40
    inputs: TouchInputs = "features"
    goal_positions: bool = False
    pose_inputs: bool = False
    refits: int = 0
    refit_every: int | None = None

    def __post_init__(self) -> None:
        check_types(self)
        _at_least(self, 1, "epochs", "refit_every")
        _at_least(self, 0, "refits")


@dataclass(frozen=True)
class EvaluationConfig:
    """What a run measures as it trains.

    Attributes:
        test_episodes: deterministic test episodes after each epoch.
        snapshots: policy snapshots kept (``snapshots/epoch_NNNN.pt``), spread evenly from the first
            epoch to the last (for the trajectory figure).
    """

    test_episodes: int = 20
    snapshots: int = 3

    def __post_init__(self) -> None:
        check_types(self)
        _at_least(self, 1, "test_episodes")
        _at_least(self, 0, "snapshots")


@dataclass(frozen=True)
class TrainConfig:
    """A training run. Defaults are the paper's; :mod:`~tactile_braille.agents.presets` sets the rest.

    Attributes:
        task: environment id (``tactile_braille/DiscreteArrows-v0``...).
        algo: the agent, a registered name (:func:`~tactile_braille.agents.registry.agent_names`:
            ``"dqn"``, ``"sac_discrete"``, ``"sac"``, ``"td3"``, ``"planner"`` and any an extension
            registers).
        seed: seeds networks, exploration and environments.
        epochs: epochs to run.
        steps_per_epoch: environment steps per epoch (250).
        start_steps: uniformly random actions before the policy acts, and before updates start (200).
        updates_per_step: gradient updates per environment step (None: 2, TD3 1).
        update_every: updates happen in bursts every this many steps
            (``update_every * updates_per_step`` at a time; the released TD3 used 100).
        update_after: updates start after this many environment steps, once the replay holds a
            batch (None: after ``start_steps``, the paper's; the released DQN and SACs updated from
            their first step, as ``1``: from the step the replay first holds a batch).
        max_episode_steps: episode cut (None: the registry's 25).
        taps: tactile images in each observation: 1, the paper's (the tap just made); more stacks the
            last ``taps`` and the ``taps - 1`` actions between them
            (:class:`~tactile_braille.envs.memory.TapMemory`): a memory of the run's own observations,
            so on the ``tactile`` track.
        keep_pose_fraction: the share of training episodes that start where the last one left the
            sensor, as the paper's typing evaluation starts each key of a sequence (drawn per
            episode; 0: every episode from a random start pose, the paper's training). Where
            episodes start is the training's schedule, not an input, so on the ``tactile`` track.
        final_press: training episodes that reach their step limit end with a press: the last
            step's action presses (discrete: PRESS; continuous: the action with its deepest tap),
            so that nearly every episode has an achieved goal to relabel its steps with, where a
            time-out has none (ours; False: the paper's). The step count is the agent's own, not an
            input, so on the ``tactile`` track.
        backend: environment backend (``dataset``, ``render``, or ``rig``: a robot, ``train(rig=...)``).
        frame_noise: ``(mm, degrees)``: the render backend's work frame off by an error drawn anew each
            episode, offsets within +-mm along x and y, a turn within +-degrees (domain randomisation
            against calibration errors; None: none).
        edges: what a continuous task's workspace edge does to a move that would cross it: ``stop``
            (the sensor stops there, as the real rig's safety limits stop the arm) or ``overrun`` (the
            released simulator's rule, in which the paper's Table III was measured: the commanded
            position runs on past the edge and only the tap is made inside). The discrete tasks' grid
            edges always stop a move.
        tap_depth: which stored depth a continuous tap reads on the dataset backend: ``commanded`` (the
            sample at the commanded depth) or ``released`` (the released simulator's lookup, which
            compared the commanded 2-8 mm with its data's 0-6 mm labels: every tap reads the sample
            2 mm deeper, the deepest from 6 mm on, so shallow taps feel and press like deeper ones).
        key_grid: the discrete tasks' key grid: ``rig`` (the original robot's: the alphabet's third row
            starts under A) or ``released`` (the released simulator's: that row one column right, Z
            under S; the arrows' grid is the same in both).
        dataset: dataset for the dataset backend: a path, or a default dataset's name
            (``grid-alphabet-6mm``...; default: the task's, cached).
        device: torch device (``cpu``, ``cuda``, ``cuda:1``...).
        precision: ``fp32`` or ``bf16`` (autocast in the updates; faster only where the device
            computes bfloat16 natively, several times slower where it is emulated).
        threads: torch CPU threads (default 1, so that runs side by side do not oversubscribe the
            cores; a run alone on an idle machine may take one per core).
        checkpoint_every: epochs between checkpoints.
        init_from: a warm start: the run folder whose last checkpoint's agent (networks, optimisers,
            temperature, touch encoder) this run starts from, not its replay, counters or generators
            (``init.json`` records what was taken). Its settings must be this run's but for
            the world, the seed, the length, the replay and the machine (``run.INIT_FREE``).
        track: the benchmark track the run competes in (docs/benchmark.md): ``tactile`` (the paper's
            rules: only the observation dictionary and the reward) or ``proprio`` (also the arm's pose
            and the calibrated key layout). A setting outside the track is refused.
        preset: name of the preset the settings came from (a record only).
        agent: the algorithm's hyperparameters (default: the paper's for ``algo``).
        replay: the replay buffer.
        touch: the touch encoder.
        evaluation: test episodes and policy snapshots.
    """

    task: str = "tactile_braille/DiscreteArrows-v0"
    algo: str = "dqn"
    seed: int = 0
    epochs: int = 25
    steps_per_epoch: int = 250
    start_steps: int = 200
    updates_per_step: int | None = None
    update_every: int = 1
    update_after: int | None = None
    max_episode_steps: int | None = None
    taps: int = 1
    keep_pose_fraction: float = 0.0
    final_press: bool = False
    backend: Backend = "dataset"
    frame_noise: tuple[float, ...] | None = None
    edges: Edges = "stop"
    tap_depth: TapDepth = "commanded"
    key_grid: KeyGrid = "rig"
    dataset: str | None = None
    device: str = "cpu"
    precision: Precision = "fp32"
    threads: int = 1
    checkpoint_every: int = 1
    init_from: str | None = None
    track: Track = "tactile"
    preset: str | None = None
    agent: AgentConfig | None = None
    replay: ReplayConfig = field(default_factory=ReplayConfig)
    touch: TouchConfig = field(default_factory=TouchConfig)
    evaluation: EvaluationConfig = field(default_factory=EvaluationConfig)

    def __post_init__(self) -> None:
        spec = _agent_spec(self.algo)  # raises for an unknown algo, naming the registered ones
        agent_config = spec.config
        for name, group in {"agent": agent_config, **GROUPS}.items():  # a group may be given as a dict
            if isinstance(getattr(self, name), dict):
                object.__setattr__(self, name, _from_dict(group, getattr(self, name), name))
        if self.agent is None:
            object.__setattr__(self, "agent", agent_config())
        elif not isinstance(self.agent, agent_config):
            raise ValueError(f"{self.algo} takes a {agent_config.__name__}, got {type(self.agent).__name__}")
        if self.updates_per_step is None:
            object.__setattr__(self, "updates_per_step", spec.updates_per_step)
        if isinstance(self.frame_noise, list):  # as config.json stores it
            object.__setattr__(self, "frame_noise", tuple(self.frame_noise))
        check_types(self)
        self._check_frame_noise()
        _at_least(self, 1, "epochs", "steps_per_epoch", "update_every", "checkpoint_every", "threads",
                  "max_episode_steps", "taps")  # fmt: skip
        _at_least(self, 0, "seed", "start_steps", "updates_per_step", "update_after")
        if not 0.0 <= self.keep_pose_fraction <= 1.0:
            raise ValueError(
                f"keep_pose_fraction is a share of episodes, in [0, 1], got {self.keep_pose_fraction}"
            )
        self._check_task()
        self._check_device()
        self._check_touch()
        self.agent.check_run(self)
        self._check_track()

    def _check_track(self) -> None:
        outside = proprio_settings(self) if self.track == "tactile" else {}
        if outside:
            uses = "; ".join(f"{name} {why}" for name, why in outside.items())
            raise ValueError(
                f"the tactile track allows only the observation dictionary and the reward, but {uses}: "
                "set track='proprio' (--track proprio) or turn them off"
            )

    def _check_frame_noise(self) -> None:
        check_frame_noise(self.frame_noise, self.backend)  # the environments' rule

    def _check_task(self) -> None:
        from tactile_braille.envs.registry import task_of  # the environments' registry, not torch

        task = task_of(self.task)  # raises for an unknown id
        spec = _agent_spec(self.algo)
        if task is not None and not spec.acts_in(task.continuous):
            kinds = " or ".join(kind for kind in ("discrete", "continuous") if kind in spec.actions)
            raise ValueError(f"{self.algo} needs a {kinds} task, got {self.task}")
        if self.keep_pose_fraction > 0 and task is None:
            raise ValueError(
                f"keep_pose_fraction starts episodes where the braille tasks' sensor was (their reset "
                f"option keep_pose), got {self.task}"
            )
        check_world(  # the environments' rules for edges, tap_depth and key_grid, as they will check them
            None if task is None else task.continuous, self.backend,
            edges=self.edges, tap_depth=self.tap_depth, key_grid=self.key_grid, task=self.task,
        )  # fmt: skip
        if self.final_press and task is None:
            raise ValueError(f"final_press ends episodes with the braille tasks' press, got {self.task}")
        if self.touch.labels == "observation" and task is None:
            raise ValueError(
                f"touch.labels='observation' reads the braille tasks' documented actions, got {self.task}"
            )
        if self.touch.goal_positions and task is None:
            raise ValueError(
                f"touch.goal_positions needs a braille task (a keyboard layout), got {self.task}"
            )

    @property
    def braille_task(self):
        """The run's :class:`~tactile_braille.envs.tasks.Task` (key set and action kind), or None for
        another registered goal-conditioned environment."""
        from tactile_braille.envs.registry import task_of  # the environments' registry, not torch

        return task_of(self.task)

    def _check_device(self) -> None:
        kind, _, index = self.device.partition(":")
        if kind not in ("cpu", "cuda", "mps") or (index and not index.isdigit()):
            raise ValueError(f"device must be cpu, cuda, cuda:N or mps, got {self.device!r}")

    def _check_touch(self) -> None:
        touch = self.touch
        needs_encoder = {
            "touch.inputs='readout'": touch.inputs != "features",
            "touch.goal_positions": touch.goal_positions,
            "touch.pose_inputs": touch.pose_inputs,
        }
        for name, wanted in needs_encoder.items():
            if wanted:
                require_encoder(self, name)
        if touch.enabled and self.taps > 1:
            raise ValueError(
                f"the touch encoder reads one tap at a time: taps={self.taps} stacks several, set taps=1"
            )
        if touch.enabled and self.replay.shift:
            raise ValueError(f"replay.shift={self.replay.shift} moves images, but with the touch "
                             "encoder the agent learns on its features: set touch.enabled=False or "
                             "shift=0")  # fmt: skip
        if touch.labels != "robot" and not touch.enabled:
            raise ValueError(f"touch.labels={touch.labels!r} is the touch encoder's: set touch.enabled too")
        if touch.goal_positions and touch.labels == "observation" and touch.inputs != "readout":
            raise ValueError(
                "touch.goal_positions with touch.labels='observation' reads the goal's offset off the "
                "encoder's readout: set touch.inputs='readout'"
            )
        if touch.pose_inputs:
            require_encoder(self, "touch.pose_inputs", robot_labels=True)
        if touch.enabled and self.start_steps < 10:
            raise ValueError(
                f"a touch encoder learns from the start steps: need at least 10, got {self.start_steps}"
            )

    def with_changes(self, **changes: Any) -> TrainConfig:
        """A copy with settings changed (groups as dicts of their settings): :func:`replace_settings`."""
        return replace_settings(self, changes)

    def check_rig(self, rig) -> None:
        """Refuse a robot handed to a run that does not train on it (its backend is not ``rig``)."""
        if rig is not None and self.backend != "rig":
            raise ValueError(f"a rig was given, but the run's backend is {self.backend!r}: set backend='rig'")

    def to_json(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, data: dict) -> TrainConfig:
        """A config from :meth:`to_json`'s dict, or from the flat config.json of runs written before
        the settings were grouped (their settings move to their groups)."""
        data = _ungroup_legacy(dict(data))
        if "algo" not in data:
            raise ValueError("the settings name no algorithm ('algo')")
        _refuse_unknown(cls, data)
        if isinstance(data.get("agent"), dict):  # written before these settings: what it was trained with
            data["agent"] = _without_retired(
                data["algo"], {**_LEGACY_AGENT.get(data["algo"], {}), **data["agent"]}
            )
        if "track" not in data:  # written before tracks: the track its settings need
            config = cls(**{**data, "track": "proprio"})
            return replace_settings(config, {"track": "proprio" if proprio_settings(config) else "tactile"})
        return cls(**data)  # the groups, given as dicts, become their dataclasses


def proprio_settings(config: TrainConfig) -> dict[str, str]:
    """The settings of ``config`` that use what only a calibrated robot knows (the ``proprio`` track),
    each with what it uses."""
    robot = config.touch.labels == "robot"
    uses = (
        ("touch.enabled", config.touch.enabled and robot,
         "labels every frame with the arm's pose and the keys the calibrated layout places there"),
        ("touch.goal_positions", config.touch.goal_positions and robot,
         "places the goal on the calibrated key layout"),
        ("touch.pose_inputs", config.touch.pose_inputs, "shows the agent the arm's pose"),
    )  # fmt: skip
    return {**{name: why for name, used, why in uses if used}, **config.agent.proprio_settings()}


def require_encoder(run: TrainConfig, name: str, robot_labels: bool = False) -> None:
    """Refuse the setting ``name``, which learns from a touch encoder's labelled frames, in a run without
    one; with ``robot_labels``, also in one whose frames are not labelled with the arm's pose."""
    if not run.touch.enabled:
        raise ValueError(f"{name} learns from a touch encoder's labelled frames: set touch.enabled too")
    if robot_labels and run.touch.labels != "robot":
        raise ValueError(
            f"{name} needs the arm's pose of every frame, which touch.labels='observation' does not "
            "record: set touch.labels='robot'"
        )


def check_goal_inputs(run: TrainConfig, all_goals: bool, goal_heads: bool = False) -> None:
    """Refuse a run that an agent reading the goal as a one-hot cannot learn with: an all-goals update
    (``all_goals``) computes one-step targets, and it and ``goal_heads`` take no goal positions."""
    if all_goals and run.replay.n_step > 1:
        raise ValueError(
            f"agent.all_goals computes one-step targets for every goal: set replay.n_step=1, "
            f"not {run.replay.n_step}"
        )
    for name, wanted in (("all_goals", all_goals), ("goal_heads", goal_heads)):
        if wanted and run.touch.goal_positions:
            raise ValueError(f"agent.{name} reads the goal as a one-hot alone: turn touch.goal_positions off")


CRITIC_POSE_USES = "shows the critics the arm's pose"
"""What ``agent.critic_pose`` (SAC's and TD3's asymmetric critics) uses that only a calibrated robot knows."""


def check_critic_pose(run: TrainConfig, critic_pose: bool) -> None:
    """Refuse asymmetric critics (``critic_pose``) in a run whose frames are not labelled with the pose."""
    if critic_pose:
        require_encoder(run, "agent.critic_pose", robot_labels=True)


def _agent_spec(algo: str):
    """The registered agent ``algo`` (:mod:`~tactile_braille.agents.registry`, which imports this module)."""
    from tactile_braille.agents.registry import agent_spec

    return agent_spec(algo)


GROUPS: dict[str, type] = {"replay": ReplayConfig, "touch": TouchConfig, "evaluation": EvaluationConfig}
"""The setting groups of :class:`TrainConfig` besides ``agent`` (whose class depends on ``algo``)."""

_LEGACY_NAMES = {
    "replay_capacity": ("replay", "capacity"),
    "her": ("replay", "her"),
    "relabel": ("replay", "relabel"),
    "touch_encoder": ("touch", "enabled"),
    "touch_epochs": ("touch", "epochs"),
    "touch_inputs": ("touch", "inputs"),
    "goal_positions": ("touch", "goal_positions"),
    "touch_refits": ("touch", "refits"),
    "touch_refit_every": ("touch", "refit_every"),
    "test_episodes": ("evaluation", "test_episodes"),
    "snapshots": ("evaluation", "snapshots"),
}
"""Flat settings of config.json files written before the groups, and where they live now."""


_LEGACY_AGENT = {
    algo: {"adam_eps": 1e-8, **({"loss": "huber"} if algo == "dqn" else {})}
    for algo in ("dqn", "sac_discrete", "sac", "td3", "planner")
}
"""What runs of the project's own agents written before a setting existed were trained with, where that
differs from its default."""


_RETIRED_AGENT = {
    "dqn": {"inverse_dynamics": 0.0},
    "sac_discrete": {"shared_encoder": False},
    "sac": {"shared_encoder": False},
    "td3": {"shared_encoder": False},
    "planner": {
        "backtrack_readings": 0.0,
        "locate": False,
        "locate_accept": 0.9,
        "locate_margin": 0.15,
        "locate_span": 3,
        "locate_learning_rate": 3e-3,
        "locate_ready": 0.95,
        "reckon": 0,
        "nothing_carry": False,
        "move_press": False,
        "press_accept": None,
        "backtrack_evidence": 0.0,
    },
    "mrq": {"gumbel_tau": 10.0},
}
"""Each algorithm's removed settings, with the one value the code still runs: a record that gives a
removed setting that value reads as one without it; any other value is refused."""


def _without_retired(algo: str, agent: dict) -> dict:
    """``agent`` without its retired settings; one given another value than the code still runs is
    refused (its run cannot be read as what it did)."""
    retired = _RETIRED_AGENT.get(algo, {})
    for name, kept in retired.items():
        if name in agent and agent[name] != kept:
            raise ValueError(
                f"agent.{name}={agent[name]!r}: this setting was removed; only runs with {kept!r} can be read"
            )
    return {name: value for name, value in agent.items() if name not in retired}


def _ungroup_legacy(data: dict) -> dict:
    for old, (group, name) in _LEGACY_NAMES.items():
        if old in data:
            data.setdefault(group, {})
            data[group] = {**data[group], name: data.pop(old)}
    return data


def _from_dict(cls: type, values: Any, where: str):
    """A group's dataclass from its JSON dict (lists become tuples), naming unknown settings."""
    if isinstance(values, cls):
        return values
    if not isinstance(values, dict):
        raise ValueError(f"{where} must be a mapping of settings, got {values!r}")
    _refuse_unknown(cls, values, where)
    return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})


def _refuse_unknown(cls: type, names, where: str | None = None) -> None:
    """Refuse settings ``cls`` does not have, naming them (and the group they were given for)."""
    unknown = set(names) - {f.name for f in dataclasses.fields(cls)}
    if unknown:
        raise ValueError(
            f"{cls.__name__} has no settings {sorted(unknown)}" + (f" ({where}.*)" if where else "")
        )


def replace_settings(config: TrainConfig, changes: dict[str, Any]) -> TrainConfig:
    """``config`` with ``changes``: TrainConfig fields, and a group as a dict of its fields to change
    (``{"agent": {"hidden": (256,)}, "touch": {"enabled": True}, "epochs": 3}``). Changing ``algo``
    starts the agent from that algorithm's defaults."""
    changes = dict(changes)
    _refuse_unknown(TrainConfig, changes)
    algo = changes.get("algo", config.algo)
    groups = {"agent": _agent_spec(algo).config, **GROUPS}
    for name, group in groups.items():
        if isinstance(changes.get(name), dict):
            base = getattr(config, name) if (name != "agent" or algo == config.algo) else group()
            _refuse_unknown(group, changes[name], name)
            changes[name] = dataclasses.replace(base, **changes[name])
    if algo != config.algo and "agent" not in changes:
        changes["agent"] = None
    return dataclasses.replace(config, **changes)


def flatten(config) -> dict[str, Any]:
    """Every setting of a config as ``{"dotted.name": value}`` (tuples as lists, as JSON stores them)."""
    flat: dict[str, Any] = {}
    for name, value in dataclasses.asdict(config).items():
        if isinstance(value, dict):
            flat.update({f"{name}.{k}": list(v) if isinstance(v, tuple) else v for k, v in value.items()})
        else:
            flat[name] = list(value) if isinstance(value, tuple) else value
    return flat


def differences(before, after, ignore: tuple[str, ...] = ()) -> list[str]:
    """``name: before -> after`` for each dotted setting in which two configs differ."""
    old, new = flatten(before), flatten(after)
    return [
        f"{name}: {old.get(name)!r} -> {new.get(name)!r}"
        for name in sorted(set(old) | set(new))
        if name not in ignore and old.get(name) != new.get(name)
    ]


# ------------------------------------------------------------------ field checks
def _at_least(config, minimum: int, *names: str) -> None:
    for name in names:
        value = getattr(config, name)
        if value is not None and value < minimum:
            raise ValueError(f"{type(config).__name__}.{name} must be at least {minimum}, got {value}")


def check_types(config) -> None:
    """Refuse a field whose value does not fit its annotation (naming the field and what it takes)."""
    hints = typing.get_type_hints(type(config))
    for spec in dataclasses.fields(config):
        value, hint = getattr(config, spec.name), hints[spec.name]
        if not _fits(value, hint):
            raise ValueError(f"{type(config).__name__}.{spec.name} must be {describe(hint)}, got {value!r}")


def _fits(value: Any, hint: Any) -> bool:
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is Literal:
        return isinstance(value, str) and value in args
    if origin in (Union, types.UnionType):
        return any(_fits(value, arg) for arg in args)
    if origin is tuple:
        return isinstance(value, tuple) and all(_fits(v, args[0]) for v in value)
    if hint is type(None):
        return value is None
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if hint is float:
        return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    return isinstance(value, hint)


def describe(hint: Any) -> str:
    """What a field of this annotation takes, in words."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin in (Union, types.UnionType):
        return " or ".join(describe(a) for a in args)
    if origin is tuple:
        return f"a tuple of {describe(args[0])}s"
    if hint is type(None):
        return "None"
    return {bool: "true or false", int: "an integer", float: "a finite number", str: "a string"}.get(
        hint, getattr(hint, "__name__", str(hint))
    )
