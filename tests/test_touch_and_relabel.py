"""Relabelling when sampling, frame labels and the encoder's feature cache, the touch encoder and
touch-encoder training runs.

The replay tests build buffers by hand from episodes whose every transition
carries a unique action id, so each sampled transition can be traced back to
its episode, and whose frames (and labels) are kept as they were handed in.
The training tests run tiny real trainings on the small test datasets (one
torch thread, a few dozen steps, a few passes of the encoder's fit).
"""

from __future__ import annotations

import copy
import dataclasses
import importlib
import inspect
import io
import json
import shutil
from typing import ClassVar, NamedTuple

import gymnasium as gym
import numpy as np
import pytest
import torch

from tactile_braille.agents import (
    AGENTS,
    DQNAgent,
    DQNConfig,
    EpisodeReplayBuffer,
    TrainConfig,
    read_progress,
)
from tactile_braille.agents.common import observation_features
from tactile_braille.agents.extensions import touch_fit_steps
from tactile_braille.agents.replay import FRAME_LABELS, PACKED_BYTES
from tactile_braille.agents.report import evaluate_run, load_run
from tactile_braille.agents.touch import TouchAgent, feature_space
from tactile_braille.evaluation.protocol import evaluate_typing
from tactile_braille.keyboard.layout import ALPHABET_KEYS, ARROW_KEYS, KeyboardLayout
from tactile_braille.supervised.touch import (
    KeyLocator,
    LabelledTaps,
    TouchEncoder,
    TouchEncoderConfig,
    fit_touch_encoder,
)

# ``tactile_braille.agents.training`` the function shadows the module of the same name: use the registry.
train_module = importlib.import_module("tactile_braille.agents.training")
extensions_module = importlib.import_module("tactile_braille.agents.extensions")

DISCRETE_TASK = "tactile_braille/DiscreteArrows-v0"
CONTINUOUS_TASK = "tactile_braille/ContinuousArrows-v0"
GOALS = 4
PREVIOUS = 5
FEATURES = 6
OTHER, TIMEOUT = "other", "timeout"
EPISODES = (  # (goal, steps, how it ends: a task key pressed, a press of a key outside the task, a time-out)
    (0, 3, 0),  # right press
    (1, 2, 3),  # wrong press of key 3
    (2, 4, OTHER),
    (3, 3, TIMEOUT),
    (0, 1, 2),  # one-step wrong press of key 2
    (2, 2, 2),  # right press
)
STEPS = sum(steps for _, steps, _ in EPISODES)
FRAMES = STEPS + len(EPISODES)  # each episode's first observation and one per step
WRONG_PRESS_STEPS = sum(steps for goal, steps, end in EPISODES if isinstance(end, int) and end != goal)


pytestmark = pytest.mark.usefixtures("one_torch_thread")


# ---------------------------------------------------------------- replay helpers
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


class Labels:
    """Distinct frame labels in order, kept in ``given``; every ``unlabelled``-th frame has none."""

    def __init__(self, unlabelled: int = 0) -> None:
        self.unlabelled = unlabelled
        self.given: list[np.ndarray | None] = []

    def __call__(self) -> np.ndarray | None:
        n = len(self.given)
        if self.unlabelled and n % self.unlabelled == self.unlabelled - 1:
            label = None
        else:  # pose (n, -n/2, n/10) mm; keys cycle through -1..3, out of step with each other
            label = LabelledTaps.label([n, -n / 2, n / 10], n % (GOALS + 1) - 1, (n + 2) % (GOALS + 1) - 1)
        self.given.append(label)
        return label

    def table(self) -> np.ndarray:
        """The labels given, NaN rows where none was (as the replay stores them)."""
        unknown = np.full(FRAME_LABELS, np.nan, np.float32)
        return np.stack([unknown if label is None else label for label in self.given])


def fill(
    buffer: EpisodeReplayBuffer, frames: Frames, episodes=EPISODES, first_id: int = 0, labels=None
) -> dict[int, dict]:
    """Record ``episodes`` (frames labelled by ``labels``, if given); returns, by action id, each
    transition's pressed key, final key and goal."""
    table, action = {}, first_id
    label = labels or (lambda: None)
    for goal, steps, end in episodes:
        buffer.start_episode(replay_observation(frames(), goal), label())
        final = end if isinstance(end, int) else -1
        for step in range(steps):
            last = step == steps - 1
            achieved = end if last and isinstance(end, int) else None
            terminated = last and end != TIMEOUT
            reward = float(achieved == goal)
            buffer.add_step(action, reward, replay_observation(frames(), goal, achieved), terminated, label())
            table[action] = {
                "achieved": -1 if achieved is None else achieved, "final": final, "goal": goal,
                "last": last, "terminal": terminated, "end": end,
            }  # fmt: skip
            action += 1
        buffer.end_episode()
    return table


def goal_indices(goals: np.ndarray) -> np.ndarray:
    """Indices of sampled goal one-hots (every sampled goal must be exactly one key)."""
    assert ((goals == 0) | (goals == 1)).all() and (goals.sum(-1) == 1).all()
    return goals.argmax(-1)


def all_buffer(**kwargs) -> EpisodeReplayBuffer:
    return EpisodeReplayBuffer(100, GOALS, (), PREVIOUS, max_episode_steps=10, relabel="all", **kwargs)


def as_images(frames: list[np.ndarray]) -> np.ndarray:
    """(100, 100, 1) images as a (N, 1, 100, 100) batch."""
    return np.moveaxis(np.stack(frames), -1, 1)


def unpack(packed: np.ndarray) -> np.ndarray:
    """Bit-packed frames of a replay file as (N, 1, 100, 100) uint8 images."""
    return (np.unpackbits(packed, axis=-1).reshape(-1, 1, 100, 100) * 255).astype(np.uint8)


# ---------------------------------------------------------------- relabel="all"
def test_all_rewards_follow_the_pressed_key_and_the_sampled_goal():
    buffer = all_buffer()
    table = fill(buffer, Frames())
    batch = buffer.sample(3000, np.random.default_rng(0))
    goals = goal_indices(batch["goals"])
    ids = batch["actions"]
    achieved = np.array([table[i]["achieved"] for i in ids])
    np.testing.assert_array_equal(batch["rewards"], (achieved == goals).astype(np.float32))
    terminal = np.array([table[i]["terminal"] for i in ids])
    np.testing.assert_array_equal(batch["dones"], terminal.astype(np.float32))
    assert (batch["rewards"][~terminal] == 0).all()
    assert batch["rewards"].sum() > 0  # the rule was exercised on presses too
    # The wrong press of key 3 for goal 1 is seen with its goal, with its pressed key, and with others.
    wrong = np.array([table[i]["goal"] == 1 for i in ids])
    assert set(goals[wrong].tolist()) == {0, 1, 2, 3}
    # A goal is kept with probability 0.2, plus 0.4 where the final key is the goal or none (12 of the
    # 15 transitions), plus 0.4 x 1/4 from random goals.
    stored = np.array([table[i]["goal"] for i in ids])
    assert abs(np.mean(goals == stored) - (0.2 + 0.4 * 12 / 15 + 0.4 / 4)) < 0.05


def test_final_relabelling_gives_each_press_episode_its_pressed_key():
    buffer = all_buffer(relabel_final=1.0, relabel_random=0.0)
    table = fill(buffer, Frames())
    batch = buffer.sample(2000, np.random.default_rng(1))
    goals = goal_indices(batch["goals"])
    assert set(batch["actions"].tolist()) == set(table)  # every transition was sampled
    for transition, goal, reward in zip(batch["actions"], goals, batch["rewards"], strict=True):
        row = table[transition]
        if row["final"] >= 0:
            assert goal == row["final"]
            assert reward == float(row["last"])
        else:  # a press of a key outside the task or a time-out: nothing to relabel to, the goal stays
            assert goal == row["goal"]
            assert reward == 0.0


def test_episodes_without_a_task_key_press_have_no_final_key():
    buffer = all_buffer()
    table = fill(buffer, Frames())
    ids = buffer.actions[: buffer.size].tolist()
    finals = dict(zip(ids, buffer.finals[: buffer.size].tolist(), strict=True))
    achieved = dict(zip(ids, buffer.achieved[: buffer.size].tolist(), strict=True))
    assert finals == {i: row["final"] for i, row in table.items()}
    assert achieved == {i: row["achieved"] for i, row in table.items()}
    no_key = [i for i, row in table.items() if row["end"] in (OTHER, TIMEOUT)]
    assert len(no_key) == 4 + 3
    assert all(finals[i] == -1 and achieved[i] == -1 for i in no_key)


def test_random_relabelling_spreads_the_goals_over_every_key():
    buffer = all_buffer(relabel_final=0.0, relabel_random=1.0)
    table = fill(buffer, Frames())
    batch = buffer.sample(4000, np.random.default_rng(2))
    goals = goal_indices(batch["goals"])
    shares = np.bincount(goals, minlength=GOALS) / len(goals)
    assert np.all(np.abs(shares - 1 / GOALS) < 0.05), shares
    achieved = np.array([table[i]["achieved"] for i in batch["actions"]])
    np.testing.assert_array_equal(batch["rewards"], (achieved == goals).astype(np.float32))
    # Even a time-out's transitions are given every goal.
    timeout = np.array([table[i]["goal"] == 3 and table[i]["final"] == -1 for i in batch["actions"]])
    assert set(goals[timeout].tolist()) == set(range(GOALS))


def test_paper_mode_stores_copies_of_wrong_presses_and_all_mode_none():
    paper = EpisodeReplayBuffer(100, GOALS, (), PREVIOUS, max_episode_steps=10, relabel="paper")
    fill(paper, Frames())
    everything = all_buffer()
    fill(everything, Frames())
    assert WRONG_PRESS_STEPS == 3
    assert paper.size == STEPS + WRONG_PRESS_STEPS
    assert everything.size == STEPS
    # The paper's copies keep the stored rewards: 1 at the last step of each relabelled episode.
    assert paper.rewards[: paper.size].sum() == 2 + 2  # two right presses, two relabelled wrong presses
    assert everything.rewards[: everything.size].sum() == 2


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"relabel": "future"}, "relabel must be one of"),
        ({"relabel_final": -0.1}, "probabilities"),
        ({"relabel_random": -0.1}, "probabilities"),
        ({"relabel_final": 0.6, "relabel_random": 0.5}, "probabilities"),
        ({"relabel_final": float("nan")}, "probabilities"),
        ({"observation_shape": (10, 10)}, "images or vectors"),
        ({"observation_shape": (100, 100)}, "images or vectors"),
        ({"observation_shape": (100, 100, 3)}, "images or vectors"),
    ],
)
def test_replay_rejects_bad_arguments(kwargs, message):
    with pytest.raises(ValueError, match=message):
        EpisodeReplayBuffer(10, GOALS, (), PREVIOUS, **kwargs)


# ---------------------------------------------------------------- feature replay, save and load
def test_feature_buffer_round_trips_exactly(tmp_path):
    buffer = all_buffer(observation_shape=(FEATURES,))
    frames = Frames(features=True)
    fill(buffer, frames)
    assert buffer.frames.dtype == np.float32 and buffer.frames.shape[1] == FEATURES
    buffer.start_episode(replay_observation(frames(), 1))  # in progress: left out of the file
    buffer.save(tmp_path / "replay.npz")
    restored = all_buffer(observation_shape=(FEATURES,))
    restored.load(tmp_path / "replay.npz")
    assert (restored.size, restored.next_slot) == (buffer.size, buffer.next_slot)
    assert (restored.next_frame, restored.frames_written) == (FRAMES, FRAMES)
    written = restored.frames_written
    np.testing.assert_array_equal(restored.frames[:written], buffer.frames[:written])
    for name in (
        "frame_index",
        "previous_actions",
        "goals",
        "actions",
        "rewards",
        "dones",
        "achieved",
        "finals",
    ):
        np.testing.assert_array_equal(getattr(restored, name), getattr(buffer, name), err_msg=name)
    ours, theirs = buffer.sample(64, np.random.default_rng(3)), restored.sample(64, np.random.default_rng(3))
    for name in ours:
        np.testing.assert_array_equal(ours[name], theirs[name], err_msg=name)
    assert ours["images"].dtype == np.float32 and ours["images"].shape == (64, FEATURES)


def test_a_feature_file_does_not_load_into_an_image_buffer(tmp_path):
    features = all_buffer(observation_shape=(FEATURES,))
    fill(features, Frames(features=True))
    features.save(tmp_path / "replay.npz")
    images = all_buffer()
    with pytest.raises(ValueError, match="frames"):
        images.load(tmp_path / "replay.npz")
    assert images.size == 0 and not images.frames.any()  # nothing changed


def test_a_file_without_pressed_keys_loads_them_as_unknown(tmp_path):
    buffer = all_buffer()
    fill(buffer, Frames())
    buffer.save(tmp_path / "new.npz")
    with np.load(tmp_path / "new.npz") as data:
        old = {name: data[name] for name in data if name not in ("achieved", "finals")}
    np.savez(tmp_path / "old.npz", **old)  # as buffers wrote before they recorded the pressed keys
    restored = all_buffer()
    fill(restored, Frames(seed=1), EPISODES[::-1], first_id=100)  # known keys to be overwritten
    assert (restored.achieved[: restored.size] >= 0).any()
    restored.load(tmp_path / "old.npz")
    assert restored.size == buffer.size
    assert (restored.achieved[: restored.size] == -1).all()
    assert (restored.finals[: restored.size] == -1).all()
    for name in ("goals", "rewards", "actions", "frame_index"):
        np.testing.assert_array_equal(getattr(restored, name), getattr(buffer, name), err_msg=name)


# ---------------------------------------------------------------- the encoder's feature cache
PROJECTION = np.random.default_rng(7).normal(size=(100 * 100, FEATURES)).astype(np.float32)


def encode(images: np.ndarray) -> np.ndarray:
    """A fixed random projection of (B, 1, 100, 100) uint8 images (one row at a time: exact per image)."""
    assert images.dtype == np.uint8 and images.shape[1:] == (1, 100, 100)
    flat = images.reshape(len(images), -1).astype(np.float32) / 255.0
    return np.stack([row @ PROJECTION for row in flat]).reshape(len(images), FEATURES)


class ScaledEncoder:
    """:func:`encode` times ``scale``, counting the images of each call; changing ``scale`` is a refit."""

    def __init__(self, scale: float = 1.0) -> None:
        self.scale, self.calls = scale, []

    def __call__(self, images: np.ndarray) -> np.ndarray:
        self.calls.append(len(images))
        return self.scale * encode(images)


def test_set_encoder_caches_the_features_of_every_frame_and_the_episode_in_progress():
    buffer = all_buffer()
    frames = Frames()
    table = fill(buffer, frames)
    buffer.start_episode(replay_observation(frames(), 1))
    buffer.add_step(50, 0.0, replay_observation(frames(), 1), terminated=False)
    start, middle = frames.given[-2:]
    original = copy.deepcopy(buffer)
    encoder = ScaledEncoder()
    buffer.set_encoder(encoder, FEATURES, batch_size=7)
    assert sum(encoder.calls) == len(frames.given) == FRAMES + 2 and max(encoder.calls) == 7
    np.testing.assert_allclose(buffer.features[: FRAMES + 2], encode(as_images(frames.given)), atol=1e-6)
    # The buffer keeps its packed images; batches hold the features of the images they would have held.
    assert buffer.images and buffer.frames.dtype == np.uint8
    np.testing.assert_array_equal(buffer.frames, original.frames)
    ours, theirs = (
        buffer.sample(200, np.random.default_rng(4)),
        original.sample(200, np.random.default_rng(4)),
    )
    assert ours["images"].shape == (200, FEATURES) and ours["images"].dtype == np.float32
    np.testing.assert_allclose(ours["images"], encode(theirs["images"]), atol=1e-6)
    np.testing.assert_allclose(ours["next_images"], encode(theirs["next_images"]), atol=1e-6)
    for name in ("goals", "actions", "rewards", "dones", "previous_actions", "next_previous_actions"):
        np.testing.assert_array_equal(ours[name], theirs[name], err_msg=name)

    # Frames stored from now on are encoded as they are stored: the episode in progress ends in a press.
    encoder.calls.clear()
    last = frames()
    buffer.add_step(51, 1.0, replay_observation(last, 1, achieved=1), terminated=True)
    assert encoder.calls == [1]
    buffer.end_episode()
    assert buffer.size == STEPS + 2
    batch = buffer.sample(2000, np.random.default_rng(5))
    assert set(batch["actions"].tolist()) == {*table, 50, 51}
    first = batch["actions"] == 50
    second = batch["actions"] == 51
    for rows, name, image in (
        (first, "images", start),
        (first, "next_images", middle),
        (second, "images", middle),
        (second, "next_images", last),
    ):
        assert rows.any()
        expected = encode(as_images([image]))
        np.testing.assert_allclose(batch[name][rows], np.repeat(expected, rows.sum(), 0), atol=1e-6)
    goals = goal_indices(batch["goals"])
    np.testing.assert_array_equal(batch["rewards"][second], (goals[second] == 1).astype(np.float32))
    assert (batch["rewards"][first] == 0).all()


def test_set_encoder_again_recomputes_the_cache_after_a_refit():
    buffer = all_buffer()
    frames = Frames()
    fill(buffer, frames)
    encoder = ScaledEncoder()
    buffer.set_encoder(encoder, FEATURES)
    encoder.scale = 3.0  # refitted in place, as the training loop refits the agent's encoder
    np.testing.assert_allclose(buffer.features[:FRAMES], encode(as_images(frames.given)), atol=1e-6)
    buffer.set_encoder(encoder, FEATURES)
    np.testing.assert_allclose(buffer.features[:FRAMES], 3.0 * encode(as_images(frames.given)), atol=1e-5)
    buffer.start_episode(replay_observation(frames(), 0))  # a frame stored after the refit
    np.testing.assert_allclose(
        buffer.features[FRAMES], 3.0 * encode(as_images(frames.given[-1:]))[0], atol=1e-5
    )

    # Another encoder, of another size, takes over.
    def wider(images):
        return np.concatenate([encode(images), np.ones((len(images), 1), np.float32)], axis=1)

    buffer.set_encoder(wider, FEATURES + 1)
    assert buffer.sample(10, np.random.default_rng(6))["images"].shape == (10, FEATURES + 1)
    np.testing.assert_allclose(buffer.features[: FRAMES + 1], wider(as_images(frames.given)), atol=1e-6)


def test_set_encoder_and_labelled_frames_are_refused_for_a_buffer_of_features():
    buffer = all_buffer(observation_shape=(FEATURES,))
    frames = Frames(features=True)
    fill(buffer, frames)
    encoder = ScaledEncoder()
    with pytest.raises(ValueError, match="buffer of images"):
        buffer.set_encoder(encoder, FEATURES)
    assert buffer.features is None and not encoder.calls
    buffer.start_episode(replay_observation(frames(), 0))  # stored as given, not through the encoder
    assert not encoder.calls
    np.testing.assert_array_equal(buffer.frames[FRAMES], frames.given[-1])
    with pytest.raises(ValueError, match="features, not images"):
        buffer.labelled_frames()


def test_the_cache_is_not_saved_and_is_recomputed_on_load(tmp_path):
    buffer = all_buffer()
    frames = Frames()
    fill(buffer, frames)
    buffer.set_encoder(encode, FEATURES)
    buffer.save(tmp_path / "replay.npz")
    with np.load(tmp_path / "replay.npz") as data:
        assert "frame_labels" in data.files and not any("feature" in name for name in data.files)
        assert data["frames"].dtype == np.uint8 and data["frames"].shape == (FRAMES, PACKED_BYTES)

    restored = all_buffer()
    fill(restored, Frames(seed=1), EPISODES * 2)  # other images, to be replaced
    encoder = ScaledEncoder(scale=2.0)
    restored.set_encoder(encoder, FEATURES)
    restored.load(tmp_path / "replay.npz")
    np.testing.assert_allclose(restored.features[:FRAMES], 2.0 * encode(as_images(frames.given)), atol=1e-5)
    ours, theirs = (
        buffer.sample(64, np.random.default_rng(3)),
        restored.sample(64, np.random.default_rng(3)),
    )
    np.testing.assert_allclose(theirs["next_images"], 2.0 * ours["next_images"], atol=1e-5)
    # Without an encoder a loaded buffer samples images.
    plain = all_buffer()
    plain.load(tmp_path / "replay.npz")
    assert plain.features is None
    batch = plain.sample(64, np.random.default_rng(3))
    assert batch["images"].shape == (64, 1, 100, 100) and batch["images"].dtype == np.uint8
    np.testing.assert_allclose(ours["images"], encode(batch["images"]), atol=1e-6)


# ---------------------------------------------------------------- frame labels
def test_frame_labels_are_stored_saved_and_loaded(tmp_path):
    buffer = all_buffer()
    labels = Labels(unlabelled=4)
    fill(buffer, Frames(), labels=labels)
    expected = labels.table()
    assert np.isnan(expected).any() and not np.isnan(expected).all()
    np.testing.assert_array_equal(buffer.frame_labels[:FRAMES], expected)  # NaN where none was given
    assert np.isnan(buffer.frame_labels[FRAMES:]).all()
    buffer.start_episode(replay_observation(Frames(seed=2)(), 1), labels())  # in progress: not saved
    assert not np.isnan(buffer.frame_labels[FRAMES]).any()
    buffer.save(tmp_path / "replay.npz")

    restored = all_buffer()
    fill(restored, Frames(seed=1), EPISODES * 2, labels=Labels())  # more labelled frames, to be replaced
    restored.load(tmp_path / "replay.npz")
    assert restored.frame_labels.dtype == np.float32 and restored.frame_labels.shape[1] == FRAME_LABELS
    np.testing.assert_array_equal(restored.frame_labels[:FRAMES], expected)
    assert np.isnan(restored.frame_labels[FRAMES:]).all()
    np.testing.assert_array_equal(restored.labelled_frames()[1], buffer.labelled_frames()[1][:-1])


def test_a_file_without_frame_labels_loads_them_as_unknown(tmp_path):
    buffer = all_buffer()
    frames = Frames()
    fill(buffer, frames, labels=Labels())
    buffer.save(tmp_path / "new.npz")
    with np.load(tmp_path / "new.npz") as data:
        old = {name: data[name] for name in data if name != "frame_labels"}
    np.savez(tmp_path / "old.npz", **old)  # as buffers wrote before frames had labels
    restored = all_buffer()
    fill(restored, Frames(seed=1), labels=Labels())  # labels to be forgotten
    restored.load(tmp_path / "old.npz")
    assert np.isnan(restored.frame_labels).all()
    images, poses, pressed, under = restored.labelled_frames()
    assert images.shape == (0, 1, 100, 100) and poses.shape == (0, 3) and len(pressed) == len(under) == 0
    np.testing.assert_array_equal(restored.frames[:FRAMES], buffer.frames[:FRAMES])
    np.testing.assert_array_equal(restored.frame_index, buffer.frame_index)


def test_labelled_frames_hold_the_labelled_frames_and_the_episode_in_progress():
    buffer = all_buffer()
    frames, labels = Frames(), Labels(unlabelled=3)
    fill(buffer, frames, labels=labels)
    buffer.start_episode(replay_observation(frames(), 1), labels())
    buffer.add_step(50, 0.0, replay_observation(frames(), 1), False, labels())
    kept = [i for i, label in enumerate(labels.given) if label is not None]
    assert len(kept) < len(labels.given) and {FRAMES, FRAMES + 1} <= set(kept)  # in progress: labelled
    images, poses, pressed, under = buffer.labelled_frames()
    assert images.dtype == np.uint8 and poses.dtype == np.float32
    assert pressed.dtype == under.dtype == np.int64
    np.testing.assert_array_equal(images, as_images([frames.given[i] for i in kept]))
    expected = labels.table()[kept]
    np.testing.assert_array_equal(poses, expected[:, :3])
    np.testing.assert_array_equal(pressed, expected[:, 3])
    np.testing.assert_array_equal(under, expected[:, 4])
    assert {-1, 3} <= set(pressed.tolist()) and {-1, 3} <= set(under.tolist())
    # As labelled taps, for the touch encoder's fit.
    taps = LabelledTaps.from_arrays(images, poses, pressed, under)
    for ours, theirs in zip(taps.arrays(), (images, poses, pressed), strict=True):
        np.testing.assert_array_equal(ours, theirs)
    assert taps.under == under.tolist()


# ---------------------------------------------------------------- touch encoder
@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"features": 0}, "features"),
        ({"hidden": 0}, "hidden"),
        ({"epochs": 0}, "epochs"),
        ({"batch_size": 0}, "batch_size"),
        ({"learning_rate": 0.0}, "learning_rate"),
        ({"validation": 1.0}, "validation"),
        ({"validation": -0.1}, "validation"),
    ],
)
def test_touch_encoder_config_is_checked(changes, message):
    with pytest.raises(ValueError, match=message):
        TouchEncoderConfig(**changes)


def test_touch_encoder_shapes_and_image_layouts():
    torch.manual_seed(0)
    encoder = TouchEncoder(keys=3, features=8, hidden=16).eval()
    images = Frames()
    channels_last = np.stack([images() for _ in range(4)])  # (B, 100, 100, 1), as environments give them
    channels_first = np.moveaxis(channels_last, -1, 1)
    features = encoder.encode(channels_last)
    assert features.shape == (4, 8) and features.dtype == np.float32
    np.testing.assert_allclose(features, encoder.encode(channels_first), rtol=1e-5, atol=1e-6)
    assert not np.allclose(features[0], features[1])  # different taps, different features
    pose, logits = encoder(torch.as_tensor(channels_first))
    assert pose.shape == (4, 3) and logits.shape == (4, 3 + 1)  # the last class: no task key


def test_labelled_taps_from_observations_and_arrays():
    taps = LabelledTaps()
    images = Frames()
    given = [images() for _ in range(5)]

    def locate(pose_mm):  # stands in for a KeyLocator: key (x mod 4)
        return int(pose_mm[0]) % GOALS

    for image, achieved in zip(given, (None, 2, None, 0), strict=False):
        pose = np.array([1.0, -2.0, 3.0]) * (len(taps) + 1)
        taps.add_observation(
            replay_observation(image, 1, achieved),
            {"sensor_pose_mm": pose},
            locate if len(taps) % 2 else None,
        )
    taps.add(given[4][:, :, 0], np.array([9.0, 8.0, 7.0, 6.0]), pressed=3)  # a 2-D image, extra pose entries
    assert len(taps) == 5
    stacked, poses, pressed = taps.arrays()
    assert stacked.shape == (5, 1, 100, 100) and stacked.dtype == np.uint8
    np.testing.assert_array_equal(stacked, as_images(given))
    assert poses.shape == (5, 3) and poses.dtype == np.float32
    np.testing.assert_array_equal(poses[:4], np.array([1.0, -2.0, 3.0]) * np.arange(1, 5)[:, None])
    np.testing.assert_array_equal(poses[4], [9.0, 8.0, 7.0])
    assert pressed.tolist() == [-1, 2, -1, 0, 3] and pressed.dtype == np.int64
    assert taps.under == [-1, 2, -1, 0, -1]  # located at x = 2 and 4 mm; none without a locator
    again = LabelledTaps.from_arrays(stacked, poses, pressed, np.array(taps.under))
    for ours, theirs in zip(taps.arrays(), again.arrays(), strict=True):
        np.testing.assert_array_equal(ours, theirs)
        assert ours.dtype == theirs.dtype
    assert again.under == taps.under
    assert len(LabelledTaps.from_arrays(stacked[:0], poses[:0], pressed[:0], pressed[:0])) == 0


@pytest.mark.parametrize("short", ["images", "poses", "pressed", "under"])
def test_labelled_taps_refuse_arrays_that_differ_in_number(short):
    arrays = {
        "images": np.zeros((3, 1, 100, 100), np.uint8),
        "poses": np.zeros((3, 3), np.float32),
        "pressed": np.zeros(3, np.int64),
        "under": np.zeros(3, np.int64),
    }
    arrays[short] = arrays[short][:2]
    with pytest.raises(ValueError, match="differ in number"):
        LabelledTaps.from_arrays(**arrays)


def test_a_label_is_the_pose_the_pressed_key_and_the_key_under_the_sensor():
    label = LabelledTaps.label(np.array([1.5, -2.0, 3.25, 99.0]), pressed=2, under=-1)
    assert label.shape == (FRAME_LABELS,) and label.dtype == np.float32
    np.testing.assert_array_equal(label, [1.5, -2.0, 3.25, 2.0, -1.0])


SYNTHETIC_KEYS = 3


def synthetic_taps(count: int, seed: int, shuffle_labels: bool = False) -> LabelledTaps:
    """Clearly separable taps: a bright square whose place on a 6x6 grid (2 mm apart) is the pose (its
    column pair the key under the sensor), and a bar along the top whose place is the pressed key (none:
    no bar, and a shallower tap)."""
    rng = np.random.default_rng(seed)
    images, labels = [], []
    for _ in range(count):
        column, row = rng.integers(0, 6, 2)
        pressed = int(rng.integers(-1, SYNTHETIC_KEYS))
        image = np.zeros((100, 100, 1), np.uint8)
        image[20 + 10 * row : 32 + 10 * row, 20 + 10 * column : 32 + 10 * column] = 255
        if pressed >= 0:
            image[:10, 30 * pressed : 30 * pressed + 20] = 255
        images.append(image)
        labels.append(
            (np.array([2.0 * column, 2.0 * row, 3.0 if pressed >= 0 else 1.0]), pressed, column // 2)
        )
    if shuffle_labels:
        labels = [labels[i] for i in rng.permutation(count)]
    taps = LabelledTaps()
    for image, (pose, pressed, under) in zip(images, labels, strict=True):
        taps.add(image, pose, pressed, under)
    return taps


def test_fit_touch_encoder_learns_pose_and_key_of_separable_taps():
    config = TouchEncoderConfig(features=16, hidden=64, epochs=12, batch_size=16, validation=0.25)
    model, metrics = fit_touch_encoder(synthetic_taps(200, 0), SYNTHETIC_KEYS, config, seed=0)
    _, control = fit_touch_encoder(
        synthetic_taps(200, 0, shuffle_labels=True), SYNTHETIC_KEYS, config, seed=0
    )
    assert set(metrics) == {
        "touch/taps", "touch/pose_error_mm", "touch/depth_error_mm", "touch/key_accuracy",
        "touch/under_accuracy",
    }  # fmt: skip
    assert metrics["touch/taps"] == 200
    # Fitted: almost every held-out key right, the pose within a grid step. Chance is about 1 in 4 for
    # the key, and about 5 mm for the pose (the control, whose labels do not match the images).
    assert metrics["touch/key_accuracy"] >= 0.9 and metrics["touch/under_accuracy"] >= 0.9, metrics
    assert metrics["touch/pose_error_mm"] < 2.0 and metrics["touch/depth_error_mm"] < 0.5, metrics
    assert control["touch/key_accuracy"] < 0.6 and control["touch/under_accuracy"] < 0.7, control
    assert control["touch/pose_error_mm"] > 3.5, control
    assert not model.training and not any(p.requires_grad for p in model.parameters())
    assert model.features_size == 16 and model.keys == SYNTHETIC_KEYS
    assert 3.0 < float(model.pose_mean[0]) < 7.0 and float(model.pose_scale[0]) > 1.0  # labels' statistics


def test_fit_touch_encoder_refuses_too_few_taps_and_unknown_keys():
    config = TouchEncoderConfig(features=4, hidden=8, epochs=1)
    with pytest.raises(ValueError, match="at least 10"):
        fit_touch_encoder(synthetic_taps(9, 0), SYNTHETIC_KEYS, config)
    taps = synthetic_taps(12, 0)
    taps.add(np.zeros((100, 100, 1), np.uint8), np.zeros(3), pressed=SYNTHETIC_KEYS)
    with pytest.raises(ValueError, match="labelled with key 3"):
        fit_touch_encoder(taps, SYNTHETIC_KEYS, config)


def test_fit_touch_encoder_keeps_a_tap_to_train_on_whatever_the_validation_share():
    config = TouchEncoderConfig(features=4, hidden=8, epochs=1, validation=0.95)
    model, metrics = fit_touch_encoder(synthetic_taps(10, 0), SYNTHETIC_KEYS, config)
    assert np.isfinite(model.pose_mean.numpy()).all()
    assert np.isfinite(metrics["touch/pose_error_mm"])


def test_a_refit_starts_from_the_given_encoders_weights():
    config = TouchEncoderConfig(features=4, hidden=8, epochs=1)
    torch.manual_seed(0)
    first, _ = fit_touch_encoder(synthetic_taps(20, 0), SYNTHETIC_KEYS, config)
    weights = copy.deepcopy(first.state_dict())
    # So small a step that a refit barely moves: its weights are those it started from.
    still = dataclasses.replace(config, learning_rate=1e-9)
    refit, metrics = fit_touch_encoder(synthetic_taps(30, 1), SYNTHETIC_KEYS, still, seed=1, init=first)
    fresh, _ = fit_touch_encoder(synthetic_taps(30, 1), SYNTHETIC_KEYS, still, seed=1)
    parameters = dict(first.named_parameters())
    assert refit is not first and metrics["touch/taps"] == 30
    for name, parameter in refit.named_parameters():
        torch.testing.assert_close(parameter, parameters[name], rtol=0, atol=1e-6, msg=name)
    assert not all(torch.allclose(p, parameters[name], atol=1e-3) for name, p in fresh.named_parameters())
    # The pose statistics are the new taps'; the encoder it started from is left as it was, frozen.
    assert not torch.equal(refit.pose_mean, first.pose_mean)
    assert all(torch.equal(first.state_dict()[name], value) for name, value in weights.items())
    assert not any(p.requires_grad for p in first.parameters())
    assert not refit.training and not any(p.requires_grad for p in refit.parameters())


# ---------------------------------------------------------------- the key under the sensor
def test_a_key_locator_maps_each_keys_centre_to_it():
    layout = KeyboardLayout()
    for keys in (ARROW_KEYS, ALPHABET_KEYS):
        locate = KeyLocator(layout, keys)
        assert [locate((*layout.centre_mm(key), 2.0)) for key in keys] == list(range(len(keys)))


@pytest.mark.parametrize("pitch_mm", [18.0, 19.0, 20.0])
@pytest.mark.parametrize(
    ("near", "far"), [("LEFT", "DOWN"), ("DOWN", "LEFT"), ("UP", "DOWN"), ("DOWN", "UP")]
)
def test_a_point_between_two_keys_belongs_to_the_key_whose_cell_holds_it(pitch_mm, near, far):
    layout = KeyboardLayout(pitch_mm=pitch_mm)
    locate = KeyLocator(layout, ARROW_KEYS)
    a, b = np.array(layout.centre_mm(near)), np.array(layout.centre_mm(far))
    assert np.linalg.norm(b - a) == pytest.approx(pitch_mm)  # neighbours, in a row or across rows
    towards = (b - a) / pitch_mm
    edge = a + towards * pitch_mm / 2  # where the two keys' cells meet
    assert locate(edge - 0.1 * towards) == ARROW_KEYS.index(near)
    assert locate(edge + 0.1 * towards) == ARROW_KEYS.index(far)


def test_a_key_locator_finds_no_task_key_off_them():
    layout = KeyboardLayout()
    locate = KeyLocator(layout, ARROW_KEYS)
    for point in ((500.0, 500.0), (-100.0, 0.0), layout.centre_mm("END"), layout.centre_mm("Q")):
        assert locate(point) == -1, point
    up = np.array(layout.centre_mm("UP"))
    assert locate(up + np.array([-9.6, 0.0])) == -1  # ENTER, in the row above UP
    assert locate(up + np.array([0.0, 9.6])) == -1  # RIGHTSHIFT's cell


def test_space_has_a_cell_as_wide_as_its_bar():
    layout = KeyboardLayout()
    locate = KeyLocator(layout, ALPHABET_KEYS)
    space = ALPHABET_KEYS.index("SPACE")
    x, y = layout.centre_mm("SPACE")
    half_mm = 6.25 * 19.0 / 2  # 59.375 mm either side of its centre, as far as LEFTALT and RIGHTALT
    for along in (0.0, 40.0, half_mm - 0.5, -(half_mm - 0.5)):
        assert locate((x, y + along)) == space, along
        assert locate((x - 9.0, y + along)) == space, along  # just below the Z row
    assert locate((x, y + half_mm + 0.5)) == -1  # LEFTALT, not a task key
    assert locate((x, y - half_mm - 0.5)) == -1  # RIGHTALT
    assert locate((x - 10.0, y)) == ALPHABET_KEYS.index("B")  # the key above its centre


# ---------------------------------------------------------------- touch agent
@pytest.fixture(scope="module")
def discrete_env(env_datasets):
    env = gym.make(DISCRETE_TASK, dataset=env_datasets[DISCRETE_TASK])
    yield env
    env.close()


def touch_agent(env: gym.Env, seed: int) -> TouchAgent:
    torch.manual_seed(seed)
    encoder = TouchEncoder(GOALS, features=8, hidden=16)
    space = feature_space(env.observation_space, encoder.features_size)
    return TouchAgent(DQNAgent(space, env.action_space, DQNConfig(hidden=(16,))), encoder)


def test_feature_space_replaces_only_the_image(discrete_env):
    space = feature_space(discrete_env.observation_space, 8)
    assert space["observation"].shape == (8,) and space["observation"].dtype == np.float32
    assert observation_features(space) == 8
    for name in ("desired_goal", "achieved_goal", "previous_action"):
        assert space[name] == discrete_env.observation_space[name]
    assert discrete_env.observation_space["observation"].shape == (100, 100, 1)  # not changed in place


def test_touch_agent_acts_on_the_encoders_features_of_the_image(discrete_env):
    agent = touch_agent(discrete_env, 0)
    rng = np.random.default_rng(0)
    for seed in range(4):
        observation, _ = discrete_env.reset(seed=seed)
        features = agent.touch.encode(observation["observation"][None])[0]
        assert features.shape == (8,)
        expected = agent.agent.policy_action({**observation, "observation": features}, 0, False, rng, True)
        assert agent.policy_action(observation, 0, explore=False, rng=rng, deterministic=True) == expected


def through_file(state: dict) -> dict:
    buffer = io.BytesIO()
    torch.save(state, buffer)
    buffer.seek(0)
    return torch.load(buffer, weights_only=False)


def same_weights(a: torch.nn.Module, b: torch.nn.Module) -> bool:
    ours, theirs = a.state_dict(), b.state_dict()
    return ours.keys() == theirs.keys() and all(torch.equal(ours[k], theirs[k]) for k in ours)


@pytest.mark.parametrize("fitted", [True, False])
def test_touch_agent_state_round_trip(discrete_env, fitted):
    agent, fresh = touch_agent(discrete_env, 0), touch_agent(discrete_env, 1)
    if fitted:
        agent.fit(touch_agent(discrete_env, 2).touch)
    assert agent.fitted is fitted and fresh.fitted is False
    assert not same_weights(agent.touch, fresh.touch) and not same_weights(agent.agent.q, fresh.agent.q)
    fresh.fitted = not fitted  # the flag must come from the checkpoint
    fresh.load_state_dict(through_file(agent.state_dict()))
    assert fresh.fitted is fitted
    assert same_weights(agent.touch, fresh.touch) and same_weights(agent.agent.q, fresh.agent.q)
    assert not fresh.touch.training and not any(p.requires_grad for p in fresh.touch.parameters())
    with pytest.raises(ValueError, match="touch encoder"):
        fresh.load_state_dict(through_file(agent.agent.state_dict()))  # a plain agent's checkpoint


def test_touch_agent_policy_snapshot_holds_the_encoder(discrete_env):
    agent, fresh = touch_agent(discrete_env, 0), touch_agent(discrete_env, 1)
    snapshot = agent.policy_state_dict()
    assert set(snapshot) == {"q", "touch"}
    fresh.load_policy_state_dict(through_file(snapshot))
    assert same_weights(agent.touch, fresh.touch) and same_weights(agent.agent.q, fresh.agent.q)
    with pytest.raises(ValueError, match="touch encoder"):
        fresh.load_policy_state_dict({"q": snapshot["q"]})


# ---------------------------------------------------------------- training with a touch encoder
class FrameRecordingBuffer(EpisodeReplayBuffer):
    """The replay buffer, keeping what was handed in for each frame slot: the image and its labels."""

    made: ClassVar[list[FrameRecordingBuffer]] = []

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.handed: dict[int, tuple[np.ndarray, np.ndarray | None]] = {}
        FrameRecordingBuffer.made.append(self)

    def _store_frame(self, image: np.ndarray, label: np.ndarray | None = None) -> int:
        slot = super()._store_frame(image, label)
        self.handed[slot] = (
            np.array(image, copy=True),
            None if label is None else np.array(label, copy=True),
        )
        return slot

    def handed_images(self, slots) -> np.ndarray:
        """The images handed in for ``slots``, as the buffer keeps them (binary, (N, 1, 100, 100))."""
        return ((as_images([self.handed[slot][0] for slot in slots]) > 127) * 255).astype(np.uint8)

    def handed_labels(self, slots) -> np.ndarray:
        return np.stack([self.handed[slot][1] for slot in slots])


class Fit(NamedTuple):
    taps: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # images, poses, pressed, under
    epochs: int
    init: dict | None  # the weights the fit started from
    result: dict  # the fitted weights


class RecordingFit:
    """``fit_touch_encoder``, noting the labelled taps, the epochs and the weights of each call."""

    def __init__(self) -> None:
        self.calls: list[Fit] = []

    def __call__(self, *args, **kwargs):
        arguments = inspect.signature(fit_touch_encoder).bind(*args, **kwargs).arguments
        taps, init = arguments["taps"], arguments.get("init")
        model, metrics = fit_touch_encoder(*args, **kwargs)
        self.calls.append(
            Fit(
                (*taps.arrays(), np.array(taps.under, dtype=np.int64)),
                arguments["config"].epochs,
                None if init is None else copy.deepcopy(init.state_dict()),
                copy.deepcopy(model.state_dict()),
            )
        )
        return model, metrics


def touch_config(env_datasets, algo: str = "dqn", **changes) -> TrainConfig:
    task = CONTINUOUS_TASK if AGENTS[algo].continuous else DISCRETE_TASK
    settings = {
        "task": task,
        "algo": algo,
        "epochs": 1,
        "steps_per_epoch": 20,
        "start_steps": 12,
        "threads": 1,
        "dataset": str(env_datasets[task]),
        "agent": AGENTS[algo].config(hidden=(16,), batch_size=8),
        "evaluation": {"test_episodes": 1, "snapshots": 1},
        "replay": {"capacity": 200},
        "touch": {"enabled": True, "epochs": 2},
    }
    groups = {name: {**settings[name], **changes.pop(name)} for name in ("evaluation", "replay", "touch")
              if isinstance(changes.get(name), dict)}  # fmt: skip
    return TrainConfig(**{**settings, **groups, **changes})


def recorded_train(config, run_dir, resume: bool = False):
    """Train (or resume) with the replay buffer and the encoder's fits recorded."""
    FrameRecordingBuffer.made = []
    fit = RecordingFit()
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(train_module, "EpisodeReplayBuffer", FrameRecordingBuffer)
        patch.setattr(extensions_module, "fit_touch_encoder", fit)
        train_module.train(config, run_dir=run_dir, resume=resume, progress=False)
    (buffer,) = FrameRecordingBuffer.made
    return buffer, fit


def checkpoint(run) -> dict:
    return torch.load(run / "checkpoint.pt", weights_only=False)


def saved_encoder(run) -> TouchEncoder:
    encoder = TouchEncoder(GOALS)  # the arrow tasks' 4 keys, the default sizes the training loop uses
    encoder.load_state_dict(checkpoint(run)["agent"]["touch"])
    return encoder.eval()


def saved_replay(run) -> tuple[np.ndarray, np.ndarray]:
    """The packed frames and the frame labels of the run's replay file (checked to hold nothing else)."""
    (replay,) = run.glob("replay.*.npz")
    with np.load(replay) as data:
        assert not any("feature" in name for name in data.files)
        return data["frames"], data["frame_labels"]


def fits(run) -> list[dict]:
    return json.loads((run / "touch.json").read_text())["fits"]


def written_slots(buffer: EpisodeReplayBuffer) -> range:
    return range(min(buffer.frames_written, buffer.frame_capacity))


def assert_replay_features_are_the_encoders(
    buffer: FrameRecordingBuffer, encoder: TouchEncoder, loaded: np.ndarray | None = None
) -> None:
    """The feature cache, and the batches sampled, are ``encoder``'s features of the stored images
    (``loaded``: the images of the frames a resumed run loaded, stored before the others)."""
    loaded = np.zeros((0, 1, 100, 100), np.uint8) if loaded is None else loaded
    slots = written_slots(buffer)
    images = np.concatenate([loaded, buffer.handed_images(slots[len(loaded) :])])
    np.testing.assert_array_equal(unpack(buffer.frames[np.array(slots)]), images)
    np.testing.assert_allclose(buffer.features[: len(slots)], encoder.encode(images), rtol=1e-4, atol=1e-5)
    plain = copy.copy(buffer)
    plain.features = None  # the same buffer sampling images
    ours, theirs = buffer.sample(16, np.random.default_rng(0)), plain.sample(16, np.random.default_rng(0))
    assert ours["images"].shape == (16, TouchEncoderConfig().features)
    for name in ("images", "next_images"):
        np.testing.assert_allclose(ours[name], encoder.encode(theirs[name]), rtol=1e-4, atol=1e-5)


@pytest.fixture(scope="module")
def touch_runs(env_datasets, tmp_path_factory) -> dict[str, tuple]:
    """A finished one-epoch touch run each for DQN (relabel "all") and SAC (the paper's relabelling)."""
    runs = {}
    for algo, relabel in (("dqn", "all"), ("sac", "paper")):
        run = tmp_path_factory.mktemp("touch") / algo
        buffer, fit = recorded_train(touch_config(env_datasets, algo, replay={"relabel": relabel}), run)
        runs[algo] = (run, buffer, fit)
    return runs


def test_make_agent_builds_a_touch_agent_on_features(env_datasets, discrete_env):
    agent = train_module.make_agent(touch_config(env_datasets), discrete_env)
    assert isinstance(agent, TouchAgent) and not agent.fitted
    assert agent.touch.features_size == TouchEncoderConfig().features and agent.touch.keys == GOALS
    assert agent.agent.q.trunk.encoder is None  # the learner has dense layers only
    plain = train_module.make_agent(touch_config(env_datasets, touch={"enabled": False}), discrete_env)
    assert isinstance(plain, DQNAgent) and plain.q.trunk.encoder is not None


@pytest.mark.parametrize("algo", ["dqn", "sac"])
def test_a_touch_run_labels_its_frames_fits_at_the_start_steps_and_replays_features(
    touch_runs, discrete_env, algo
):
    run, buffer, fit = touch_runs[algo]
    (summary,) = fits(run)
    assert set(summary) == {
        "touch/taps", "touch/pose_error_mm", "touch/depth_error_mm", "touch/key_accuracy",
        "touch/under_accuracy", "env_steps",
    }  # fmt: skip
    assert summary["env_steps"] == 12 and all(np.isfinite(value) for value in summary.values())
    (call,) = fit.calls
    assert call.init is None and call.epochs == 2  # a first fit: fresh weights, touch_epochs passes
    # The first observation and the 12 start steps' observations, plus the first observation of each
    # episode begun within them: the frames stored so far, in order, with their labels.
    images, poses, pressed, under = call.taps
    assert summary["touch/taps"] == len(images) and 13 <= len(images) <= 24
    taps = range(len(images))
    np.testing.assert_array_equal(images, buffer.handed_images(taps))
    labels = buffer.handed_labels(taps)
    np.testing.assert_array_equal(poses, labels[:, :3])
    np.testing.assert_array_equal(pressed, labels[:, 3])
    np.testing.assert_array_equal(under, labels[:, 4])
    state = checkpoint(run)
    assert state["agent"]["touch_fitted"] is True and "taps" not in state
    assert not list(run.glob("taps.*.npz"))
    (row,) = read_progress(run)
    assert row["env_steps"] == 20 and row["updates"] > 0  # the learner trained on features
    snapshot = torch.load(next((run / "snapshots").iterdir()), weights_only=False)
    assert torch.equal(snapshot["touch"]["pose.weight"], state["agent"]["touch"]["pose.weight"])

    # Every frame came with its labels; the replay file holds the packed images and the labels.
    slots = written_slots(buffer)
    assert set(buffer.handed) == set(slots)
    assert all(label is not None and label.shape == (FRAME_LABELS,) for _, label in buffer.handed.values())
    frames, saved_labels = saved_replay(run)
    assert frames.dtype == np.uint8 and frames.shape[1] == PACKED_BYTES and len(frames) > len(images)
    np.testing.assert_array_equal(unpack(frames), buffer.handed_images(range(len(frames))))
    np.testing.assert_array_equal(saved_labels, buffer.handed_labels(range(len(frames))))
    # A frame's pressed key is the key its transition pressed; the key under the sensor is the task key
    # whose centre it is over (the discrete task taps key centres, or places outside the task's keys).
    size = buffer.size
    np.testing.assert_array_equal(
        buffer.frame_labels[buffer.frame_index[:size, 1], 3], buffer.achieved[:size]
    )
    all_labels = buffer.handed_labels(slots)
    assert (all_labels[:, 3] >= 0).any(), "no key was pressed: the pressed-key labels were not checked"
    if algo == "dqn":
        layout, keys = discrete_env.unwrapped.layout, discrete_env.unwrapped.goal_keys
        centres = {layout.centre_mm(key): index for index, key in enumerate(keys)}
        expected = [centres.get((float(x), float(y)), -1) for x, y in all_labels[:, :2]]
        assert all_labels[:, 4].tolist() == expected and set(expected) > {-1}
    else:
        locate = KeyLocator(KeyboardLayout(), ARROW_KEYS)
        assert all_labels[:, 4].tolist() == [locate(pose) for pose in all_labels[:, :3]]

    # Batches hold the saved encoder's features of the stored images.
    assert buffer.images
    assert_replay_features_are_the_encoders(buffer, saved_encoder(run))


def test_a_run_resumed_before_the_fit_keeps_its_labelled_frames_and_fits_at_the_start_steps(
    env_datasets, tmp_path
):
    run = tmp_path / "early"
    config = touch_config(env_datasets, start_steps=30)
    first, fit = recorded_train(config, run)
    assert not fit.calls and not (run / "touch.json").exists()
    state = checkpoint(run)
    assert state["agent"]["touch_fitted"] is False and "taps" not in state
    assert read_progress(run)[0]["updates"] == 0
    old_frames, old_labels = saved_replay(run)
    saved = len(old_frames)
    assert saved >= 21 and len(old_labels) == saved  # the first observation and 20 steps' observations
    np.testing.assert_array_equal(old_labels, first.handed_labels(range(saved)))

    data = json.loads((run / "config.json").read_text())
    data["epochs"] = 2
    (run / "config.json").write_text(json.dumps(data))
    buffer, fit = recorded_train(None, run, resume=True)
    (call,) = fit.calls
    images, poses, pressed, under = call.taps
    # The frames of the first epoch come first, with the labels they were saved with.
    np.testing.assert_array_equal(images[:saved], unpack(old_frames))
    np.testing.assert_array_equal(poses[:saved], old_labels[:, :3])
    np.testing.assert_array_equal(pressed[:saved], old_labels[:, 3])
    np.testing.assert_array_equal(under[:saved], old_labels[:, 4])
    assert saved + 11 <= len(images) <= saved + 21  # a new first observation and 10 steps more
    (summary,) = fits(run)
    assert summary["env_steps"] == 30 and summary["touch/taps"] == len(images)
    state = checkpoint(run)
    assert state["agent"]["touch_fitted"] is True and "taps" not in state
    rows = read_progress(run)
    assert [row["env_steps"] for row in rows] == [20, 40] and rows[-1]["updates"] > 0
    frames, labels = saved_replay(run)
    assert frames.dtype == np.uint8 and len(frames) > saved
    np.testing.assert_array_equal(frames[:saved], old_frames)
    np.testing.assert_array_equal(labels[:saved], old_labels)
    # The loaded frames were encoded too, by the fitted encoder.
    assert set(buffer.handed) == set(written_slots(buffer)[saved:])
    assert_replay_features_are_the_encoders(buffer, saved_encoder(run), loaded=unpack(old_frames))


def test_a_run_resumed_after_the_fit_reencodes_its_replay_with_the_loaded_encoder(touch_runs, tmp_path):
    original, _, _ = touch_runs["dqn"]
    run = tmp_path / "late"
    shutil.copytree(original, run)
    fitted = saved_encoder(run)
    old_frames, old_labels = saved_replay(run)
    summary = (run / "touch.json").read_text()
    data = json.loads((run / "config.json").read_text())
    data["epochs"] = 2
    (run / "config.json").write_text(json.dumps(data))
    buffer, fit = recorded_train(None, run, resume=True)
    assert not fit.calls  # not fitted again
    assert same_weights(saved_encoder(run), fitted)
    assert checkpoint(run)["agent"]["touch_fitted"] is True
    assert (run / "touch.json").read_text() == summary
    # The loaded images' features were recomputed with the loaded encoder, the new ones encoded as stored.
    assert set(buffer.handed) == set(written_slots(buffer)[len(old_frames) :])
    assert_replay_features_are_the_encoders(buffer, fitted, loaded=unpack(old_frames))
    frames, labels = saved_replay(run)
    assert frames.dtype == np.uint8 and len(frames) > len(old_frames)
    np.testing.assert_array_equal(frames[: len(old_frames)], old_frames)
    np.testing.assert_array_equal(labels[: len(old_frames)], old_labels)
    assert not np.isnan(labels).any()
    rows = read_progress(run)
    assert [row["env_steps"] for row in rows] == [20, 40] and rows[1]["updates"] > rows[0]["updates"]


def test_touch_fit_steps_follow_the_start_steps_at_the_refit_interval(env_datasets):
    assert touch_fit_steps(touch_config(env_datasets)) == (12,)
    assert touch_fit_steps(touch_config(env_datasets, touch={"refits": 3})) == (12, 24, 36, 48)
    every = touch_config(env_datasets, touch={"refits": 2, "refit_every": 5})
    assert touch_fit_steps(every) == (12, 17, 22)
    with pytest.raises(ValueError, match=r"TouchConfig.refit_every must be at least 1"):
        touch_config(env_datasets, touch={"refit_every": 0})


def test_a_refit_starts_from_the_current_encoder_on_every_labelled_frame_so_far(env_datasets, tmp_path):
    run = tmp_path / "refit"
    config = touch_config(env_datasets, steps_per_epoch=26, touch={"refits": 1, "epochs": 8})
    buffer, fit = recorded_train(config, run)
    first, second = fit.calls
    assert first.init is None and first.epochs == 8
    taps, more = len(first.taps[0]), len(second.taps[0])
    assert more >= taps + 12
    for ours, theirs in zip(first.taps, second.taps, strict=True):  # the first fit's taps, then newer ones
        np.testing.assert_array_equal(theirs[:taps], ours)
    np.testing.assert_array_equal(second.taps[0], buffer.handed_images(range(more)))
    # From the first fit's weights, with as many gradient steps as it (epochs scaled by the taps).
    assert second.init is not None
    assert all(torch.equal(second.init[name], value) for name, value in first.result.items())
    assert second.epochs == max(1, round(8 * 12 / more)) and 1 <= second.epochs < 8
    assert [(entry["env_steps"], entry["touch/taps"]) for entry in fits(run)] == [(12, taps), (24, more)]
    # The replay holds the refitted encoder's features.
    encoder = saved_encoder(run)
    assert all(torch.equal(encoder.state_dict()[name], value) for name, value in second.result.items())
    assert not all(torch.equal(second.result[name], value) for name, value in first.result.items())
    assert_replay_features_are_the_encoders(buffer, encoder)


@pytest.mark.parametrize("algo", ["dqn", "sac"])
def test_report_and_typing_evaluate_a_touch_run_on_images(touch_runs, algo):
    run, _, _ = touch_runs[algo]
    config, env, agent = load_run(run)
    assert config.touch.enabled and isinstance(agent, TouchAgent) and agent.fitted
    assert same_weights(agent.touch, saved_encoder(run))
    observation, _ = env.reset(seed=0)
    assert observation["observation"].shape == (100, 100, 1)
    rng = np.random.default_rng(0)
    features = {**observation, "observation": agent.touch.encode(observation["observation"][None])[0]}
    np.testing.assert_array_equal(
        agent.policy_action(observation, 0, explore=False, rng=rng, deterministic=True),
        agent.agent.policy_action(features, 0, explore=False, rng=rng, deterministic=True),
    )
    results = evaluate_run(run, episodes=2)
    assert 0.0 <= results["test/success_rate"] <= 1.0
    assert 1 <= results["test/episode_length"] <= env.spec.max_episode_steps
    typing = evaluate_typing(run)
    assert typing["keys_asked"] == 96 and 0.0 <= typing["accuracy"] <= 1.0
    assert 96 <= typing["total_steps"] <= 96 * env.spec.max_episode_steps
    assert (run / "typing.json").exists()


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"replay": {"relabel": "bogus"}}, "relabel must be one of"),
        ({"start_steps": 9}, "at least 10"),
        ({"touch": {"epochs": 0}}, "TouchConfig.epochs must be at least 1"),
        ({"touch": {"refits": -1}}, "TouchConfig.refits must be at least 0"),
    ],
)
def test_train_config_rejects_bad_touch_and_relabel_settings(env_datasets, changes, message):
    with pytest.raises(ValueError, match=message):
        touch_config(env_datasets, **changes)


def test_few_start_steps_are_fine_without_a_touch_encoder(env_datasets):
    assert touch_config(env_datasets, start_steps=5, touch={"enabled": False}).start_steps == 5
