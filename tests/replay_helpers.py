"""Observations and frames made by hand, shared by the replay buffer's and the touch encoder's tests.

Imported by name: pytest puts tests/ on sys.path (tests/conftest.py lives there).
"""

from __future__ import annotations

import numpy as np

from tactile_braille.agents.replay import EpisodeReplayBuffer

GOALS = 4
PREVIOUS = 5
FEATURES = 6


def replay_observation(observation: np.ndarray, goal: int, achieved: int | None = None) -> dict:
    one_hot = np.eye(GOALS, dtype=np.float32)
    return {
        "observation": observation,
        "previous_action": np.zeros(PREVIOUS, dtype=np.float32),
        "desired_goal": one_hot[goal],
        "achieved_goal": one_hot[achieved] if achieved is not None else np.zeros(GOALS, np.float32),
    }


class Frames:
    """Distinct observations in order (random binary images, or random feature vectors), kept in ``given``."""

    def __init__(self, features: bool = False, seed: int = 0) -> None:
        self.features, self.rng = features, np.random.default_rng(seed)
        self.given: list[np.ndarray] = []

    def __call__(self) -> np.ndarray:
        if self.features:
            frame = self.rng.normal(size=FEATURES).astype(np.float32)
        else:
            frame = ((self.rng.random((100, 100, 1)) < 0.3) * 255).astype(np.uint8)
        self.given.append(frame)
        return frame


def as_images(frames: list[np.ndarray]) -> np.ndarray:
    """(100, 100, 1) images as a (N, 1, 100, 100) batch."""
    return np.moveaxis(np.stack(frames), -1, 1)


def goal_indices(goals: np.ndarray) -> np.ndarray:
    """Indices of sampled goal one-hots (every sampled goal must be exactly one key)."""
    assert ((goals == 0) | (goals == 1)).all() and (goals.sum(-1) == 1).all()
    return goals.argmax(-1)


def n_step_buffer(n_step: int, relabel: str = "paper", capacity: int = 100, **kwargs) -> EpisodeReplayBuffer:
    return EpisodeReplayBuffer(capacity, GOALS, (), PREVIOUS, relabel=relabel,
                               observation_shape=(FEATURES,), n_step=n_step, gamma=0.5, **kwargs)  # fmt: skip


def feature_episode(buffer, goal: int, pressed: int | None, steps: int, first_frame: int) -> None:
    """An episode whose frames are numbered (each feature vector holds its number) and whose actions
    are its steps' indices; it ends pressing ``pressed`` (None: a time-out)."""
    frame = lambda k: np.full(FEATURES, first_frame + k, dtype=np.float32)  # noqa: E731
    buffer.start_episode(replay_observation(frame(0), goal))
    for t in range(steps):
        last = t == steps - 1
        achieved = pressed if last else None
        observation = replay_observation(frame(t + 1), goal, achieved)
        buffer.add_step(t, float(last and pressed == goal), observation, last and pressed is not None)
    buffer.end_episode()
