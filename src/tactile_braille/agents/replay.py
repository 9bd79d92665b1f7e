"""Episode replay with the paper's Hindsight Experience Replay, storing each image once.

:class:`EpisodeReplayBuffer` records goal-conditioned episodes and samples
batches of their transitions. It is made of three parts, in this order below:

- :class:`FrameStore`, a ring of *frames*: the observations, each stored
  once, with the *labels* a robot knows of a tap without touch (sensor pose,
  pressed key, key under the sensor). Binary (H, W, 1) images are bit-packed
  (100x100 -> 1,250 bytes), feature vectors (``observation_shape=(n,)``) are
  stored as float32. Transitions only hold the slots of their two frames, so
  an image shared by two transitions, or by a transition and its hindsight
  copy, is stored once.
- A relabelling strategy (:class:`Relabelling`), chosen by name, with two
  hooks: the transitions an episode adds when it ends, and how the goals and
  rewards of sampled transitions are rewritten.
- :class:`FeatureCache`: given an *encoder* (:meth:`EpisodeReplayBuffer.set_encoder`),
  batches of an image buffer hold its features of the stored images, kept in a
  cache that :meth:`~EpisodeReplayBuffer.set_encoder` recomputes when the encoder
  changes (a touch encoder refitted on the labelled frames,
  :mod:`~tactile_braille.agents.touch`).

The buffer itself keeps the transitions (frame slots, previous actions, goals,
actions, rewards, dones, pressed keys) and writes and reads checkpoints.

HER as released with the paper (``relabel="paper"``): when an episode ends
because a WRONG key was pressed, every transition of the episode is stored
again with the pressed key as the goal and the final reward set to 1.
Time-outs are not relabelled (the achieved goal exists only at the final
step, so the usual 'future' strategy does not apply). ``her=False`` turns
relabelling off.

``relabel="all"`` (ours, not the paper's) relabels when sampling instead:
the reward of a press depends only on which key was pressed and which was
wanted, and the dynamics do not depend on the goal, so every transition is a
valid transition for every goal. A sampled transition keeps its goal, or
takes its episode's pressed key (the paper's relabelling, for every episode
that ended in a press of a task key, right or wrong), or a uniformly random
goal (a press of key k then teaches "not here" for the other goals). No
copies are stored.

``n_step`` > 1 (ours, not the paper's) makes each sampled transition an
n-step one: the discounted rewards of up to ``n_step`` steps of its episode
(under the goal it was sampled with), bootstrapped from the frame after the
last of them; batches then carry ``steps``, the steps the return spans,
for a discount of ``gamma ** steps``. A window never crosses its episode's
end. With the default of 1 batches are as they always were.

Memory at the paper's capacity of 100,000 transitions: the frame ring holds
twice as many frames as transitions (episodes of one step need two frames
per transition) plus room for the episode in progress (whose frames are
written before its transitions are committed), about 200,000 x 1,250 bytes
= 250 MB, plus about 60 bytes per transition.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, ClassVar, NamedTuple

import numpy as np

from tactile_braille._io import atomic_path

PACKED_BYTES = 100 * 100 // 8
"""Bytes of a packed frame of the default 100x100 image."""
FRAME_LABELS = 5
"""Labels of a frame: sensor x, y, depth (mm), pressed key, key under the sensor."""

Encoder = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""(B, 1, H, W) uint8 images and their frames' labels (B, FRAME_LABELS; NaN: none) -> (B, size) float32
features (a touch agent with pose inputs appends each frame's pose)."""


def _goal_index(one_hot: np.ndarray) -> int:
    """Index of a goal one-hot, -1 for the zero vector (no key of the task)."""
    return int(one_hot.argmax()) if one_hot.any() else -1


# ================================================================= frames
class FrameStore:
    """A ring of observations, each with its labels (NaN where a frame came without).

    Args:
        capacity: frames kept (the oldest are overwritten).
        observation_shape: ``(H, W, C)`` for binary images (C channels: 1, or stacked taps),
            bit-packed to ``ceil(H * W * C / 8)`` bytes (pixels above 127 are 1) and handed
            back as (B, C, H, W) uint8 images of 0 and 255; ``(n,)`` for float32 vectors.
    """

    def __init__(self, capacity: int, observation_shape: tuple[int, ...] = (100, 100, 1)) -> None:
        shape = tuple(observation_shape)
        self.images = len(shape) == 3 and min(shape) >= 1
        if not self.images and len(shape) != 1:
            raise ValueError(
                f"observations must be (H, W, C) binary images or vectors, got {observation_shape}"
            )
        self.capacity = int(capacity)
        if self.images:
            self.image_shape = (int(shape[2]), int(shape[0]), int(shape[1]))
            self.pixels = int(np.prod(shape))
            self.frames = np.zeros((self.capacity, -(-self.pixels // 8)), dtype=np.uint8)
        else:
            self.frames = np.zeros((self.capacity, shape[0]), dtype=np.float32)
        # Per frame: sensor x, y, depth (mm), pressed key, key under the sensor (goal indices, -1 none).
        self.labels = np.full((self.capacity, FRAME_LABELS), np.nan, dtype=np.float32)
        self.next_frame = 0
        self.frames_written = 0
        self.committed = (0, 0)  # (next_frame, frames_written) at the last commit: what a checkpoint keeps

    def store(self, observation: np.ndarray, label: np.ndarray | None = None) -> int:
        """Store one observation (and its labels, if known); returns its slot."""
        slot = self.next_frame
        if self.images:
            self.frames[slot] = np.packbits(np.asarray(observation).reshape(-1) > 127)
        else:
            self.frames[slot] = observation
        self.labels[slot] = np.nan if label is None else label
        self.next_frame = (self.next_frame + 1) % self.capacity
        self.frames_written += 1
        return slot

    def commit(self) -> None:
        """Mark the frames written so far as those a checkpoint keeps."""
        self.committed = (self.next_frame, self.frames_written)

    def observations(self, slots: np.ndarray) -> np.ndarray:
        """The observations of ``slots`` (1-D): images (B, C, H, W) uint8, or vectors (B, n)."""
        if not self.images:
            return self.frames[slots]
        channels, height, width = self.image_shape
        bits = np.unpackbits(self.frames[slots], axis=-1, count=self.pixels)
        images = bits.reshape(len(slots), height, width, channels)
        if channels > 1:  # stored as the environment gives them, channels last
            images = images.transpose(0, 3, 1, 2)
        return np.ascontiguousarray(images.reshape(len(slots), *self.image_shape) * 255, dtype=np.uint8)

    def written_slots(self) -> np.ndarray:
        """Slots that hold a frame (committed or of the episode in progress)."""
        return np.arange(min(self.frames_written, self.capacity))

    def labelled(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Images (N, 1, H, W), poses (N, 3), pressed and under-sensor keys (N,) of labelled frames."""
        if not self.images:
            raise ValueError("this buffer holds features, not images")
        written = self.written_slots()
        slots = written[~np.isnan(self.labels[written, 0])]
        labels = self.labels[slots]
        return (
            self.observations(slots),
            labels[:, :3],
            labels[:, 3].astype(np.int64),
            labels[:, 4].astype(np.int64),
        )

    # checkpoints: the committed frames and their labels; the counters are written by the buffer
    def checkpoint(self) -> tuple[tuple[int, int], dict[str, np.ndarray]]:
        """The committed counters (next_frame, frames_written) and the arrays of the committed frames."""
        kept = min(self.committed[1], self.capacity)
        return self.committed, {"frames": self.frames[:kept], "frame_labels": self.labels[:kept]}

    def read_checkpoint(
        self, data: Mapping[str, np.ndarray], path: str | Path
    ) -> dict[str, np.ndarray | None]:
        """The checkpoint's frame arrays, checked to fit this store (which is left unchanged).

        Files written before frames had labels give ``frame_labels`` None.
        """
        if "frame_capacity" not in data or int(data["frame_capacity"]) != self.capacity:
            raise ValueError(
                f"{path}: written by a buffer with another frame ring "
                "(its capacity or max_episode_steps differ)"
            )
        frames = data["frames"]
        if frames.shape[1:] != self.frames.shape[1:] or len(frames) > self.capacity:
            raise ValueError(f"{path}: frames of shape {frames.shape} does not fit {self.frames.shape}")
        labels = data.get("frame_labels")
        if labels is not None and (labels.shape[1:] != self.labels.shape[1:] or len(labels) > self.capacity):
            raise ValueError(f"{path}: frame_labels of shape {labels.shape} does not fit {self.labels.shape}")
        return {"frames": frames, "frame_labels": labels}

    def restore(self, arrays: dict[str, np.ndarray | None], next_frame: int, frames_written: int) -> None:
        """Take the arrays of :meth:`read_checkpoint` and the counters; they become the committed frames."""
        frames, labels = arrays["frames"], arrays["frame_labels"]
        self.frames[: len(frames)] = frames
        self.labels[:] = np.nan
        if labels is not None:
            self.labels[: len(labels)] = labels
        self.next_frame, self.frames_written = int(next_frame), int(frames_written)
        self.commit()


# ================================================================= features
class FeatureCache:
    """An encoder's features of the frames of a :class:`FrameStore` of images.

    Empty (``features`` None) until :meth:`set` is given an encoder; from then
    on every frame stored should be :meth:`add`-ed.
    """

    def __init__(self, store: FrameStore) -> None:
        self.store = store
        self.features: np.ndarray | None = None  # (store capacity, size) float32
        self.encode: Encoder | None = None

    def set(self, encode: Encoder, size: int, batch_size: int = 1024) -> None:
        """Compute ``encode``'s features of every written frame (again, after the encoder changed)."""
        if not self.store.images:
            raise ValueError("set_encoder needs a buffer of images")
        features = np.zeros((self.store.capacity, size), dtype=np.float32)
        written = self.store.written_slots()
        for start in range(0, len(written), batch_size):
            slots = written[start : start + batch_size]
            features[slots] = encode(self.store.observations(slots), self.store.labels[slots])
        self.features, self.encode = features, encode

    def add(self, slot: int) -> None:
        """Compute the feature of a newly stored frame (nothing without an encoder)."""
        if self.encode is not None:
            slots = np.array([slot])
            self.features[slot] = self.encode(self.store.observations(slots), self.store.labels[slots])[0]

    def lookup(self, slots: np.ndarray) -> np.ndarray:
        """The features (B, size) of ``slots``."""
        return self.features[slots]


# ================================================================= relabelling
class Step(NamedTuple):
    """One step of the episode in progress, as :meth:`EpisodeReplayBuffer.add_step` recorded it."""

    frames: tuple[int, int]  # slots of the observation and the next observation
    previous: tuple[np.ndarray, np.ndarray]  # previous-action vectors of both
    goal: np.ndarray  # the desired goal one-hot
    action: Any
    reward: float
    done: float
    achieved: np.ndarray  # the achieved goal one-hot (zero: no key of the task pressed)


class Relabelling:
    """No relabelling (``her=False``): an episode adds its own transitions, batches keep their goals.

    A relabelling strategy has two hooks: :meth:`episode_end` (extra transitions
    an ending episode adds) and :meth:`sampled` (goals and rewards of sampled
    transitions).
    """

    name: ClassVar[str] = "none"

    def episode_end(self, episode: list[Step]) -> list[tuple[Step, np.ndarray, float]]:
        """Extra transitions of an ending episode, as (step, goal, reward), stored after its own."""
        return []

    def sampled(
        self,
        goals: np.ndarray,
        rewards: np.ndarray,
        achieved: np.ndarray,
        finals: np.ndarray,
        rng: np.random.Generator,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Goals (B, goal_size) and rewards (B,) of sampled transitions, from their stored goals and
        rewards, the goal indices of their pressed keys and of their episodes' final keys (-1: none)."""
        return goals, rewards

    def rewards(self, goals: np.ndarray, stored: np.ndarray, achieved: np.ndarray) -> np.ndarray:
        """Rewards of transitions under the goals :meth:`sampled` gave their batch's transitions (for
        the later steps of n-step returns): the stored ones, where goals are never rewritten."""
        return stored

    def goal_weights(self, goals: np.ndarray, finals: np.ndarray) -> np.ndarray:
        """How likely :meth:`sampled` gives each transition each goal, (B, goal_size), from their
        stored goals and their episodes' final keys: here the stored goal, certainly."""
        return goals.astype(np.float32)


class PaperRelabelling(Relabelling):
    """The paper's HER: a wrong-press episode is stored again with the pressed key as its goal."""

    name: ClassVar[str] = "paper"

    def episode_end(self, episode: list[Step]) -> list[tuple[Step, np.ndarray, float]]:
        if not episode:
            return []
        last = episode[-1]
        wrong_press = last.achieved.any() and not np.array_equal(last.achieved, last.goal)
        if not wrong_press:
            return []
        return [
            (step, last.achieved, 1.0 if i == len(episode) - 1 else 0.0) for i, step in enumerate(episode)
        ]


class SampledRelabelling(Relabelling):
    """Relabelling of every transition when sampled (``relabel="all"``).

    A sampled transition takes its episode's pressed key with probability
    ``final`` (when its episode ended in a press of a task key), a uniformly
    random goal with probability ``random``, or else keeps its goal; its
    reward is 1 where its pressed key is its goal.
    """

    name: ClassVar[str] = "all"

    def __init__(self, final: float, random: float) -> None:
        self.final, self.random = float(final), float(random)

    def sampled(
        self,
        goals: np.ndarray,
        rewards: np.ndarray,
        achieved: np.ndarray,
        finals: np.ndarray,
        rng: np.random.Generator,
    ) -> tuple[np.ndarray, np.ndarray]:
        batch, goal_size = goals.shape
        goal = np.where(goals.any(-1), goals.argmax(-1), -1)
        draw = rng.random(batch)
        final = finals.astype(np.int64)
        to_final = (draw < self.final) & (final >= 0)
        to_random = (draw >= self.final) & (draw < self.final + self.random)
        goal = np.where(to_final, final, goal)
        goal = np.where(to_random, rng.integers(goal_size, size=batch), goal)
        relabelled = np.zeros((batch, goal_size), dtype=np.float32)
        has_goal = goal >= 0
        relabelled[np.flatnonzero(has_goal), goal[has_goal]] = 1.0
        return relabelled, self.rewards(relabelled, rewards, achieved)

    def goal_weights(self, goals: np.ndarray, finals: np.ndarray) -> np.ndarray:
        batch, goal_size = goals.shape
        weights = np.full((batch, goal_size), self.random / goal_size, dtype=np.float32)
        weights += (1.0 - self.final - self.random) * goals  # kept
        final = finals.astype(np.int64)
        has_final = final >= 0
        weights[np.flatnonzero(has_final), final[has_final]] += self.final
        weights[~has_final] += self.final * goals[~has_final]  # no key to relabel to: kept
        return weights

    def rewards(self, goals: np.ndarray, stored: np.ndarray, achieved: np.ndarray) -> np.ndarray:
        """1 where the pressed key is the goal."""
        goal = np.where(goals.any(-1), goals.argmax(-1), -1)
        return ((achieved == goal) & (goal >= 0)).astype(np.float32)


RELABELLINGS: dict[str, type[Relabelling]] = {"paper": PaperRelabelling, "all": SampledRelabelling}
RELABELLING = tuple(RELABELLINGS)
"""The names ``relabel`` takes."""


def make_relabelling(relabel: str, her: bool = True, final: float = 0.4, random: float = 0.4) -> Relabelling:
    """The strategy named ``relabel`` (one of :data:`RELABELLING`), or none when ``her`` is off."""
    if relabel not in RELABELLINGS:
        raise ValueError(f"relabel must be one of {RELABELLING}, got {relabel!r}")
    if not her:
        return Relabelling()
    return SampledRelabelling(final, random) if relabel == "all" else RELABELLINGS[relabel]()


# ================================================================= batch extras
class Sampled(NamedTuple):
    """A batch's transitions as :meth:`EpisodeReplayBuffer.sample` drew them, for :class:`BatchExtra`."""

    index: np.ndarray  # (B,) the sampled transitions' slots
    last: np.ndarray  # (B,) the slot of each one's last step (itself, but for n-step returns)
    frames: np.ndarray  # (B, 2) frame slots: the observation and the frame the target bootstraps from
    goals: np.ndarray  # (B, goal_size) the goals the batch was relabelled to
    observations: Callable[[np.ndarray], np.ndarray]  # frame slots -> images or encoder features


class BatchExtra:
    """Something an agent's updates read beyond the transitions, added to every batch the replay samples.

    An agent asks for extras in :meth:`~tactile_braille.agents.common.Agent.replay_extras`; the shared
    buffer knows none of them by name. :meth:`add` returns the batch's new entries; ``rng`` is the
    run's generator (draw from it only where needed: the order of draws is part of a run).
    """

    keeps_remaining: ClassVar[bool] = False
    """Whether it reads each transition's ``remaining`` steps (checkpoints then keep them)."""

    def check(self, action_shape: tuple[int, ...]) -> None:
        """Refuse a buffer it cannot serve (a ``ValueError``), before the buffer is made."""

    def add(
        self, buffer: EpisodeReplayBuffer, sampled: Sampled, rng: np.random.Generator
    ) -> dict[str, np.ndarray]:
        raise NotImplementedError


class GoalOutcomes(BatchExtra):
    """For updates on every goal: each transition's pressed key (``achieved``, a goal index, -1 for none)
    and how likely the relabelling gives it each goal (``goal_weights``, (B, goal_size))."""

    def add(self, buffer, sampled, rng):
        index = sampled.index
        return {
            "achieved": buffer.achieved[sampled.last].astype(np.int64),
            "goal_weights": buffer.relabelling.goal_weights(buffer.goals[index], buffer.finals[index]),
        }


class ReturnBounds(BatchExtra):
    """``return_bounds``: the discounted return each sampled transition's own episode went on to get under
    the batch goal, ``gamma ** k`` where the episode pressed that goal key ``k`` steps after it, else 0
    (a lower bound of the optimal value where moves are deterministic).

    Args:
        gamma: the agent's discount, in [0, 1].
        after: the bounds are 0 until the buffer holds this many transitions.
    """

    keeps_remaining = True

    def __init__(self, gamma: float, after: int = 0) -> None:
        if gamma is None or not 0 <= gamma <= 1:
            raise ValueError(f"return bounds need the agent's discount gamma in [0, 1], got {gamma}")
        self.gamma, self.after = float(gamma), int(after)

    def add(self, buffer, sampled, rng):
        goals, index = sampled.goals, sampled.index
        goal = np.where(goals.any(-1), goals.argmax(-1), -1)
        pressed = (buffer.finals[index] == goal) & (goal >= 0) & (buffer.size >= self.after)
        bounds = np.where(pressed, np.float32(self.gamma) ** buffer.remaining[index], 0.0)
        return {"return_bounds": bounds.astype(np.float32)}


class PressFrames(BatchExtra):
    """``press_images``: as many frames a press was made from as the batch has transitions, drawn
    uniformly among the stored transitions that pressed a task key, and ``press_keys``, the key each
    pressed (its achieved goal, int64); none before the first press. Discrete actions only: there a
    press does not move, so its frame shows the key."""

    def check(self, action_shape):
        if action_shape != ():
            raise ValueError(
                "press frames label the frame a press was made from with its key, which holds for "
                f"discrete actions (a press does not move), not actions of shape {action_shape}"
            )

    def add(self, buffer, sampled, rng):
        presses = np.flatnonzero(buffer.achieved[: buffer.size] >= 0)
        if len(presses) == 0:
            empty = sampled.observations(np.zeros(0, dtype=np.int64))
            return {"press_images": empty, "press_keys": np.zeros(0, dtype=np.int64)}
        index = presses[rng.integers(len(presses), size=len(sampled.index))]
        return {
            "press_images": sampled.observations(buffer.frame_index[index, 0]),
            "press_keys": buffer.achieved[index].astype(np.int64),
        }


class SensorPoses(BatchExtra):
    """``poses`` and ``next_poses``: the labelled sensor poses (x, y, depth in mm) of both frames, for
    asymmetric critics (every sampled frame must be labelled)."""

    def add(self, buffer, sampled, rng):
        poses = buffer.store.labels[sampled.frames, :3]  # (B, 2, 3)
        if np.isnan(poses).any():
            raise RuntimeError("SensorPoses needs labelled frames, but a sampled frame has no labels")
        return {"poses": poses[:, 0], "next_poses": poses[:, 1]}


class EpisodeSteps(BatchExtra):
    """Adds nothing to batches; its checkpoints keep each transition's ``remaining`` steps, for an agent
    that reads the replay's episodes itself (the key-graph planner) and needs them after a resume."""

    keeps_remaining = True

    def add(self, buffer, sampled, rng):
        return {}


class SubTrajectories(BatchExtra):
    """The ``horizon`` steps of its episode that start at each sampled transition (the transition
    itself first), under the batch's goals, for agents that unroll a model or build their own
    multi-step returns: ``horizon_actions`` (B, H, ...), ``horizon_rewards``, ``horizon_dones`` and
    ``horizon_valid`` (B, H) float32, ``horizon_next_images`` (B, H, C, 100, 100) (or features) and
    ``horizon_next_previous_actions`` (B, H, n): step ``j``'s action, reward, end, next frame and
    next previous action. ``horizon_valid`` is 0 for the steps past the episode's last (their
    entries are another episode's and must be masked out).

    Args:
        horizon: steps per sub-trajectory, at least 1.
    """

    keeps_remaining = True

    def __init__(self, horizon: int) -> None:
        if isinstance(horizon, bool) or not isinstance(horizon, int) or horizon < 1:
            raise ValueError(f"a sub-trajectory's horizon must be a whole number >= 1, got {horizon!r}")
        self.horizon = horizon

    def add(self, buffer, sampled, rng):
        if buffer.shift:
            raise ValueError(
                f"sub-trajectories' frames are not shifted by the replay (shift={buffer.shift}): an agent "
                "that reads them shifts every image of its batches itself"
            )
        index, goals = sampled.index, sampled.goals
        offsets = np.arange(self.horizon)
        steps = (index[:, None] + offsets) % buffer.capacity  # (B, H)
        valid = buffer.remaining[index].astype(np.int64)[:, None] >= offsets
        flat = steps.reshape(-1)
        rewards = buffer.relabelling.rewards(
            np.repeat(goals, self.horizon, axis=0), buffer.rewards[flat], buffer.achieved[flat]
        )
        next_frames = sampled.observations(buffer.frame_index[flat, 1])
        batch = len(index)
        return {
            "horizon_actions": buffer.actions[steps],
            "horizon_rewards": (rewards.reshape(batch, self.horizon) * valid).astype(np.float32),
            "horizon_dones": (buffer.dones[steps] * valid).astype(np.float32),
            "horizon_valid": valid.astype(np.float32),
            "horizon_next_images": next_frames.reshape(batch, self.horizon, *next_frames.shape[1:]),
            "horizon_next_previous_actions": buffer.previous_actions[steps, 1],
        }


# ================================================================= the buffer
def random_shift(images: np.ndarray, pixels: int, rng: np.random.Generator) -> np.ndarray:
    """Each of the (B, C, H, W) ``images`` moved by its own whole number of pixels in
    [-``pixels``, ``pixels``] along each axis, the edge pixels repeated into the space it leaves
    (DrQ's pad-and-crop)."""
    batch, _, height, width = images.shape
    padded = np.pad(images, ((0, 0), (0, 0), (pixels, pixels), (pixels, pixels)), mode="edge")
    rows, columns = rng.integers(0, 2 * pixels + 1, size=(2, batch))
    return np.stack(
        [
            padded[i, :, r : r + height, c : c + width]
            for i, (r, c) in enumerate(zip(rows, columns, strict=True))
        ]
    )


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
        relabel_final: with ``"all"``, the probability that a sampled transition takes its
            episode's pressed key as its goal.
        relabel_random: with ``"all"``, the probability that it takes a uniformly random goal.
        observation_shape: ``(H, W, 1)`` for binary images (bit-packed; ``(100, 100, 1)``
            by default), ``(n,)`` for feature vectors.
        n_step: steps of an episode a sampled transition's return spans (1: one-step
            transitions, the paper's); above 1 its rewards are discounted by ``gamma``.
        gamma: the agent's discount, needed where ``n_step`` > 1.
        shift: sampled images moved by up to this many pixels (:func:`random_shift`; 0: none).
        extras: what the agent's updates read beyond the transitions (:class:`BatchExtra`, from the
            agent's :meth:`~tactile_braille.agents.common.Agent.replay_extras`), added to each batch
            in this order.
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
        n_step: int = 1,
        gamma: float | None = None,
        shift: int = 0,
        extras: tuple[BatchExtra, ...] = (),
    ) -> None:
        for extra in extras:
            if not isinstance(extra, BatchExtra):
                raise TypeError(f"extras must be BatchExtra instances, got {type(extra).__name__}")
            extra.check(action_shape)
        if shift < 0:
            raise ValueError(f"shift is a number of pixels, at least 0, got {shift}")
        if n_step < 1:
            raise ValueError(f"n_step must be at least 1, got {n_step}")
        if n_step > 1 and (gamma is None or not 0 <= gamma <= 1):
            raise ValueError(f"n-step returns (n_step={n_step}) need the agent's discount gamma in [0, 1], "
                             f"got {gamma}")  # fmt: skip
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
        self.capacity = int(capacity)
        self.extras = tuple(extras)
        self.n_step, self.gamma = int(n_step), gamma
        self.shift = int(shift)
        self.her = her
        self.relabel = relabel
        self.relabel_final, self.relabel_random = float(relabel_final), float(relabel_random)
        self.relabelling = make_relabelling(relabel, her, relabel_final, relabel_random)
        self.goal_size = int(goal_size)
        self.max_episode_steps = int(max_episode_steps)
        # Committed transitions use at most 2 frames each; the episode in progress adds its own.
        self.store = FrameStore(2 * self.capacity + self.max_episode_steps + 1, observation_shape)
        self.cache = FeatureCache(self.store)
        # The transitions.
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
        self.remaining = np.zeros(self.capacity, dtype=np.int16)  # steps after it in its episode
        self.next_slot = 0
        self.size = 0
        # The episode in progress.
        self._episode: list[Step] = []
        self._current_frame = -1
        self._current_previous_action: np.ndarray | None = None

    # the frame store's and the cache's state, under the names the buffer always had
    @property
    def images(self) -> bool:
        """Whether observations are images (else feature vectors)."""
        return self.store.images

    @property
    def frames(self) -> np.ndarray:
        """The frame ring: packed images (frame_capacity, bytes) uint8, or vectors (frame_capacity, n)."""
        return self.store.frames

    @property
    def frame_labels(self) -> np.ndarray:
        """Labels of the frames (frame_capacity, FRAME_LABELS) float32, NaN where unknown."""
        return self.store.labels

    @property
    def frame_capacity(self) -> int:
        return self.store.capacity

    @property
    def next_frame(self) -> int:
        return self.store.next_frame

    @property
    def frames_written(self) -> int:
        return self.store.frames_written

    @property
    def features(self) -> np.ndarray | None:
        """The encoder's features of the frames, None without an encoder (batches then hold images)."""
        return self.cache.features

    @features.setter
    def features(self, features: np.ndarray | None) -> None:
        # A new cache, not a change to the shared one: a shallow copy of the buffer set to sample
        # images (``copy.copy(buffer).features = None``) leaves the original's cache alone.
        cache = FeatureCache(self.store)
        if features is not None:
            cache.features, cache.encode = features, self.cache.encode
        self.cache = cache

    # --------------------------------------------------------- writing
    def _store_frame(self, image: np.ndarray, label: np.ndarray | None = None) -> int:
        slot = self.store.store(image, label)
        self.cache.add(slot)
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
            Step(
                frames=(self._current_frame, next_frame),
                previous=(self._current_previous_action, next_previous),
                goal=np.asarray(next_observation["desired_goal"], dtype=np.float32),
                action=action,
                reward=float(reward),
                done=float(terminated),
                achieved=np.asarray(next_observation["achieved_goal"], dtype=np.float32),
            )
        )
        self._current_frame, self._current_previous_action = next_frame, next_previous

    def end_episode(self) -> None:
        """Commit the episode's transitions, and those its relabelling adds (the paper's HER)."""
        final = _goal_index(self._episode[-1].achieved) if self._episode else -1
        last = len(self._episode) - 1
        for i, step in enumerate(self._episode):
            self._add(step, step.goal, step.reward, final, last - i)
        for i, (step, goal, reward) in enumerate(self.relabelling.episode_end(self._episode)):
            self._add(step, goal, reward, final, last - i)  # a copy of the whole episode
        self._episode = []
        self._current_frame = -1
        self.store.commit()

    def _add(self, step: Step, goal: np.ndarray, reward: float, final: int, remaining: int) -> None:
        slot = self.next_slot
        self.achieved[slot] = _goal_index(step.achieved)
        self.finals[slot] = final
        self.remaining[slot] = remaining
        self.frame_index[slot] = step.frames
        self.previous_actions[slot, 0] = step.previous[0]
        self.previous_actions[slot, 1] = step.previous[1]
        self.goals[slot] = goal
        self.actions[slot] = step.action
        self.rewards[slot] = reward
        self.dones[slot] = step.done
        self.next_slot = (self.next_slot + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)

    # --------------------------------------------------------- reading
    def sample(
        self, batch_size: int, rng: np.random.Generator, index: np.ndarray | None = None
    ) -> dict[str, np.ndarray]:
        """A uniform batch of transitions (images as (B, C, H, W) uint8, or features (B, n)); ``index``:
        the transitions' slots, drawn by the caller (a prioritised replay), in place of uniform ones."""
        if self.size == 0:
            raise RuntimeError("the replay buffer is empty")
        if index is None:
            index = rng.integers(self.size, size=batch_size)
        else:
            index = np.asarray(index, dtype=np.int64)
            if index.shape != (batch_size,) or index.min() < 0 or index.max() >= self.size:
                raise ValueError(
                    f"index must hold {batch_size} slots in [0, {self.size}), got shape {index.shape}"
                    + (f" in [{index.min()}, {index.max()}]" if index.size else "")
                )
        goals, rewards = self.relabelling.sampled(
            self.goals[index], self.rewards[index], self.achieved[index], self.finals[index], rng
        )
        last = index  # the transition whose next frame the target bootstraps from
        if self.n_step > 1:
            rewards, last, steps = self._n_step_returns(index, goals, rewards)
        frames = np.stack([self.frame_index[index, 0], self.frame_index[last, 1]], axis=1)
        observations = self.store.observations if self.cache.features is None else self.cache.lookup
        batch = {
            "images": observations(frames[:, 0]),
            "previous_actions": self.previous_actions[index, 0],
            "goals": goals,
            "actions": self.actions[index],
            "rewards": rewards,
            "next_images": observations(frames[:, 1]),
            "next_previous_actions": self.previous_actions[last, 1],
            "dones": self.dones[last],
        }
        if self.n_step > 1:
            batch["steps"] = steps
        sampled = Sampled(index, last, frames, goals, observations)
        for extra in self.extras:
            batch.update(extra.add(self, sampled, rng))
        if self.shift:
            if self.cache.features is not None:
                raise RuntimeError(f"shift={self.shift} moves images, but this replay serves features")
            batch["images"] = random_shift(batch["images"], self.shift, rng)
            batch["next_images"] = random_shift(batch["next_images"], self.shift, rng)
        return batch

    def _n_step_returns(
        self, index: np.ndarray, goals: np.ndarray, rewards: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Returns over up to ``n_step`` steps of each sampled transition's episode, under its batch
        goal; the index of each window's last transition; and the steps each spans (float32).

        An episode's transitions (and each relabelled copy of it) lie one after another in the ring,
        newer than their first, so a window's later transitions are still stored."""
        span = np.minimum(self.remaining[index].astype(np.int64), self.n_step - 1)
        returns = rewards.astype(np.float32).copy()
        for j in range(1, self.n_step):
            within = span >= j
            if not within.any():
                break
            later = (index[within] + j) % self.capacity
            reward = self.relabelling.rewards(goals[within], self.rewards[later], self.achieved[later])
            returns[within] += np.float32(self.gamma**j) * reward
        return returns, (index + span) % self.capacity, (span + 1).astype(np.float32)

    def set_encoder(self, encode: Encoder, size: int, batch_size: int = 1024) -> None:
        """From now on, batches hold ``encode``'s features of the stored images (recomputed now).

        ``encode`` takes (B, 1, H, W) uint8 images and their frames' labels (B, FRAME_LABELS; NaN
        where unlabelled) and returns (B, size) float32 features. Call it again after the encoder
        changed.
        """
        self.cache.set(encode, size, batch_size)

    def labelled_frames(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Images (N, 1, H, W), poses (N, 3), pressed and under-sensor keys (N,) of labelled frames."""
        return self.store.labelled()

    def frame_pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The steps so far (the episode in progress too) as consecutive frames, from what their
        observations carry alone.

        Returns the frames (N, 1, H, W) the steps use, each once; the steps' (this, next) indices
        into them (M, 2); the next frame's previous action (M, previous_action_size), i.e. the action
        as the environment applied it; and the key its achieved goal names (M,; -1 none). With the
        paper's relabelling, a relabelled copy of a step appears again.
        """
        if not self.images:
            raise ValueError("this buffer holds features, not images")
        going = self._episode
        ongoing = np.array([step.frames for step in going], dtype=np.int64).reshape(-1, 2)
        unique, pairs = np.unique(
            np.concatenate([self.frame_index[: self.size], ongoing]), return_inverse=True
        )
        previous = [self.previous_actions[: self.size, 1], *(step.previous[1][None] for step in going)]
        achieved = [self.achieved[: self.size], [_goal_index(step.achieved) for step in going]]
        return (
            self.store.observations(unique),
            pairs.reshape(-1, 2),
            np.concatenate(previous).astype(np.float32),
            np.concatenate(achieved).astype(np.int64),
        )

    # ------------------------------------------------------ checkpoints
    _TRANSITIONS = (
        "frame_index", "previous_actions", "goals", "actions", "rewards", "dones", "achieved", "finals",
    )  # fmt: skip
    _ADDED_LATER: ClassVar[dict[str, int]] = {"achieved": -1, "finals": -1, "remaining": 0}
    """Transition arrays that older buffers lack, and their fill value (no key known; no step after it:
    one-step returns, always valid); older buffers' frames have no labels."""

    @property
    def _saved(self) -> tuple[str, ...]:
        """The transition arrays a checkpoint holds: ``remaining`` only where n-step returns or an extra
        (:attr:`BatchExtra.keeps_remaining`) read it, so that other buffers write the files they always
        wrote."""
        keeps = self.n_step > 1 or any(extra.keeps_remaining for extra in self.extras)
        return self._TRANSITIONS + (("remaining",) if keeps else ())

    def save(self, path: str | Path) -> None:
        """Write the used part of the buffer (committed transitions) atomically as ``.npz``.

        The frames of an episode in progress are left out (the counters are
        those after the last committed episode), so a resumed run has the
        whole slack of the frame ring for its next episode.
        """
        (next_frame, frames_written), frames = self.store.checkpoint()
        transitions = {name: getattr(self, name)[: self.size] for name in self._saved}
        with atomic_path(path, fsync=True) as temporary, open(temporary, "wb") as handle:
            np.savez(
                handle,
                counters=np.array([next_frame, frames_written, self.next_slot, self.size]),
                frame_capacity=np.array(self.store.capacity),
                **frames,
                **transitions,
            )

    def load(self, path: str | Path) -> None:
        """Restore a buffer written by :meth:`save` (same capacity and sizes)."""
        with np.load(path) as data:
            # Check everything before changing anything.
            frames = self.store.read_checkpoint(data, path)
            counters = [int(v) for v in data["counters"]]
            size = counters[3]
            transitions = {
                name: data[name] if name in data else np.full(size, self._ADDED_LATER[name], dtype=np.int16)
                for name in (*self._TRANSITIONS, "remaining")
            }
            for name, array in transitions.items():
                mine = getattr(self, name)
                if array.shape[1:] != mine.shape[1:] or len(array) > len(mine):
                    raise ValueError(f"{path}: {name} of shape {array.shape} does not fit {mine.shape}")
            self.store.restore(frames, counters[0], counters[1])
            for name, array in transitions.items():
                getattr(self, name)[: len(array)] = array
            self.next_slot, self.size = counters[2], counters[3]
        self._episode = []
        self._current_frame = -1
        if self.cache.encode is not None:
            self.set_encoder(self.cache.encode, self.cache.features.shape[1])
