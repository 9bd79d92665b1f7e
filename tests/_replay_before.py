"""The pre-split replay buffer, kept verbatim to prove the split one equivalent (tests/agents/test_replay.py).

A frozen copy of ``tactile_braille.agents.replay`` as it was before ``EpisodeReplayBuffer`` was
split into a frame store, a relabelling strategy and a feature cache; only this paragraph is new.
Do not edit it: tests/agents/test_replay.py drives it and the new buffer with the same calls and asserts
equal samples, equal generator draws and interchangeable checkpoints.

Episode replay with the paper's Hindsight Experience Replay, storing each image once.

Images are bit-packed (100x100 binary -> 1,250 bytes) in a ring of *frames*;
transitions only hold the indices of their two frames, so an image shared by
two transitions, or by a transition and its hindsight copy, is stored once.

HER as released with the paper: when an episode ends because a WRONG key was
pressed, every transition of the episode is stored again with the pressed key
as the goal and the final reward set to 1. Time-outs are not relabelled (the
achieved goal exists only at the final step, so the usual 'future' strategy
does not apply). ``her=False`` turns it off.

``relabel="all"`` (ours, not the paper's) relabels when sampling instead:
the reward of a press depends only on which key was pressed and which was
wanted, and the dynamics do not depend on the goal, so every transition is a
valid transition for every goal. A sampled transition keeps its goal, or
takes its episode's pressed key (the paper's relabelling, for every episode
that ended in a press of a task key, right or wrong), or a uniformly random
goal (a press of key k then teaches "not here" for the other goals). No
copies are stored.

Observations are tactile images or feature vectors (``observation_shape=(n,)``,
stored as float32). Each stored frame may carry *labels*, what a robot knows
of a tap without touch (sensor pose, pressed key, key under the sensor), and
an image buffer may be given an *encoder* (:meth:`set_encoder`): batches then
hold its features of the stored images, kept in a cache that
:meth:`set_encoder` recomputes when the encoder changes (a touch encoder
refitted on the labelled frames, :mod:`~tactile_braille.agents.touch`).

Memory at the paper's capacity of 100,000 transitions: the frame ring holds
twice as many frames as transitions (episodes of one step need two frames
per transition) plus room for the episode in progress (whose frames are
written before its transitions are committed), about 200,000 x 1,250 bytes
= 250 MB, plus about 60 bytes per transition.
"""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

import numpy as np

from tactile_braille._io import atomic_path

PACKED_BYTES = 100 * 100 // 8
RELABELLING = ("paper", "all")
FRAME_LABELS = 5
"""Labels of a frame: sensor x, y, depth (mm), pressed key, key under the sensor."""


def _goal_index(one_hot: np.ndarray) -> int:
    """Index of a goal one-hot, -1 for the zero vector (no key of the task)."""
    return int(one_hot.argmax()) if one_hot.any() else -1


class EpisodeReplayBuffer:
    """Transitions of goal-conditioned episodes, with hindsight relabelling.

    Args:
        capacity: transitions kept (the oldest are overwritten).
        goal_size: length of the goal one-hots.
        action_shape: shape of one action (``()`` for discrete).
        previous_action_size: length of the previous-action vector.
        her: relabel with hindsight.
        max_episode_steps: the longest episode it will record (room is kept
            for the frames of the episode in progress).
        relabel: ``"paper"`` (store copies of wrong-press episodes) or
            ``"all"`` (relabel when sampling, see above).
        relabel_final, relabel_random: with ``"all"``, the probabilities that
            a sampled transition takes its episode's pressed key, or a random goal.
        observation_shape: ``(100, 100, 1)`` for images (bit-packed), ``(n,)``
            for feature vectors.
        poses: batches also carry the labelled sensor poses (x, y, depth in mm) of
            both frames, ``poses`` and ``next_poses``, for asymmetric critics.
    """

    def __init__(
        self,
        capacity: int,
        goal_size: int,
        action_shape: tuple[int, ...],
        previous_action_size: int,
        her: bool = True,
        max_episode_steps: int = 100,
        relabel: str = "paper",
        relabel_final: float = 0.4,
        relabel_random: float = 0.4,
        observation_shape: tuple[int, ...] = (100, 100, 1),
        poses: bool = False,
    ) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be at least 1, got {capacity}")
        if max_episode_steps < 1:
            raise ValueError(f"max_episode_steps must be at least 1, got {max_episode_steps}")
        if relabel not in RELABELLING:
            raise ValueError(f"relabel must be one of {RELABELLING}, got {relabel!r}")
        if not (relabel_final >= 0 and relabel_random >= 0 and relabel_final + relabel_random <= 1):
            raise ValueError(
                f"relabel_final={relabel_final} and relabel_random={relabel_random} must be "
                "probabilities that sum to at most 1"
            )
        self.images = tuple(observation_shape) == (100, 100, 1)
        if not self.images and len(observation_shape) != 1:
            raise ValueError(f"observations must be 100x100x1 images or vectors, got {observation_shape}")
        self.capacity = int(capacity)
        self.poses = bool(poses)
        self.her = her
        self.relabel = relabel
        self.relabel_final, self.relabel_random = float(relabel_final), float(relabel_random)
        self.goal_size = int(goal_size)
        self.max_episode_steps = int(max_episode_steps)
        # Committed transitions use at most 2 frames each; the episode in progress adds its own.
        self.frame_capacity = 2 * self.capacity + self.max_episode_steps + 1
        if self.images:
            self.frames = np.zeros((self.frame_capacity, PACKED_BYTES), dtype=np.uint8)
        else:
            self.frames = np.zeros((self.frame_capacity, observation_shape[0]), dtype=np.float32)
        self.frame_index = np.zeros((self.capacity, 2), dtype=np.int64)  # (this, next)
        self.previous_actions = np.zeros((self.capacity, 2, previous_action_size), dtype=np.float32)
        self.goals = np.zeros((self.capacity, goal_size), dtype=np.float32)
        action_dtype = np.int64 if action_shape == () else np.float32
        self.actions = np.zeros((self.capacity, *action_shape), dtype=action_dtype)
        self.rewards = np.zeros(self.capacity, dtype=np.float32)
        self.dones = np.zeros(self.capacity, dtype=np.float32)
        # Goal index of the key pressed at the step, and at the end of its episode (-1: none).
        self.achieved = np.full(self.capacity, -1, dtype=np.int16)
        self.finals = np.full(self.capacity, -1, dtype=np.int16)
        self.next_frame = 0
        self.frames_written = 0
        # Per frame: sensor x, y, depth (mm), pressed key, key under the sensor (goal indices, -1 none);
        # NaN where a frame came without labels.
        self.frame_labels = np.full((self.frame_capacity, FRAME_LABELS), np.nan, dtype=np.float32)
        self.features: np.ndarray | None = None  # the encoder's features of the frames (set_encoder)
        self._encode = None
        self._committed = (0, 0)  # (next_frame, frames_written) after the last committed episode
        self.next_slot = 0
        self.size = 0
        self._episode: list[dict] = []
        self._current_frame = -1
        self._current_previous_action: np.ndarray | None = None

    # --------------------------------------------------------- writing
    def _store_frame(self, image: np.ndarray, label: np.ndarray | None = None) -> int:
        slot = self.next_frame
        if self.images:
            self.frames[slot] = np.packbits(np.asarray(image).reshape(-1) > 127)
        else:
            self.frames[slot] = image
        self.frame_labels[slot] = np.nan if label is None else label
        if self._encode is not None:
            self.features[slot] = self._encode(self._images(np.array([slot])))[0]
        self.next_frame = (self.next_frame + 1) % self.frame_capacity
        self.frames_written += 1
        return slot

    def start_episode(self, observation: dict[str, np.ndarray], label: np.ndarray | None = None) -> None:
        """Store an episode's first observation (and its frame's labels, if known)."""
        self._episode = []
        self._current_frame = self._store_frame(observation["observation"], label)
        self._current_previous_action = np.asarray(observation["previous_action"], dtype=np.float32)

    def add_step(
        self,
        action,
        reward: float,
        next_observation: dict[str, np.ndarray],
        terminated: bool,
        label: np.ndarray | None = None,
    ) -> None:
        """Record one step of the episode in progress (its goal: the desired one; ``label``: its frame's)."""
        if self._current_frame < 0:
            raise RuntimeError("call start_episode before add_step")
        if len(self._episode) >= self.max_episode_steps:
            raise RuntimeError(
                f"episode longer than max_episode_steps={self.max_episode_steps}; build the buffer with more"
            )
        next_frame = self._store_frame(next_observation["observation"], label)
        next_previous = np.asarray(next_observation["previous_action"], dtype=np.float32)
        self._episode.append(
            {
                "frames": (self._current_frame, next_frame),
                "previous": (self._current_previous_action, next_previous),
                "goal": np.asarray(next_observation["desired_goal"], dtype=np.float32),
                "action": action,
                "reward": float(reward),
                "done": float(terminated),
                "achieved": np.asarray(next_observation["achieved_goal"], dtype=np.float32),
            }
        )
        self._current_frame, self._current_previous_action = next_frame, next_previous

    def end_episode(self) -> None:
        """Commit the episode's transitions, and their hindsight copies (the paper's HER)."""
        final = _goal_index(self._episode[-1]["achieved"]) if self._episode else -1
        for step in self._episode:
            self._add(step, step["goal"], step["reward"], final)
        if self.her and self.relabel == "paper" and self._episode:
            last = self._episode[-1]
            wrong_press = last["achieved"].any() and not np.array_equal(last["achieved"], last["goal"])
            if wrong_press:
                for i, step in enumerate(self._episode):
                    self._add(step, last["achieved"], 1.0 if i == len(self._episode) - 1 else 0.0, final)
        self._episode = []
        self._current_frame = -1
        self._committed = (self.next_frame, self.frames_written)

    def _add(self, step: dict, goal: np.ndarray, reward: float, final: int) -> None:
        slot = self.next_slot
        self.achieved[slot] = _goal_index(step["achieved"])
        self.finals[slot] = final
        self.frame_index[slot] = step["frames"]
        self.previous_actions[slot, 0] = step["previous"][0]
        self.previous_actions[slot, 1] = step["previous"][1]
        self.goals[slot] = goal
        self.actions[slot] = step["action"]
        self.rewards[slot] = reward
        self.dones[slot] = step["done"]
        self.next_slot = (self.next_slot + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)

    # --------------------------------------------------------- reading
    def _images(self, frames: np.ndarray) -> np.ndarray:
        if not self.images:
            return self.frames[frames]
        bits = np.unpackbits(self.frames[frames], axis=-1)
        return (bits.reshape(len(frames), 1, 100, 100) * 255).astype(np.uint8)

    def sample(self, batch_size: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """A uniform batch of transitions (images as (B, 1, 100, 100) uint8, or features (B, n))."""
        if self.size == 0:
            raise RuntimeError("the replay buffer is empty")
        index = rng.integers(self.size, size=batch_size)
        frames = self.frame_index[index]
        goals, rewards = self.goals[index], self.rewards[index]
        if self.her and self.relabel == "all":
            goals, rewards = self._relabel(index, rng)
        observations = self._images if self.features is None else self.features.__getitem__
        batch = {
            "images": observations(frames[:, 0]),
            "previous_actions": self.previous_actions[index, 0],
            "goals": goals,
            "actions": self.actions[index],
            "rewards": rewards,
            "next_images": observations(frames[:, 1]),
            "next_previous_actions": self.previous_actions[index, 1],
            "dones": self.dones[index],
        }
        if self.poses:
            poses = self.frame_labels[frames, :3]  # (B, 2, 3)
            if np.isnan(poses).any():
                raise RuntimeError("poses=True needs labelled frames, but a sampled frame has no labels")
            batch["poses"], batch["next_poses"] = poses[:, 0], poses[:, 1]
        return batch

    def _relabel(self, index: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Goals and rewards of sampled transitions under ``relabel="all"``."""
        goal = self.goals[index].argmax(-1)
        goal = np.where(self.goals[index].any(-1), goal, -1)
        draw = rng.random(len(index))
        final = self.finals[index].astype(np.int64)
        to_final = (draw < self.relabel_final) & (final >= 0)
        to_random = (draw >= self.relabel_final) & (draw < self.relabel_final + self.relabel_random)
        goal = np.where(to_final, final, goal)
        goal = np.where(to_random, rng.integers(self.goal_size, size=len(index)), goal)
        goals = np.zeros((len(index), self.goal_size), dtype=np.float32)
        has_goal = goal >= 0
        goals[np.flatnonzero(has_goal), goal[has_goal]] = 1.0
        rewards = ((self.achieved[index] == goal) & has_goal).astype(np.float32)
        return goals, rewards

    def _written_frames(self) -> np.ndarray:
        """Slots that hold a frame (committed or of the episode in progress)."""
        return np.arange(min(self.frames_written, self.frame_capacity))

    def set_encoder(self, encode, size: int, batch_size: int = 1024) -> None:
        """From now on, batches hold ``encode``'s features of the stored images (recomputed now).

        ``encode`` takes (B, 1, 100, 100) uint8 images and returns (B, size)
        float32 features. Call it again after the encoder changed.
        """
        if not self.images:
            raise ValueError("set_encoder needs a buffer of images")
        features = np.zeros((self.frame_capacity, size), dtype=np.float32)
        written = self._written_frames()
        for start in range(0, len(written), batch_size):
            frames = written[start : start + batch_size]
            features[frames] = encode(self._images(frames))
        self.features, self._encode = features, encode

    def labelled_frames(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Images (N, 1, 100, 100), poses (N, 3), pressed and under-sensor keys (N,) of labelled frames."""
        if not self.images:
            raise ValueError("this buffer holds features, not images")
        written = self._written_frames()
        frames = written[~np.isnan(self.frame_labels[written, 0])]
        labels = self.frame_labels[frames]
        return (
            self._images(frames),
            labels[:, :3],
            labels[:, 3].astype(np.int64),
            labels[:, 4].astype(np.int64),
        )

    # ------------------------------------------------------ checkpoints
    _ARRAYS = (
        "frames", "frame_index", "previous_actions", "goals", "actions", "rewards", "dones",
        "achieved", "finals",
    )  # fmt: skip
    _ADDED_LATER: ClassVar[dict[str, int]] = {"achieved": -1, "finals": -1}
    """Arrays that older buffers lack, and their fill value (no key known); older buffers' frames have
    no labels."""

    def save(self, path: str | Path) -> None:
        """Write the used part of the buffer (committed transitions) atomically as ``.npz``.

        The frames of an episode in progress are left out (the counters are
        those after the last committed episode), so a resumed run has the
        whole slack of the frame ring for its next episode.
        """
        next_frame, frames_written = self._committed
        frames = min(frames_written, self.frame_capacity)
        arrays = {name: getattr(self, name)[: self.size] for name in self._ARRAYS if name != "frames"}
        with atomic_path(path, fsync=True) as temporary, open(temporary, "wb") as handle:
            np.savez(
                handle,
                counters=np.array([next_frame, frames_written, self.next_slot, self.size]),
                frame_capacity=np.array(self.frame_capacity),
                frames=self.frames[:frames],
                frame_labels=self.frame_labels[:frames],
                **arrays,
            )

    def load(self, path: str | Path) -> None:
        """Restore a buffer written by :meth:`save` (same capacity and sizes)."""
        with np.load(path) as data:
            if "frame_capacity" not in data or int(data["frame_capacity"]) != self.frame_capacity:
                raise ValueError(
                    f"{path}: written by a buffer with another frame ring "
                    "(its capacity or max_episode_steps differ)"
                )
            size = int(data["counters"][3])
            stored = {
                name: data[name] if name in data else np.full(size, self._ADDED_LATER[name], dtype=np.int16)
                for name in self._ARRAYS
            }
            for name, array in stored.items():  # check everything before changing anything
                mine = getattr(self, name)
                if array.shape[1:] != mine.shape[1:] or len(array) > len(mine):
                    raise ValueError(f"{path}: {name} of shape {array.shape} does not fit {mine.shape}")
            labels = data.get("frame_labels")
            if labels is not None and (
                labels.shape[1:] != self.frame_labels.shape[1:] or len(labels) > self.frame_capacity
            ):
                raise ValueError(
                    f"{path}: frame_labels of shape {labels.shape} does not fit {self.frame_labels.shape}"
                )
            for name, array in stored.items():
                getattr(self, name)[: len(array)] = array
            self.frame_labels[:] = np.nan
            if labels is not None:
                self.frame_labels[: len(labels)] = labels
            self.next_frame, self.frames_written, self.next_slot, self.size = (
                int(v) for v in data["counters"]
            )
            self._committed = (self.next_frame, self.frames_written)
        self._episode = []
        self._current_frame = -1
        if self._encode is not None:
            self.set_encoder(self._encode, self.features.shape[1])
