"""The paper's agents with Hindsight Experience Replay (so far: double + dueling DQN, discrete SAC)."""

from tactile_braille.agents.dqn import DQNAgent, DQNConfig
from tactile_braille.agents.replay import EpisodeReplayBuffer
from tactile_braille.agents.sac_discrete import DiscreteSACAgent, DiscreteSACConfig
from tactile_braille.agents.train import TrainConfig, train

__all__ = [
    "DQNAgent",
    "DQNConfig",
    "DiscreteSACAgent",
    "DiscreteSACConfig",
    "EpisodeReplayBuffer",
    "TrainConfig",
    "train",
]
