"""The paper's agents with Hindsight Experience Replay: double + dueling DQN, discrete SAC, SAC, TD3;
MR.Q, a recent learner from pixels for both kinds of actions; and ours, the key-graph planner.

An agent is a class that keeps the :class:`Agent` contract, a hyperparameter
class (an :class:`AgentConfig`), and one :class:`AgentSpec` given to
:func:`register_agent` (docs/extending.md). Names are imported on first use,
so that ``tactile_braille.agents.config`` (the settings, which the command
line is generated from) loads without torch.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "Agent": "common",
    "AgentConfig": "config",
    "AgentSpec": "registry",
    "register_agent": "registry",
    "agent_spec": "registry",
    "agent_names": "registry",
    "BatchExtra": "replay",
    "make_replay": "training",
    "train": "training",
    "make_agent": "training",
    "make_env": "training",
    "evaluate": "rollout",
    "run_episode": "rollout",
    "read_progress": "run",
    "EpisodeReplayBuffer": "replay",
    "PRESETS": "presets",
    "preset_config": "presets",
    "TrainConfig": "config",
    "DQNConfig": "config",
    "DiscreteSACConfig": "config",
    "SACConfig": "config",
    "TD3Config": "config",
    "MRQConfig": "config",
    "PlannerConfig": "config",
    "DQNAgent": "dqn",
    "DiscreteSACAgent": "sac_discrete",
    "SACAgent": "sac",
    "TD3Agent": "td3",
    "MRQAgent": "mrq",
    "PlannerAgent": "planner",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
