"""The paper's agents with Hindsight Experience Replay (so far: double + dueling DQN)."""

from tactile_braille.agents.dqn import DQNAgent, DQNConfig
from tactile_braille.agents.replay import EpisodeReplayBuffer
from tactile_braille.agents.train import TrainConfig, train

__all__ = ["DQNAgent", "DQNConfig", "EpisodeReplayBuffer", "TrainConfig", "train"]
