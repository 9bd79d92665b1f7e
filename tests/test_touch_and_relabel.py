"""Relabelling when sampling, feature replay, the touch encoder and touch-encoder training runs.

The replay tests build buffers by hand from episodes whose every transition
carries a unique action id, so each sampled transition can be traced back to
its episode. The training tests run tiny real trainings on the small test
datasets (one torch thread, a few dozen steps, two passes of the encoder's fit).
"""

from __future__ import annotations

import copy
import importlib
import io
import json
import shutil
from typing import ClassVar

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
from tactile_braille.agents.report import evaluate_run, load_run
from tactile_braille.agents.touch import (
    LabelledTaps,
    TouchAgent,
    TouchEncoder,
    TouchEncoderConfig,
    feature_space,
    fit_touch_encoder,
)
from tactile_braille.evaluation.protocol import evaluate_typing

# ``tactile_braille.agents.train`` the function shadows the module of the same name: use the registry.
train_module = importlib.import_module("tactile_braille.agents.train")

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
WRONG_PRESS_STEPS = sum(steps for goal, steps, end in EPISODES if isinstance(end, int) and end != goal)


@pytest.fixture(autouse=True)
def _one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


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
    """Distinct observations in order: random binary images, or random feature vectors."""

    def __init__(self, features: bool = False, seed: int = 0) -> None:
        self.features, self.rng = features, np.random.default_rng(seed)

    def __call__(self) -> np.ndarray:
        if self.features:
            return self.rng.normal(size=FEATURES).astype(np.float32)
        return ((self.rng.random((100, 100, 1)) < 0.3) * 255).astype(np.uint8)


def fill(
    buffer: EpisodeReplayBuffer, frames: Frames, episodes=EPISODES, first_id: int = 0
) -> dict[int, dict]:
    """Record ``episodes``; returns, by action id, each transition's pressed key, final key and goal."""
    table, action = {}, first_id
    for goal, steps, end in episodes:
        buffer.start_episode(replay_observation(frames(), goal))
        final = end if isinstance(end, int) else -1
        for step in range(steps):
            last = step == steps - 1
            achieved = end if last and isinstance(end, int) else None
            terminated = last and end != TIMEOUT
            reward = float(achieved == goal)
            buffer.add_step(action, reward, replay_observation(frames(), goal, achieved), terminated)
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
    assert (restored.next_frame, restored.frames_written) == (STEPS + len(EPISODES),) * 2
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


# ---------------------------------------------------------------- map_observations
PROJECTION = np.random.default_rng(7).normal(size=(100 * 100, FEATURES)).astype(np.float32)


def encode(images: np.ndarray) -> np.ndarray:
    """A fixed random projection of (B, 1, 100, 100) uint8 images (one row at a time: exact per image)."""
    assert images.dtype == np.uint8 and images.shape[1:] == (1, 100, 100)
    flat = images.reshape(len(images), -1).astype(np.float32) / 255.0
    return np.stack([row @ PROJECTION for row in flat])


def as_batch(image: np.ndarray) -> np.ndarray:
    """One (100, 100, 1) image as a (1, 1, 100, 100) batch."""
    return np.moveaxis(image, -1, 0)[None]


def test_map_observations_encodes_every_frame_and_the_episode_in_progress():
    buffer = all_buffer()
    frames = Frames()
    table = fill(buffer, frames)
    start = frames()
    buffer.start_episode(replay_observation(start, 1))
    middle = frames()
    buffer.add_step(50, 0.0, replay_observation(middle, 1), terminated=False)
    original = copy.deepcopy(buffer)
    calls = []

    def counting(images):
        calls.append(len(images))
        return encode(images)

    with pytest.raises(ValueError, match="vectors"):
        buffer.map_observations(counting, (2, 3))
    assert buffer.images and not calls  # refused before anything changed
    buffer.map_observations(counting, (FEATURES,), batch_size=7)
    assert sum(calls) == original.frames_written and max(calls) == 7
    assert not buffer.images and buffer.frames.dtype == np.float32
    ours, theirs = (
        buffer.sample(200, np.random.default_rng(4)),
        original.sample(200, np.random.default_rng(4)),
    )
    np.testing.assert_allclose(ours["images"], encode(theirs["images"]), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(ours["next_images"], encode(theirs["next_images"]), rtol=1e-6, atol=1e-6)
    for name in ("goals", "actions", "rewards", "dones", "previous_actions"):
        np.testing.assert_array_equal(ours[name], theirs[name], err_msg=name)
    with pytest.raises(ValueError, match="features already"):
        buffer.map_observations(counting, (FEATURES,))

    # The episode in progress goes on with features and ends in a press of key 1.
    last = np.full(FEATURES, 9.0, dtype=np.float32)
    buffer.add_step(51, 1.0, replay_observation(last, 1, achieved=1), terminated=True)
    buffer.end_episode()
    assert buffer.size == STEPS + 2
    batch = buffer.sample(2000, np.random.default_rng(5))
    assert set(batch["actions"].tolist()) == {*table, 50, 51}
    first = batch["actions"] == 50
    second = batch["actions"] == 51
    for rows, name, expected in (
        (first, "images", encode(as_batch(start))),
        (first, "next_images", encode(as_batch(middle))),
        (second, "images", encode(as_batch(middle))),
        (second, "next_images", last[None]),
    ):
        assert rows.any()
        np.testing.assert_allclose(
            batch[name][rows], np.repeat(expected, rows.sum(), 0), rtol=1e-6, atol=1e-6
        )
    goals = goal_indices(batch["goals"])
    np.testing.assert_array_equal(batch["rewards"][second], (goals[second] == 1).astype(np.float32))
    assert (batch["rewards"][first] == 0).all()
    assert buffer.finals[buffer.size - 1] == buffer.finals[buffer.size - 2] == 1


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


def test_labelled_taps_from_observations_and_through_a_file(tmp_path):
    taps = LabelledTaps()
    images = Frames()
    given = [images() for _ in range(5)]
    for image, achieved in zip(given, (None, 2, None, 0), strict=False):
        pose = np.array([1.0, -2.0, 3.0]) * (len(taps) + 1)
        taps.add_observation(replay_observation(image, 1, achieved), {"sensor_pose_mm": pose})
    taps.add(given[4][:, :, 0], np.array([9.0, 8.0, 7.0, 6.0]), pressed=3)  # a 2-D image, extra pose entries
    assert len(taps) == 5
    stacked, poses, pressed = taps.arrays()
    assert stacked.shape == (5, 1, 100, 100) and stacked.dtype == np.uint8
    np.testing.assert_array_equal(stacked, np.moveaxis(np.stack(given), -1, 1))
    assert poses.shape == (5, 3) and poses.dtype == np.float32
    np.testing.assert_array_equal(poses[:4], np.array([1.0, -2.0, 3.0]) * np.arange(1, 5)[:, None])
    np.testing.assert_array_equal(poses[4], [9.0, 8.0, 7.0])
    assert pressed.tolist() == [-1, 2, -1, 0, 3] and pressed.dtype == np.int64
    taps.save(tmp_path / "taps.npz")
    again = LabelledTaps()
    again.add(images(), np.zeros(3), 1)  # replaced by the file's taps
    again.load(tmp_path / "taps.npz")
    for ours, theirs in zip(taps.arrays(), again.arrays(), strict=True):
        np.testing.assert_array_equal(ours, theirs)
        assert ours.dtype == theirs.dtype
    empty = LabelledTaps()
    empty.save(tmp_path / "empty.npz")
    again.load(tmp_path / "empty.npz")
    assert len(again) == 0


def test_labelled_taps_refuse_a_file_whose_arrays_differ_in_number(tmp_path):
    np.savez(
        tmp_path / "bad.npz",
        images=np.zeros((3, 1, 100, 100), np.uint8),
        poses=np.zeros((2, 3), np.float32),
        pressed=np.zeros(3, np.int64),
    )
    with pytest.raises(ValueError, match="differ in number"):
        LabelledTaps().load(tmp_path / "bad.npz")


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
    """The replay buffer, keeping what was handed in for each frame slot (an image or features)."""

    made: ClassVar[list[FrameRecordingBuffer]] = []

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.handed: dict[int, np.ndarray] = {}
        FrameRecordingBuffer.made.append(self)

    def _store_frame(self, image: np.ndarray) -> int:
        slot = super()._store_frame(image)
        self.handed[slot] = np.array(image, copy=True)
        return slot


class RecordingFit:
    """``fit_touch_encoder``, noting the labelled taps of each call."""

    def __init__(self) -> None:
        self.calls: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def __call__(self, taps, *args, **kwargs):
        self.calls.append(taps.arrays())
        return fit_touch_encoder(taps, *args, **kwargs)


def touch_config(env_datasets, algo: str = "dqn", **changes) -> TrainConfig:
    task = CONTINUOUS_TASK if AGENTS[algo].continuous else DISCRETE_TASK
    settings = {
        "task": task, "algo": algo, "epochs": 1, "steps_per_epoch": 20, "start_steps": 12, "test_episodes": 1,
        "replay_capacity": 200, "threads": 1, "dataset": str(env_datasets[task]), "touch_encoder": True,
        "touch_epochs": 2, "snapshots": 1, "agent": AGENTS[algo].config(hidden=(16,), batch_size=8),
    }  # fmt: skip
    return TrainConfig(**{**settings, **changes})


def recorded_train(config, run_dir, resume: bool = False):
    """Train (or resume) with the replay buffer and the encoder's fit recorded."""
    FrameRecordingBuffer.made = []
    fit = RecordingFit()
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(train_module, "EpisodeReplayBuffer", FrameRecordingBuffer)
        patch.setattr(train_module, "fit_touch_encoder", fit)
        train_module.train(config, run_dir=run_dir, resume=resume, progress=False)
    (buffer,) = FrameRecordingBuffer.made
    return buffer, fit


def checkpoint(run) -> dict:
    return torch.load(run / "checkpoint.pt", weights_only=False)


def saved_encoder(run) -> TouchEncoder:
    encoder = TouchEncoder(GOALS)  # the arrow tasks' 4 keys, the default sizes the training loop uses
    encoder.load_state_dict(checkpoint(run)["agent"]["touch"])
    return encoder.eval()


def replay_frames(run) -> np.ndarray:
    (replay,) = run.glob("replay.*.npz")
    with np.load(replay) as data:
        return data["frames"]


@pytest.fixture(scope="module")
def touch_runs(env_datasets, tmp_path_factory) -> dict[str, tuple]:
    """A finished one-epoch touch run each for DQN (relabel "all") and SAC (the paper's relabelling)."""
    runs = {}
    for algo, relabel in (("dqn", "all"), ("sac", "paper")):
        run = tmp_path_factory.mktemp("touch") / algo
        buffer, fit = recorded_train(touch_config(env_datasets, algo, relabel=relabel), run)
        runs[algo] = (run, buffer, fit)
    return runs


def test_make_agent_builds_a_touch_agent_on_features(env_datasets, discrete_env):
    agent = train_module.make_agent(touch_config(env_datasets), discrete_env)
    assert isinstance(agent, TouchAgent) and not agent.fitted
    assert agent.touch.features_size == TouchEncoderConfig().features and agent.touch.keys == GOALS
    assert agent.agent.q.trunk.encoder is None  # the learner has dense layers only
    plain = train_module.make_agent(touch_config(env_datasets, touch_encoder=False), discrete_env)
    assert isinstance(plain, DQNAgent) and plain.q.trunk.encoder is not None


@pytest.mark.parametrize("algo", ["dqn", "sac"])
def test_a_touch_run_fits_the_encoder_at_the_start_steps_and_replays_features(touch_runs, algo):
    run, buffer, fit = touch_runs[algo]
    summary = json.loads((run / "touch.json").read_text())
    assert set(summary) == {
        "touch/taps", "touch/pose_error_mm", "touch/depth_error_mm", "touch/key_accuracy",
        "touch/under_accuracy", "env_steps",
    }  # fmt: skip
    assert summary["env_steps"] == 12
    (taps,) = fit.calls
    # The first observation and the 12 start steps' observations, plus the first observation of each
    # episode begun within them.
    assert summary["touch/taps"] == len(taps[0]) and 13 <= len(taps[0]) <= 24
    assert all(np.isfinite(value) for value in summary.values())
    state = checkpoint(run)
    assert state["agent"]["touch_fitted"] is True and state["taps"] is None
    assert not list(run.glob("taps.*.npz"))
    (row,) = read_progress(run)
    assert row["env_steps"] == 20 and row["updates"] > 0  # the learner trained on features
    snapshot = torch.load(next((run / "snapshots").iterdir()), weights_only=False)
    assert torch.equal(snapshot["touch"]["pose.weight"], state["agent"]["touch"]["pose.weight"])

    frames = replay_frames(run)
    assert frames.dtype == np.float32 and frames.shape[1] == TouchEncoderConfig().features
    # Every frame is the fitted encoder's features of its image: images stored before the fit were mapped,
    # observations after it were stored as features.
    encoder = saved_encoder(run)
    written = min(buffer.frames_written, buffer.frame_capacity)
    assert set(buffer.handed) == set(range(written))
    kinds = {buffer.handed[slot].ndim for slot in range(written)}
    assert kinds == {1, 3}  # both before and after the fit
    for slot in range(written):
        handed = buffer.handed[slot]
        expected = encoder.encode(handed[None])[0] if handed.ndim == 3 else handed
        np.testing.assert_allclose(buffer.frames[slot], expected, rtol=1e-5, atol=1e-5, err_msg=str(slot))
    np.testing.assert_array_equal(frames, buffer.frames[: len(frames)])


def test_a_run_resumed_before_the_fit_keeps_its_taps_and_fits_at_the_start_steps(env_datasets, tmp_path):
    run = tmp_path / "early"
    config = touch_config(env_datasets, start_steps=30)
    _, fit = recorded_train(config, run)
    assert not fit.calls and not (run / "touch.json").exists()
    state = checkpoint(run)
    assert state["taps"] == "taps.0.npz" and state["agent"]["touch_fitted"] is False
    assert read_progress(run)[0]["updates"] == 0
    saved = LabelledTaps()
    saved.load(run / "taps.0.npz")
    assert len(saved) >= 21  # the first observation and 20 steps' observations at least
    old_frames = replay_frames(run)
    assert old_frames.dtype == np.uint8  # images, bit-packed

    data = json.loads((run / "config.json").read_text())
    data["epochs"] = 2
    (run / "config.json").write_text(json.dumps(data))
    buffer, fit = recorded_train(None, run, resume=True)
    (taps,) = fit.calls
    for ours, theirs in zip(saved.arrays(), taps, strict=True):  # the saved taps come first
        np.testing.assert_array_equal(theirs[: len(saved)], ours)
    assert len(saved) + 11 <= len(taps[0]) <= len(saved) + 21  # a new first observation and 10 steps more
    summary = json.loads((run / "touch.json").read_text())
    assert summary["env_steps"] == 30 and summary["touch/taps"] == len(taps[0])
    state = checkpoint(run)
    assert state["taps"] is None and state["agent"]["touch_fitted"] is True
    assert not list(run.glob("taps.*.npz"))
    rows = read_progress(run)
    assert [row["env_steps"] for row in rows] == [20, 40] and rows[-1]["updates"] > 0
    # The images of the first epoch were mapped to the fitted encoder's features.
    frames = replay_frames(run)
    assert frames.dtype == np.float32
    images = (np.unpackbits(old_frames, axis=-1).reshape(-1, 1, 100, 100) * 255).astype(np.uint8)
    np.testing.assert_allclose(frames[: len(old_frames)], saved_encoder(run).encode(images), atol=1e-5)
    assert not buffer.images


def test_a_run_resumed_after_the_fit_reloads_the_encoder_and_the_feature_replay(touch_runs, tmp_path):
    original, _, _ = touch_runs["dqn"]
    run = tmp_path / "late"
    shutil.copytree(original, run)
    fitted = saved_encoder(run)
    old_frames = replay_frames(run)
    summary = (run / "touch.json").read_text()
    data = json.loads((run / "config.json").read_text())
    data["epochs"] = 2
    (run / "config.json").write_text(json.dumps(data))
    buffer, fit = recorded_train(None, run, resume=True)
    assert not fit.calls  # not fitted again
    assert not buffer.images  # the replay holds features from the start
    assert all(handed.ndim == 1 for handed in buffer.handed.values())
    assert same_weights(saved_encoder(run), fitted)
    assert checkpoint(run)["agent"]["touch_fitted"] is True
    assert (run / "touch.json").read_text() == summary
    frames = replay_frames(run)
    assert frames.dtype == np.float32 and len(frames) > len(old_frames)
    np.testing.assert_array_equal(frames[: len(old_frames)], old_frames)
    rows = read_progress(run)
    assert [row["env_steps"] for row in rows] == [20, 40] and rows[1]["updates"] > rows[0]["updates"]


@pytest.mark.parametrize("algo", ["dqn", "sac"])
def test_report_and_typing_evaluate_a_touch_run_on_images(touch_runs, algo):
    run, _, _ = touch_runs[algo]
    config, env, agent = load_run(run)
    assert config.touch_encoder and isinstance(agent, TouchAgent) and agent.fitted
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
        ({"relabel": "bogus"}, "relabel must be one of"),
        ({"start_steps": 9}, "at least 10"),
        ({"touch_epochs": 0}, "touch_epochs"),
    ],
)
def test_train_config_rejects_bad_touch_and_relabel_settings(env_datasets, changes, message):
    with pytest.raises(ValueError, match=message):
        touch_config(env_datasets, **changes)


def test_few_start_steps_are_fine_without_a_touch_encoder(env_datasets):
    assert touch_config(env_datasets, touch_encoder=False, start_steps=5).start_steps == 5
