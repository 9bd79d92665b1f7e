"""Named hyperparameter presets: the paper's Table II, the released code's settings, and ours.

``paper`` follows the paper's Table II, taking the released code's values
where the table is silent; ``released`` reproduces the configurations saved
with the original runs (``reference/braille_rl_2020/.../config.json``). The
differences are listed in ``docs/agents.md`` and in :data:`DIFFERENCES`.
``fast`` is ours (docs/agents.md, "Beyond the paper"): a touch encoder
fitted and refitted on the run's own labelled taps, relabelling of every
transition for every goal, and more, cheaper updates on the encoder's features;
on the continuous alphabet also asymmetric critics that see the sensor pose,
goals placed on the calibrated layout, and learning on the encoder's readout.

>>> config = preset_config("paper", "tactile_braille/DiscreteArrows-v0", "dqn")
>>> config.epochs, config.updates_per_step, config.agent.gamma
(25, 2, 0.95)
"""

from __future__ import annotations

import dataclasses
from typing import Any

PRESETS = ("paper", "released", "fast")

# Epochs of the original runs (sim): discrete arrows 25, discrete alphabet 100,
# continuous arrows 100, continuous alphabet 2000.
EPOCHS = {
    ("Discrete", "Arrows"): 25,
    ("Discrete", "Alphabet"): 100,
    ("Continuous", "Arrows"): 100,
    ("Continuous", "Alphabet"): 2000,
}

# Values on which the released code departs from the paper's Table II.
DIFFERENCES: dict[str, dict[str, tuple[Any, Any]]] = {
    "dqn": {"agent.test_epsilon": (0.0, 0.05)},
    "sac": {"agent.hidden": ((512,), (1024, 512)), "max_episode_steps": (25, 35)},
    "td3": {"agent.learning_rate": (5e-5, 7.5e-5), "update_every": (1, 100)},
    "sac_discrete": {},
}
"""algo -> setting -> (paper, released)."""

FAST_EPOCHS = {
    ("Discrete", "Arrows"): 8,
    ("Discrete", "Alphabet"): 25,
    ("Continuous", "Arrows"): 30,
    ("Continuous", "Alphabet"): 90,
}
"""Epochs of the ``fast`` preset: a third of the paper's convergence epochs or less, and the
90-epoch budget for the continuous alphabet."""


def fast_settings(kind: str, keys: str, algo: str) -> dict[str, Any]:
    """What ``fast`` changes on top of the paper's settings, for a task family and an algorithm."""
    arrows = keys == "Arrows"
    settings: dict[str, Any] = {
        "relabel": "all",
        "touch_encoder": True,
        "start_steps": 200 if arrows else 500,
        "touch_refit_every": 200 if arrows else 250,
        "touch_refits": 4 if arrows else 16,
        "updates_per_step": 2 if algo == "td3" else 4,
        "agent.hidden": (256, 256),
        "agent.batch_size": 128,
        "agent.learning_rate": 1e-3,
    }
    if (kind, keys) == ("Continuous", "Alphabet"):
        # Reading a letter at any offset takes many more taps than at key centres: refit all along.
        settings.update({"touch_refit_every": 1000, "touch_refits": 20})
        # The critics also see the sensor pose the arm reports: judging a move is easy from where the
        # sensor is, and the actor, which acts on touch alone, learns from that judgement.
        settings["agent.critic_pose"] = True
        # The goal is given where it lies on the calibrated layout, in the encoder's pose coordinates.
        settings["goal_positions"] = True
        # The agent learns on what the encoder reads (pose, key probabilities), which keeps its meaning
        # across the 20 refits, where latent features changed theirs and cost test return at each refit.
        settings["touch_inputs"] = "readout"
    if algo == "dqn":
        settings["agent.epsilon_decay_steps"] = 1000
    if algo in ("sac", "sac_discrete"):
        settings["agent.initial_alpha"] = 0.05  # press early: a high temperature pays for staying alive
    return settings


def _family(task: str) -> tuple[str, str]:
    name = task.split("/")[-1]
    for kind in ("Discrete", "Continuous"):
        for keys in ("Arrows", "Alphabet"):
            if name.startswith(f"{kind}{keys}"):
                return kind, keys
    raise ValueError(f"no preset for task {task!r}")


def preset_settings(name: str, task: str, algo: str) -> dict[str, Any]:
    """The TrainConfig fields (``agent.*`` for hyperparameters) that preset ``name`` sets."""
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose one of {PRESETS}")
    if algo not in DIFFERENCES:
        raise ValueError(f"unknown algorithm {algo!r}; choose one of {tuple(DIFFERENCES)}")
    settings: dict[str, Any] = {
        "epochs": EPOCHS[_family(task)],
        "steps_per_epoch": 250,
        "start_steps": 200,
        "updates_per_step": 1 if algo == "td3" else 2,
        "update_every": 1,
        "replay_capacity": 100_000,
        "test_episodes": 20,
        "her": True,
        "max_episode_steps": 25,
        "agent.batch_size": 32,
    }
    if name == "released":
        settings.update({key: value[1] for key, value in DIFFERENCES[algo].items()})
    if name == "fast":
        kind, keys = _family(task)
        settings["epochs"] = FAST_EPOCHS[kind, keys]
        settings.update(fast_settings(kind, keys, algo))
    return settings


def preset_config(name: str, task: str, algo: str, **overrides: Any):
    """A :class:`~tactile_braille.agents.train.TrainConfig` from a preset, with overrides on top.

    ``overrides`` take TrainConfig fields, and ``agent`` as a dict of
    hyperparameters to change.
    """
    from tactile_braille.agents.train import AGENTS, TrainConfig

    if algo not in AGENTS:
        raise ValueError(f"unknown algorithm {algo!r}; choose one of {tuple(AGENTS)}")
    settings = preset_settings(name, task, algo)
    agent_fields = {key[6:]: value for key, value in settings.items() if key.startswith("agent.")}
    agent_fields.update(overrides.pop("agent", None) or {})
    fields = {key: value for key, value in settings.items() if not key.startswith("agent.")}
    fields.update(overrides)
    agent_class = AGENTS[algo].config
    known = {field.name for field in dataclasses.fields(agent_class)}
    unknown = set(agent_fields) - known
    if unknown:
        raise ValueError(f"{agent_class.__name__} has no hyperparameters {sorted(unknown)}")
    return TrainConfig(task=task, algo=algo, preset=name, agent=agent_class(**agent_fields), **fields)
