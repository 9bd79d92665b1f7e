"""Named hyperparameter presets: the paper's Table II, the released code's settings, and ours.

Each preset is a :class:`~tactile_braille.agents.config.TrainConfig` built by
``dataclasses.replace`` from the defaults (which are the paper's, written
once in :mod:`~tactile_braille.agents.config`):

* ``paper`` follows the paper's Table II, taking the released code's values
  where the table is silent (Adam's epsilon 1e-4, DQN's squared-error loss,
  TD3's noise in mm): the defaults, the paper's epochs per task and its 25-step
  episodes, and on the continuous tasks the released simulator's world: its
  workspace edge, past which the commanded position runs on, and its lookup of
  the stored depths, 2 mm deeper than commanded (:func:`paper_changes`).
* ``released`` reproduces the configurations saved with the original runs
  (``reference/braille_rl_2020/.../config.json``): ``paper`` with
  :data:`RELEASED_CHANGES`. docs/agents.md tables the differences.
* ``fast`` is ours (docs/agents.md, "Beyond the paper"): a touch encoder
  fitted and refitted on the run's own labelled taps, relabelling of every
  transition for every goal, and more, cheaper updates on the encoder's
  readout, with the arm's pose and the goal placed on the calibrated layout
  as inputs; on the continuous alphabet also asymmetric critics that see the
  sensor pose (:func:`fast_changes`). Both ``fast`` presets keep the real
  rig's world: the workspace edge stops the arm, and taps read the depth
  commanded.
* ``fast-tactile`` is ``fast`` on the ``tactile`` track: its touch encoder
  learns from the observation dictionary alone (touch odometry, pressed keys,
  press outcomes and each key's offset learnt in hindsight from the run's
  presses), and neither the agent nor its critics see the arm's pose
  (:func:`fast_tactile_changes`).

Each preset declares its track (:data:`PRESET_TRACKS`, docs/benchmark.md):
``paper``, ``released`` and ``fast-tactile`` are ``tactile``, ``fast`` (whose
encoder learns from the arm's pose and the key layout) is ``proprio``.

>>> config = preset_config("paper", "tactile_braille/DiscreteArrows-v0", "dqn")
>>> config.epochs, config.updates_per_step, config.agent.gamma
(25, 2, 0.95)
>>> preset_config("fast", "tactile_braille/DiscreteArrows-v0", "dqn").track
'proprio'
>>> preset_differences("released", "tactile_braille/DiscreteArrows-v0", "sac_discrete")[:2]
['agent.dueling: True -> False', 'agent.initial_alpha: 1.0 -> 1.174618943088019']
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

from tactile_braille.agents.config import TrainConfig, differences, replace_settings
from tactile_braille.agents.registry import PAPER_AGENTS, agent_spec
from tactile_braille.envs.registry import task_of
from tactile_braille.envs.tasks import Task

PRESETS = ("paper", "released", "fast", "fast-tactile")
PRESET_TRACKS = {"paper": "tactile", "released": "tactile", "fast": "proprio", "fast-tactile": "tactile"}
"""The track each preset competes in (docs/benchmark.md): the paper's agents and ``fast-tactile`` learn
from touch alone; ``fast`` also from the arm's pose and the calibrated key layout."""


@dataclass(frozen=True)
class TaskPresets:
    """What the presets set on one registered braille task: a row of :data:`TASK_PRESETS`.

    Attributes:
        paper_epochs: epochs of the original runs (sim): the ``paper`` and ``released`` presets'.
        fast_epochs: the ``fast`` preset's: a third of the paper's convergence epochs or less, and the
            90-epoch budget for the continuous alphabet.
        fast_tactile_epochs: the ``fast-tactile`` preset's: ``fast``'s, and on the continuous alphabet a
            third of the paper's 872 convergence epochs.
        fast: what ``fast`` sets on this task beyond what it sets on every task (:func:`fast_changes`;
            a group as a dict of its settings).
        planner_epochs: the planner's epochs (``fast-tactile``) where they are not
            ``fast_tactile_epochs``: on the continuous alphabet twice the first epoch at 0.95 of its
            tuning seed (30), where ``fast-tactile``'s 290 are a third of the paper's 872.
        planner_agent: the planner's settings on this task beyond its action kind's
            (:func:`planner_changes` says why).
    """

    paper_epochs: int
    fast_epochs: int
    fast_tactile_epochs: int
    fast: dict[str, Any]
    planner_epochs: int | None = None
    planner_agent: dict[str, Any] = field(default_factory=dict)


_ARROWS_FAST = {"start_steps": 200, "touch": {"refit_every": 200, "refits": 4}}
TASK_PRESETS: dict[str, TaskPresets] = {
    "tactile_braille/DiscreteArrows-v0": TaskPresets(
        paper_epochs=25, fast_epochs=8, fast_tactile_epochs=8, fast=_ARROWS_FAST,
        planner_agent={"test_gamma": 0.7, "outcome_memory": True},
    ),
    "tactile_braille/DiscreteAlphabet-v0": TaskPresets(
        paper_epochs=100, fast_epochs=25, fast_tactile_epochs=25,
        fast={"start_steps": 500, "touch": {"refit_every": 250, "refits": 16}},
    ),
    "tactile_braille/ContinuousArrows-v0": TaskPresets(
        paper_epochs=100, fast_epochs=30, fast_tactile_epochs=30, fast=_ARROWS_FAST,
        planner_agent={"press_reading": 0.8, "first_press": False},
    ),
    "tactile_braille/ContinuousAlphabet-v0": TaskPresets(
        paper_epochs=2000, fast_epochs=90, fast_tactile_epochs=290, planner_epochs=60,
        fast={
            "start_steps": 500,
            # Reading a letter at any offset takes many more taps than at key centres: refit all along.
            "touch": {"refit_every": 1000, "refits": 20},
            # The critics also see the sensor pose the arm reports: judging a move is easy from where
            # the sensor is, and the actor, which acts on touch alone, learns from that judgement.
            "agent": {"critic_pose": True},
        },
        planner_agent={"move": 0.9, "lost_value": 0.0, "outcome_memory": True, "test_gamma": 0.97},
    ),
}  # fmt: skip
"""The presets' numbers for each registered braille task (:data:`~tactile_braille._tasks.REGISTERED_TASKS`),
by id."""

RELEASED_CHANGES: dict[str, dict[str, Any]] = {
    # The target moves 99.5 % of the way to the online network once per epoch (its `polyak: 0.005` is
    # the share the target keeps); epsilon steps down once per epoch; tests explore with 0.05. Its
    # dueling heads each read half of the dense units, and every layer starts from TensorFlow's
    # variance scaling (records run before the project took it depart from it, and say so).
    "dqn": {
        "agent": {
            "test_epsilon": 0.05,
            "target_update": "epoch",
            "tau": 0.995,
            "schedule_interval": 250,
            "dueling_split": True,
            "weights_init": "released",
        },
        "update_after": 1,
    },
    # log alpha starts at the target entropy, 0.1 ln 5: alpha = 5 ** 0.1. Its critics have one head of
    # Q-values (no dueling), and every layer starts from TensorFlow's variance scaling.
    "sac_discrete": {
        "agent": {"initial_alpha": 5**0.1, "dueling": False, "weights_init": "released"},
        "update_after": 1,
    },
    # Both continuous agents also start from the release's initial weights (Glorot
    # heads), and SAC's log deviation runs through a tanh onto [-20, 2]; their networks read actions in
    # mm (:func:`released_changes` sets the scale, the task's largest move).
    "sac": {
        "agent": {"hidden": (1024, 512), "weights_init": "released", "log_std": "tanh"},
        "max_episode_steps": 35,
        "update_after": 1,
    },
    "td3": {
        "agent": {"learning_rate": 7.5e-5, "schedule_interval": 250, "weights_init": "released"},
        "update_every": 100,
    },
}
"""What the released code changes from the paper's Table II, per algorithm (docs/agents.md tables each
difference, and those not reproduced)."""

TD3_NOISE_MM = {"noise_start": 1.0, "noise_end": 0.05, "target_noise": 0.05, "noise_clip": 0.2}
"""TD3's exploration and smoothing noise (Table II): the released code adds it to actions in mm; ours act
in [-1, 1] units of the task's largest move, so :func:`paper_changes` divides by that move."""


def paper_changes(task: str, algo: str) -> dict[str, Any]:
    """What the paper's presets set beyond the defaults, for a task and an algorithm: its epochs and
    25-step episodes, on the continuous tasks the released simulator's workspace edge and depth lookup
    (``edges="overrun"``, ``tap_depth="released"``), and TD3's noise in the units of
    the released code (mm)."""
    spec, presets = task_presets(task)
    changes: dict[str, Any] = {"epochs": presets.paper_epochs, "max_episode_steps": 25}
    if spec.continuous:  # the released simulator, in which Table III was measured:
        changes["edges"] = "overrun"  # its workspace edge, past which the commanded position runs on
        changes["tap_depth"] = "released"  # and its lookup of the stored depths, 2 mm deeper
    if algo == "td3":
        scale = spec.max_move_mm
        changes["agent"] = {name: mm / scale for name, mm in TD3_NOISE_MM.items()}
    return changes


def released_changes(task: str, algo: str) -> dict[str, Any]:
    """:data:`RELEASED_CHANGES` for ``algo``, and for the continuous agents the scale of actions inside
    their networks: the released code's read them in mm, ours in units of the task's largest move."""
    if algo not in RELEASED_CHANGES:
        raise ValueError(
            f"the released code has no {algo}: --preset released is for {tuple(RELEASED_CHANGES)}"
        )
    changes = RELEASED_CHANGES[algo]
    if algo in ("sac", "td3"):
        agent = {**changes["agent"], "action_input_scale": task_of(task).max_move_mm}
        changes = {**changes, "agent": agent}
    return changes


def task_presets(task: str) -> tuple[Task, TaskPresets]:
    """The braille task of a registered id (read from its registration) and its row of
    :data:`TASK_PRESETS`.

    Raises:
        ValueError: ``task`` is not registered, or is not one of the braille tasks the presets are for.
    """
    spec = task_of(task)  # raises for an unknown id
    if spec is None or task not in TASK_PRESETS:
        raise ValueError(
            f"no preset for task {task!r}: presets are for the braille tasks {tuple(TASK_PRESETS)}"
        )
    return spec, TASK_PRESETS[task]


def _merged(changes: dict[str, Any], more: dict[str, Any]) -> dict[str, Any]:
    """``changes`` with ``more`` on top, a group's settings merged into the group's (a new dict)."""
    merged = dict(changes)
    for name, value in more.items():
        both = isinstance(value, dict) and isinstance(merged.get(name), dict)
        merged[name] = {**merged[name], **value} if both else copy.deepcopy(value)
    return merged


def fast_changes(task: str, algo: str) -> dict[str, Any]:
    """What ``fast`` changes on top of the paper's settings, for a task (its row's ``fast``, on top of
    what it sets on every task) and an algorithm."""
    _, presets = task_presets(task)
    changes: dict[str, Any] = {
        "epochs": presets.fast_epochs,
        "updates_per_step": 2 if algo == "td3" else 4,
        "replay": {"relabel": "all"},
        # The agent acts on what the encoder reads (pose, key probabilities), the arm's pose and the
        # goal key's place on the calibrated layout, all in the encoder's pose coordinates: "where to go"
        # is then one function for every key, and the pose the arm reports makes it exact.
        "touch": {"enabled": True, "inputs": "readout", "goal_positions": True, "pose_inputs": True},
        "agent": {"hidden": (256, 256), "batch_size": 128, "learning_rate": 1e-3, "adam_eps": 1e-8},
    }
    changes = _merged(changes, presets.fast)  # its start steps, the encoder's refits, ...
    if algo == "dqn":
        changes["agent"].update(epsilon_decay_steps=1000, loss="huber")
    if algo in ("sac", "sac_discrete"):
        changes["agent"]["initial_alpha"] = 0.05  # press early: a high temperature pays for staying alive
    return changes


def fast_tactile_changes(task: str, algo: str) -> dict[str, Any]:
    """What ``fast-tactile`` changes on top of the paper's settings: ``fast`` on the ``tactile`` track.

    Its touch encoder learns from the observations alone (``touch.labels="observation"``: touch
    odometry, pressed keys, press outcomes, and each key's offset from the sensor learnt in hindsight
    from the run's presses); the learner sees its goal's offset (``touch.goal_positions`` with these
    labels), and neither it nor its critics see the arm's pose.
    """
    if algo == "planner":
        return planner_changes(task)
    changes = fast_changes(task, algo)
    changes["epochs"] = TASK_PRESETS[task].fast_tactile_epochs
    changes["touch"].update(labels="observation", pose_inputs=False)
    changes["agent"].pop("critic_pose", None)
    return changes


def planner_changes(task: str) -> dict[str, Any]:
    """``fast-tactile`` for the key-graph planner (:mod:`~tactile_braille.agents.planner`): its epochs,
    no random start steps (its own epsilon starts at 1), one update of its key reader a step, a replay
    that stores each transition once (every transition relabelled as it is sampled), and on the discrete
    tasks a press on the last step a training episode's time limit allows (every training episode then
    labels its frames).

    On the continuous tasks its moves tap at a commanded 4 mm (``sense_depth``, the depth of an
    episode's first tap, so that every frame it reads is alike); its random actions press 8 times in 10
    (``explore_press``: each press names the key under the sensor, and the labels must cover every part
    of each key) over 2,000 steps of decaying epsilon; its states are each key as reached by each move
    (``entry_memory``: a move may leave the sensor on the key it was on); and no final press (a press
    with the move asked is none of its five actions). On the continuous arrows, in test episodes and
    typing, it presses only where the frame itself reads the goal at 0.8 or more (``press_reading``),
    and never on an episode's first frame (``first_press`` False). On the continuous alphabet its moves
    are 18 mm (``move`` 0.9), shorter than nearly every key along a row. Its test episodes and typing
    plan with a discount of their own (``test_gamma``; exploring keeps 0.9): 0.7 on the discrete
    arrows, 0.97 on the continuous alphabet (its long paths, where a sure route to a far key must
    outbid a likely press of the key beside it), 0.9 on the others. On the discrete arrows and the
    continuous alphabet its test episodes and typing plan on where each move already taken led
    (``outcome_memory``). On the discrete tasks its backtracking weighs each state by how often it is
    occupied (``backtrack_prior``); on the discrete tasks and the continuous alphabet a move into the
    generic *nothing* is worth none of that state's value (``lost_value`` 0). Each was tuned on seeds
    100-102; docs/notes/key-graph-planner.md and docs/notes/key-graph-planner-continuous.md have the
    measurements behind each."""
    spec, presets = task_presets(task)
    epochs = presets.fast_tactile_epochs if presets.planner_epochs is None else presets.planner_epochs
    changes: dict[str, Any] = {
        "epochs": epochs,
        "start_steps": 0,
        "final_press": not spec.continuous,
        "updates_per_step": 1,
        "replay": {"relabel": "all"},
    }
    if spec.continuous:
        agent = {
            "sense_depth": -1 / 3,
            "explore_press": 0.8,
            "epsilon_decay_steps": 2000,
            "entry_memory": True,
        }
    else:
        agent = {"backtrack_prior": True, "lost_value": 0.0}
    changes["agent"] = {**agent, **presets.planner_agent}  # each task's own (TASK_PRESETS)
    return changes


def preset_config(name: str, task: str, algo: str, **overrides: Any) -> TrainConfig:
    """A :class:`~tactile_braille.agents.config.TrainConfig` from a preset, with overrides on top.

    ``overrides`` take TrainConfig fields, and a group (``agent``, ``replay``,
    ``touch``, ``evaluation``) as a dict of its fields to change.
    """
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose one of {PRESETS}")
    agent_spec(algo)  # raises for an unknown name, listing the registered ones
    if name.startswith("fast") and algo not in PAPER_AGENTS and algo != "planner":
        raise ValueError(
            f"--preset {name} holds settings for the paper's agents {PAPER_AGENTS} only, not {algo}: "
            "use --preset paper (and agent.* settings of its own)"
        )
    changes = paper_changes(task, algo)
    if name.startswith("fast"):  # fast keeps the noise it was made with, in the actions' [-1, 1] units
        changes.pop("agent", None)
        changes.pop("edges", None)  # and the rig's world: its workspace edge stops the arm,
        changes.pop("tap_depth", None)  # and it taps at the depth commanded
    config = replace_settings(
        TrainConfig(task=task, algo=algo, preset=name, track=PRESET_TRACKS[name]), changes
    )
    if name == "released":
        config = replace_settings(config, released_changes(task, algo))
    if name == "fast":
        if algo == "planner":
            raise ValueError("the planner reads the tactile images alone: use --preset fast-tactile or paper")
        config = replace_settings(config, fast_changes(task, algo))
    if name == "fast-tactile":
        config = replace_settings(config, fast_tactile_changes(task, algo))
    return replace_settings(config, overrides)


def preset_differences(name: str, task: str, algo: str) -> list[str]:
    """``setting: paper -> preset`` for each setting in which preset ``name`` departs from the paper's."""
    return differences(
        preset_config("paper", task, algo), preset_config(name, task, algo), ignore=("preset", "track")
    )
