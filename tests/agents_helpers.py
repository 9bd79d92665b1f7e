"""Helpers shared by the agents' tests (imported by name: pytest puts tests/ on sys.path)."""

from __future__ import annotations

import csv
import importlib
import io

import torch

from tactile_braille.agents import (
    DiscreteSACAgent,
    DiscreteSACConfig,
    DQNAgent,
    DQNConfig,
    SACAgent,
    SACConfig,
    TD3Agent,
    TD3Config,
    TrainConfig,
)
from tactile_braille.agents.registry import agent_spec

# ``tactile_braille.agents`` re-exports the function ``train``, which shadows the submodule of the
# same name as an attribute of the package: go through the module registry for the module itself.
train_module = importlib.import_module("tactile_braille.agents.training")


DISCRETE_TASK = "tactile_braille/DiscreteArrows-v0"
CONTINUOUS_TASK = "tactile_braille/ContinuousArrows-v0"
ALGOS = {
    "dqn": (DQNAgent, DQNConfig, "discrete"),
    "sac_discrete": (DiscreteSACAgent, DiscreteSACConfig, "discrete"),
    "sac": (SACAgent, SACConfig, "continuous"),
    "td3": (TD3Agent, TD3Config, "continuous"),
}


HIDDEN = (16,)


def through_file(state: dict) -> dict:
    """A state dict as a checkpoint file gives it back (no tensor shared with the live agent)."""
    buffer = io.BytesIO()
    torch.save(state, buffer)
    buffer.seek(0)
    return torch.load(buffer, weights_only=False)


def same_weights(a: torch.nn.Module, b: torch.nn.Module) -> bool:
    ours, theirs = a.state_dict(), b.state_dict()
    return ours.keys() == theirs.keys() and all(torch.equal(ours[k], theirs[k]) for k in ours)


def read_progress_csv(run_dir) -> list[dict]:
    with open(run_dir / "progress.csv", newline="") as handle:
        return list(csv.DictReader(handle))


def touch_config(env_datasets, algo: str = "dqn", **changes) -> TrainConfig:
    task = CONTINUOUS_TASK if agent_spec(algo).acts_in(continuous=True) else DISCRETE_TASK
    settings = {
        "task": task,
        "algo": algo,
        "epochs": 1,
        "steps_per_epoch": 20,
        "start_steps": 12,
        "threads": 1,
        "dataset": str(env_datasets[task]),
        "agent": agent_spec(algo).config(hidden=(16,), batch_size=8),
        "evaluation": {"test_episodes": 1, "snapshots": 1},
        "replay": {"capacity": 200},
        "touch": {"enabled": True, "epochs": 2},
        "track": "proprio",
    }
    groups = {name: {**settings[name], **changes.pop(name)} for name in ("evaluation", "replay", "touch")
              if isinstance(changes.get(name), dict)}  # fmt: skip
    return TrainConfig(**{**settings, **groups, **changes})
