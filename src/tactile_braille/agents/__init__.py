"""The paper's agents with Hindsight Experience Replay: double + dueling DQN, discrete SAC, SAC, TD3."""

from tactile_braille.agents.dqn import DQNAgent, DQNConfig
from tactile_braille.agents.presets import PRESETS, preset_config
from tactile_braille.agents.replay import EpisodeReplayBuffer
from tactile_braille.agents.sac import SACAgent, SACConfig
from tactile_braille.agents.sac_discrete import DiscreteSACAgent, DiscreteSACConfig
from tactile_braille.agents.td3 import TD3Agent, TD3Config
from tactile_braille.agents.train import AGENTS, TrainConfig, evaluate, read_progress, train

__all__ = [
    "AGENTS",
    "PRESETS",
    "DQNAgent",
    "DQNConfig",
    "DiscreteSACAgent",
    "DiscreteSACConfig",
    "EpisodeReplayBuffer",
    "SACAgent",
    "SACConfig",
    "TD3Agent",
    "TD3Config",
    "TrainConfig",
    "evaluate",
    "preset_config",
    "read_progress",
    "train",
]
