"""The replay buffer (agents/replay.py): the paper's HER copies and relabelling when sampling, frames and
their labels, the encoder's feature cache, poses for asymmetric critics, saving and loading, and the
buffer split into a frame store, a relabelling strategy and a feature cache proven equal to the buffer
before the split.

Most buffers are built by hand from episodes whose every transition carries a
unique action id, so each sampled transition can be traced back to its
episode, and whose frames (and labels) are kept as they were handed in.

The split buffer is checked against a frozen copy of the implementation before the split
(``tests/_replay_before.py``): both are driven with the same random episodes, and every
sampled batch must be equal bit for bit, the sampling generators left in the same state, and the
checkpoint files of each must load into the other.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np
import pytest

import _replay_before as before
import feature_agents
import replay_helpers
from replay_helpers import (
    FEATURES,
    GOALS,
    Frames,
    as_images,
    feature_episode,
    goal_indices,
    n_step_buffer,
    replay_observation,
)
from tactile_braille.agents import replay as after
from tactile_braille.agents.replay import (
    FRAME_LABELS,
    PACKED_BYTES,
    RELABELLING,
    EpisodeReplayBuffer,
    FeatureCache,
    FrameStore,
    GoalOutcomes,
    PaperRelabelling,
    PressFrames,
    Relabelling,
    ReturnBounds,
    SampledRelabelling,
    SensorPoses,
    make_relabelling,
    random_shift,
)
from tactile_braille.supervised.touch import LabelledTaps

pytestmark = pytest.mark.usefixtures("one_torch_thread")


# ---------------------------------------------------------------- the paper's HER: copies of wrong presses
def observation(image_value: int, goal: int, achieved: int | None = None, previous=(0.0,) * 5) -> dict:
    one_hot = np.eye(GOALS, dtype=np.float32)
    return {
        "observation": np.full((100, 100, 1), image_value, dtype=np.uint8),
        "previous_action": np.asarray(previous, dtype=np.float32),
        "desired_goal": one_hot[goal],
        "achieved_goal": one_hot[achieved] if achieved is not None else np.zeros(GOALS, np.float32),
    }


def run_episode(buffer: EpisodeReplayBuffer, goal: int, pressed: int | None, steps: int = 3) -> None:
    buffer.start_episode(observation(0, goal))
    for t in range(steps):
        last = t == steps - 1
        achieved = pressed if last else None
        reward = float(last and pressed == goal)
        buffer.add_step(
            t % 5, reward, observation(255 * (t % 2), goal, achieved), terminated=last and pressed is not None
        )
    buffer.end_episode()


def make_buffer(her: bool = True, capacity: int = 100) -> EpisodeReplayBuffer:
    return EpisodeReplayBuffer(capacity, GOALS, (), 5, her=her)


def test_wrong_press_is_relabelled_with_the_pressed_key_as_goal():
    buffer = make_buffer()
    run_episode(buffer, goal=0, pressed=2)
    assert buffer.size == 6  # 3 transitions + 3 hindsight copies
    np.testing.assert_array_equal(buffer.goals[:3].argmax(1), [0, 0, 0])
    np.testing.assert_array_equal(buffer.goals[3:6].argmax(1), [2, 2, 2])
    np.testing.assert_array_equal(buffer.rewards[:6], [0, 0, 0, 0, 0, 1])
    np.testing.assert_array_equal(buffer.dones[:6], [0, 0, 1, 0, 0, 1])
    # The copies point at the same frames: each image is stored once.
    np.testing.assert_array_equal(buffer.frame_index[:3], buffer.frame_index[3:6])
    assert buffer.frames_written == 4


@pytest.mark.parametrize(("pressed", "her"), [(0, True), (None, True), (2, False)])
def test_right_presses_time_outs_and_her_off_are_not_relabelled(pressed, her):
    buffer = make_buffer(her=her)
    run_episode(buffer, goal=0, pressed=pressed)
    assert buffer.size == 3
    assert buffer.rewards[2] == float(pressed == 0)


def test_sampled_images_and_next_images_follow_the_episode():
    buffer = make_buffer(her=False)
    run_episode(buffer, goal=1, pressed=1)
    batch = buffer.sample(64, np.random.default_rng(0))
    assert batch["images"].shape == (64, 1, 100, 100) and batch["images"].dtype == np.uint8
    # Frames alternate 0 (reset), 0, 255, 0: each next image is the following frame.
    frames = [0, 0, 255, 0]
    for image, next_image, action in zip(
        batch["images"], batch["next_images"], batch["actions"], strict=True
    ):
        assert image.max() == frames[action] and next_image.max() == frames[action + 1]


def test_press_frames_are_the_frames_presses_were_made_from_with_the_keys_they_pressed():
    """Each press frame is the first frame of a transition that pressed a key (the frame PRESS was
    chosen on), with that key; episodes without a press add none, and before any press there are none."""

    def frame(rows: int, goal: int, achieved: int | None = None) -> dict:  # a binary image: `rows` lit
        lit = observation(0, goal, achieved)
        lit["observation"][:rows] = 255
        return lit

    buffer = EpisodeReplayBuffer(100, GOALS, (), 5, relabel="all", extras=(PressFrames(),))
    buffer.start_episode(frame(1, goal=0))
    buffer.add_step(0, 0.0, frame(2, goal=0), terminated=False)
    buffer.end_episode()  # a time-out: no press
    batch = buffer.sample(8, np.random.default_rng(0))
    assert batch["press_images"].shape == (0, 1, 100, 100) and batch["press_keys"].shape == (0,)
    for rows, key in ((30, 2), (60, 3)):  # the press is made from `rows`; the frames around it differ
        buffer.start_episode(frame(rows - 10, goal=1))
        buffer.add_step(2, 0.0, frame(rows, goal=1), terminated=False)
        buffer.add_step(4, 0.0, frame(rows + 5, goal=1, achieved=key), terminated=True)
        buffer.end_episode()
    batch = buffer.sample(200, np.random.default_rng(1))
    assert batch["press_images"].shape == (200, 1, 100, 100) and batch["press_keys"].dtype == np.int64
    lit_rows = (batch["press_images"][:, 0, :, 0] > 0).sum(-1)
    assert set(zip(lit_rows.tolist(), batch["press_keys"].tolist(), strict=True)) == {(30, 2), (60, 3)}
    plain = make_buffer()
    run_episode(plain, goal=1, pressed=2)
    assert "press_images" not in plain.sample(4, np.random.default_rng(0))
    with pytest.raises(ValueError, match="discrete actions"):
        EpisodeReplayBuffer(10, GOALS, (3,), 3, extras=(PressFrames(),))


def test_return_bounds_are_the_discounted_return_of_the_transitions_own_episode(tmp_path):
    """gamma ** k where the episode pressed the batch goal's key k steps after the transition, else 0;
    a saved and loaded buffer gives the same bounds (it keeps the steps remaining)."""
    buffer = EpisodeReplayBuffer(100, GOALS, (), 5, her=False, extras=(ReturnBounds(0.5),))
    run_episode(buffer, goal=2, pressed=2, steps=3)  # actions 0, 1, 2: pressed 2 steps after the first
    run_episode(buffer, goal=1, pressed=3, steps=2)  # a wrong press: no bound under goal 1
    run_episode(buffer, goal=0, pressed=None, steps=2)  # a time-out: no bound
    batch = buffer.sample(300, np.random.default_rng(0))
    goals, actions = batch["goals"].argmax(-1), batch["actions"]
    expected = np.where(goals == 2, 0.5 ** (2 - actions), 0.0)
    np.testing.assert_allclose(batch["return_bounds"], expected)
    assert set(np.unique(goals)) == {0, 1, 2} and batch["return_bounds"].dtype == np.float32
    buffer.save(tmp_path / "replay.npz")
    again = EpisodeReplayBuffer(100, GOALS, (), 5, her=False, extras=(ReturnBounds(0.5),))
    again.load(tmp_path / "replay.npz")
    np.testing.assert_array_equal(
        again.sample(300, np.random.default_rng(0))["return_bounds"], batch["return_bounds"]
    )
    late = EpisodeReplayBuffer(100, GOALS, (), 5, her=False, extras=(ReturnBounds(0.5, after=6),))
    run_episode(late, goal=2, pressed=2, steps=3)
    assert not late.sample(50, np.random.default_rng(0))["return_bounds"].any()  # 3 transitions of 6
    run_episode(late, goal=2, pressed=2, steps=3)
    assert late.sample(50, np.random.default_rng(0))["return_bounds"].max() == 1.0  # 6: the bounds apply
    with pytest.raises(ValueError, match="return bounds need the agent's discount"):
        ReturnBounds(None)


def shifted(image: np.ndarray, rows: int, columns: int) -> np.ndarray:
    """``image`` (C, H, W) moved by (rows, columns), read pixel by pixel with the indices clipped."""
    _, height, width = image.shape
    r = np.clip(np.arange(height) + rows, 0, height - 1)
    c = np.clip(np.arange(width) + columns, 0, width - 1)
    return image[:, r][:, :, c]


def offset_of(image: np.ndarray, source: np.ndarray, pixels: int) -> tuple[int, int] | None:
    for rows in range(-pixels, pixels + 1):
        for columns in range(-pixels, pixels + 1):
            if np.array_equal(image, shifted(source, rows, columns)):
                return rows, columns
    return None


def test_random_shift_moves_each_image_by_its_own_offset_with_its_edges_repeated():
    rng = np.random.default_rng(0)
    images = rng.integers(0, 256, size=(300, 1, 12, 12), dtype=np.uint8)
    moved = random_shift(images, 2, np.random.default_rng(1))
    assert moved.shape == images.shape and moved.dtype == np.uint8
    offsets = [offset_of(m, i, 2) for m, i in zip(moved, images, strict=True)]
    assert None not in offsets and len(set(offsets)) == 25  # every offset in [-2, 2]^2, drawn per image
    np.testing.assert_array_equal(random_shift(images, 0, rng), images)


def test_a_replay_with_shift_serves_its_images_moved_and_the_rest_unchanged():
    def edge_observation(column: int, goal: int, achieved: int | None = None) -> dict:
        seen = observation(0, goal, achieved)
        seen["observation"][:, column:] = 255  # a vertical edge, where a shift shows
        seen["observation"][40:, :] = 0
        return seen

    buffers = [EpisodeReplayBuffer(100, GOALS, (), 5, her=False, shift=shift) for shift in (0, 3)]
    for buffer in buffers:
        buffer.start_episode(edge_observation(50, 1))
        for t in range(4):
            buffer.add_step(t, 0.0, edge_observation(30 + 10 * t, 1), terminated=False)
        buffer.end_episode()
    plain, moved = (buffer.sample(64, np.random.default_rng(2)) for buffer in buffers)
    for name in ("actions", "goals", "rewards", "dones", "previous_actions"):
        np.testing.assert_array_equal(plain[name], moved[name])
    for key in ("images", "next_images"):
        offsets = [offset_of(m, p, 3) for m, p in zip(moved[key], plain[key], strict=True)]
        assert None not in offsets and len(set(offsets)) > 10
    with pytest.raises(ValueError, match="shift is a number of pixels, at least 0, got -1"):
        EpisodeReplayBuffer(100, GOALS, (), 5, shift=-1)


def test_ring_overwrites_the_oldest_transitions():
    buffer = make_buffer(her=False, capacity=5)
    for _ in range(4):
        run_episode(buffer, goal=0, pressed=None, steps=2)
    assert buffer.size == 5
    assert buffer.next_slot == 8 % 5


def test_save_and_load_round_trip(tmp_path):
    buffer = make_buffer()
    run_episode(buffer, goal=3, pressed=1)
    buffer.save(tmp_path / "replay.npz")
    restored = make_buffer()
    restored.load(tmp_path / "replay.npz")
    for name in ("frame_index", "goals", "actions", "rewards", "dones", "previous_actions"):
        np.testing.assert_array_equal(getattr(restored, name), getattr(buffer, name))
    assert (restored.size, restored.next_slot, restored.frames_written) == (6, 6, 4)
    too_small = EpisodeReplayBuffer(2, GOALS, (), 5)
    with pytest.raises(ValueError, match="another frame ring"):
        too_small.load(tmp_path / "replay.npz")
    assert too_small.size == 0  # nothing changed
    other_goals = EpisodeReplayBuffer(100, GOALS + 1, (), 5)
    with pytest.raises(ValueError, match="goals of shape"):
        other_goals.load(tmp_path / "replay.npz")
    assert other_goals.size == 0 and not other_goals.frames.any()


def test_add_step_before_start_raises():
    with pytest.raises(RuntimeError, match="start_episode"):
        make_buffer().add_step(0, 0.0, observation(0, 0), False)


def filled_observation(value: int, goal: int = 0, achieved: int | None = None) -> dict:
    one_hot = np.eye(4, dtype=np.float32)
    return {
        "observation": np.full((100, 100, 1), value, dtype=np.uint8),
        "previous_action": np.zeros(5, dtype=np.float32),
        "desired_goal": one_hot[goal],
        "achieved_goal": one_hot[achieved] if achieved is not None else np.zeros(4, np.float32),
    }


def test_replay_images_survive_the_next_episode_starting():
    buffer = EpisodeReplayBuffer(3, 4, (), 5, her=False)
    for action in range(3):  # three one-step successful episodes: black image, then white
        buffer.start_episode(filled_observation(0))
        buffer.add_step(action, 1.0, filled_observation(255, 0, 0), terminated=True)
        buffer.end_episode()
    buffer.start_episode(filled_observation(255))  # the next episode starts on a white image
    batch = buffer.sample(64, np.random.default_rng(0))
    if buffer.size != 3 or set(batch["actions"].tolist()) != {0, 1, 2}:
        raise RuntimeError("setup: every stored transition should be sampled")
    assert (batch["images"] == 0).all()  # each stored transition began on a black image
    assert (batch["next_images"] == 255).all()


def test_replay_save_leaves_out_the_episode_in_progress(tmp_path):
    buffer = EpisodeReplayBuffer(10, 4, (), 5, her=False, max_episode_steps=5)
    buffer.start_episode(filled_observation(0))
    buffer.add_step(0, 0.0, filled_observation(255, 0, 1), terminated=True)
    buffer.end_episode()
    buffer.start_episode(filled_observation(0))  # in progress: one frame written, nothing committed
    buffer.add_step(1, 0.0, filled_observation(255), terminated=False)
    assert buffer.frames_written == 4
    buffer.save(tmp_path / "replay.npz")
    restored = EpisodeReplayBuffer(10, 4, (), 5, her=False, max_episode_steps=5)
    restored.load(tmp_path / "replay.npz")
    assert (restored.frames_written, restored.next_frame, restored.size) == (2, 2, 1)


# ---------------------------------------------------------------- relabel="all": relabelling when sampling
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


def all_buffer(**kwargs) -> EpisodeReplayBuffer:
    return EpisodeReplayBuffer(
        100, GOALS, (), replay_helpers.PREVIOUS, max_episode_steps=10, relabel="all", **kwargs
    )


def test_all_rewards_follow_the_pressed_key_and_the_sampled_goal():
    buffer = all_buffer(extras=(GoalOutcomes(),))
    table = fill(buffer, Frames())
    batch = buffer.sample(3000, np.random.default_rng(0))
    goals = goal_indices(batch["goals"])
    ids = batch["actions"]
    achieved = np.array([table[i]["achieved"] for i in ids])
    np.testing.assert_array_equal(batch["rewards"], (achieved == goals).astype(np.float32))
    np.testing.assert_array_equal(batch["achieved"], achieved)  # for updates on every goal
    plain = all_buffer()
    fill(plain, Frames())
    assert not {"achieved", "goal_weights"} & set(plain.sample(8, np.random.default_rng(0)))  # asked for only
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


def test_goal_weights_are_how_often_the_relabelling_samples_each_goal():
    """The weights an all-goals update may use are the sampling's own frequencies, per transition."""
    for buffer in (
        all_buffer(extras=(GoalOutcomes(),)),
        all_buffer(relabel_final=0.7, relabel_random=0.1, extras=(GoalOutcomes(),)),
    ):
        fill(buffer, Frames())
        batch = buffer.sample(40_000, np.random.default_rng(7))
        weights, goals = batch["goal_weights"], goal_indices(batch["goals"])
        np.testing.assert_allclose(weights.sum(-1), 1.0, rtol=1e-6)
        for transition in np.unique(batch["actions"])[:6]:
            rows = batch["actions"] == transition
            counts = np.bincount(goals[rows], minlength=GOALS) / rows.sum()
            np.testing.assert_allclose(counts, weights[rows][0], atol=0.06)
    paper = EpisodeReplayBuffer(
        100,
        GOALS,
        (),
        replay_helpers.PREVIOUS,
        max_episode_steps=10,
        relabel="paper",
        extras=(GoalOutcomes(),),
    )
    fill(paper, Frames())
    batch = paper.sample(50, np.random.default_rng(8))
    np.testing.assert_array_equal(batch["goal_weights"], batch["goals"])  # goals are never redrawn


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
    paper = EpisodeReplayBuffer(
        100, GOALS, (), replay_helpers.PREVIOUS, max_episode_steps=10, relabel="paper"
    )
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
        ({"observation_shape": (100, 100, 0)}, "images or vectors"),
    ],
)
def test_replay_rejects_bad_arguments(kwargs, message):
    with pytest.raises(ValueError, match=message):
        EpisodeReplayBuffer(10, GOALS, (), replay_helpers.PREVIOUS, **kwargs)


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


def encode(images: np.ndarray, labels: np.ndarray | None = None) -> np.ndarray:
    """A fixed random projection of (B, 1, 100, 100) uint8 images (one row at a time: exact per image)."""
    assert images.dtype == np.uint8 and images.shape[1:] == (1, 100, 100)
    flat = images.reshape(len(images), -1).astype(np.float32) / 255.0
    return np.stack([row @ PROJECTION for row in flat]).reshape(len(images), FEATURES)


class ScaledEncoder:
    """:func:`encode` times ``scale``, counting the images of each call; changing ``scale`` is a refit."""

    def __init__(self, scale: float = 1.0) -> None:
        self.scale, self.calls = scale, []

    def __call__(self, images: np.ndarray, labels: np.ndarray) -> np.ndarray:
        assert labels.shape == (len(images), FRAME_LABELS)  # each frame's labels (NaN: none) come along
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
    def wider(images, labels):
        return np.concatenate([encode(images), np.ones((len(images), 1), np.float32)], axis=1)

    buffer.set_encoder(wider, FEATURES + 1)
    assert buffer.sample(10, np.random.default_rng(6))["images"].shape == (10, FEATURES + 1)
    np.testing.assert_allclose(buffer.features[: FRAMES + 1], wider(as_images(frames.given), None), atol=1e-6)


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


def test_frame_pairs_are_each_steps_two_frames_its_action_and_its_key_the_episode_in_progress_too():
    buffer, frames = all_buffer(), Frames()
    table = fill(buffer, frames)
    buffer.start_episode(replay_observation(frames(), 1))
    acted = np.full(replay_helpers.PREVIOUS, 7.0, np.float32)
    buffer.add_step(99, 0.0, {**replay_observation(frames(), 1, 2), "previous_action": acted}, False)
    images, pairs, previous, pressed = buffer.frame_pairs()
    expected, first = [], 0
    for _, steps, _ in (*EPISODES, (1, 1, 2)):
        expected += [(first + step, first + step + 1) for step in range(steps)]
        first += steps + 1
    assert len(images) == len(frames.given) and pairs.shape == (STEPS + 1, 2)
    np.testing.assert_array_equal(images[pairs[:, 0]], as_images([frames.given[i] for i, _ in expected]))
    np.testing.assert_array_equal(images[pairs[:, 1]], as_images([frames.given[j] for _, j in expected]))
    assert pressed.tolist() == [table[i]["achieved"] for i in range(STEPS)] + [2]
    assert not previous[:STEPS].any() and (previous[STEPS] == 7.0).all() and previous.dtype == np.float32
    with pytest.raises(ValueError, match="holds features"):
        EpisodeReplayBuffer(10, GOALS, (), 2, observation_shape=(FEATURES,)).frame_pairs()


# ---------------------------------------------------------------- poses for asymmetric critics
def one_step_episodes(buffer: EpisodeReplayBuffer, count: int, labelled: bool = True) -> list[np.ndarray]:
    """``count`` one-step episodes; returns the (first, next) labels of each, in order."""
    eye = np.eye(GOALS, dtype=np.float32)
    labels = []
    for episode in range(count):
        observation = {
            "observation": np.full(feature_agents.FEATURES, episode, np.float32),
            "previous_action": np.zeros(feature_agents.PREVIOUS, np.float32),
            "desired_goal": eye[episode % GOALS],
            "achieved_goal": np.zeros(GOALS, np.float32),
        }
        first = np.array([episode, -episode, 4.0, -1, episode % GOALS], np.float32)
        following = np.array([episode + 0.5, -episode - 0.5, 8.0, episode % GOALS, -1], np.float32)
        buffer.start_episode(observation, first if labelled else None)
        pressed = {**observation, "achieved_goal": eye[episode % GOALS]}
        buffer.add_step(np.full(feature_agents.ACTIONS, episode, np.float32), 1.0, pressed, True,
                        following if labelled else None)  # fmt: skip
        buffer.end_episode()
        labels.append(np.stack([first, following]))
    return labels


def test_a_replay_with_poses_gives_each_transition_the_poses_of_its_two_frames():
    buffer = EpisodeReplayBuffer(
        50,
        GOALS,
        (feature_agents.ACTIONS,),
        feature_agents.PREVIOUS,
        observation_shape=(feature_agents.FEATURES,),
        extras=(SensorPoses(),),
    )
    labels = one_step_episodes(buffer, 10)
    data = buffer.sample(32, np.random.default_rng(0))
    episodes = data["actions"][:, 0].astype(int)  # each transition's action holds its episode
    expected = np.stack([labels[e] for e in episodes])
    np.testing.assert_array_equal(data["poses"], expected[:, 0, :3])
    np.testing.assert_array_equal(data["next_poses"], expected[:, 1, :3])
    plain = EpisodeReplayBuffer(
        50,
        GOALS,
        (feature_agents.ACTIONS,),
        feature_agents.PREVIOUS,
        observation_shape=(feature_agents.FEATURES,),
    )
    one_step_episodes(plain, 3)
    assert "poses" not in plain.sample(4, np.random.default_rng(0))


def test_a_replay_with_poses_refuses_to_sample_unlabelled_frames():
    buffer = EpisodeReplayBuffer(
        50,
        GOALS,
        (feature_agents.ACTIONS,),
        feature_agents.PREVIOUS,
        observation_shape=(feature_agents.FEATURES,),
        extras=(SensorPoses(),),
    )
    one_step_episodes(buffer, 3, labelled=False)
    with pytest.raises(RuntimeError, match="needs labelled frames"):
        buffer.sample(4, np.random.default_rng(0))


# ---------------------------------------------------------------- the split buffer against the one before it
PREVIOUS = 3
MAX_STEPS = 6
CAPACITY = 23  # small: transitions and frames wrap around the rings many times
VECTOR = 7
ACTIONS = 2


def block_sums(images: np.ndarray, labels: np.ndarray | None = None) -> np.ndarray:
    """Features of (B, 1, 100, 100) images: the white pixels of a 4x4 grid of blocks (exact floats)."""
    blocks = (images.reshape(len(images), 4, 25, 4, 25) > 0).sum(axis=(2, 4))
    return blocks.reshape(len(images), 16).astype(np.float32)


def halved_block_sums(images: np.ndarray, labels: np.ndarray | None = None) -> np.ndarray:
    """Another encoder (a refit), of the same size."""
    return 0.5 * block_sums(images)


@dataclass(frozen=True)
class Config:
    """A buffer's settings, and how the episodes that drive it are made."""

    relabel: str = "paper"
    her: bool = True
    vectors: bool = False
    continuous: bool = False
    encoder: bool = False
    poses: bool = False
    kwargs: dict = field(default_factory=dict)

    def make(self, module):
        return module.EpisodeReplayBuffer(
            CAPACITY, GOALS, (ACTIONS,) if self.continuous else (), PREVIOUS, her=self.her,
            max_episode_steps=MAX_STEPS, relabel=self.relabel,
            observation_shape=(VECTOR,) if self.vectors else (100, 100, 1), **self.kwargs,
            **self.poses_option(module),
        )  # fmt: skip

    def poses_option(self, module) -> dict:
        """The frozen buffer takes ``poses``; the current one serves poses as an extra."""
        if module is after:
            return {"extras": (after.SensorPoses(),) if self.poses else ()}
        return {"poses": self.poses}


CONFIGS = {
    "paper": Config(),
    "paper-her-off": Config(her=False),
    "all": Config(relabel="all"),
    "all-her-off": Config(relabel="all", her=False),
    "all-probabilities": Config(relabel="all", kwargs={"relabel_final": 0.7, "relabel_random": 0.2}),
    "vectors-paper-continuous": Config(vectors=True, continuous=True),
    "vectors-all": Config(relabel="all", vectors=True),
    "encoder-all": Config(relabel="all", encoder=True),
    "encoder-paper": Config(encoder=True),
    "poses-all": Config(relabel="all", poses=True),
    "vectors-poses-paper-continuous": Config(vectors=True, continuous=True, poses=True),
}


class Script:
    """Random episodes for ``config``, applied call by call to every buffer of a group.

    Episodes of 1..MAX_STEPS steps end in a press of the wanted key, of another task key, of a key
    outside the task (no achieved goal), or in a time-out; frames are random binary images (or
    vectors), some without labels (none without, for ``poses``).
    """

    def __init__(self, config: Config, seed: int) -> None:
        self.config, self.rng = config, np.random.default_rng(seed)
        self.steps = 0

    def observation(self, goal: int, achieved: int | None = None) -> dict[str, np.ndarray]:
        if self.config.vectors:
            frame = self.rng.normal(size=VECTOR).astype(np.float32)
        else:
            frame = ((self.rng.random((100, 100, 1)) < 0.4) * 255).astype(np.uint8)
        one_hot = np.eye(GOALS, dtype=np.float32)
        return {
            "observation": frame,
            "previous_action": self.rng.normal(size=PREVIOUS).astype(np.float32),
            "desired_goal": one_hot[goal],
            "achieved_goal": one_hot[achieved] if achieved is not None else np.zeros(GOALS, np.float32),
        }

    def label(self) -> np.ndarray | None:
        if not self.config.poses and self.rng.random() < 0.25:
            return None
        pose = self.rng.normal(size=3) * 10
        return np.array([*pose, self.rng.integers(-1, GOALS), self.rng.integers(-1, GOALS)], np.float32)

    def action(self):
        if self.config.continuous:
            return self.rng.uniform(-1, 1, size=ACTIONS).astype(np.float32)
        return int(self.rng.integers(100))

    def start(self, buffers) -> int:
        """Start an episode in every buffer; returns its goal."""
        goal = int(self.rng.integers(GOALS))
        observation, label = self.observation(goal), self.label()
        for buffer in buffers:
            buffer.start_episode(observation, label)
        return goal

    def steps_of(self, buffers, goal: int, steps: int | None = None, end: str | None = None) -> None:
        """Record an episode's steps in every buffer (its last step ends it as ``end`` says)."""
        steps = int(self.rng.integers(1, MAX_STEPS + 1)) if steps is None else steps
        end = str(self.rng.choice(["right", "wrong", "outside", "timeout"])) if end is None else end
        for step in range(steps):
            last = step == steps - 1
            achieved = None
            if last and end == "right":
                achieved = goal
            elif last and end == "wrong":
                achieved = int((goal + self.rng.integers(1, GOALS)) % GOALS)
            terminated = last and end != "timeout"
            reward = float(achieved == goal)
            action, observation, label = self.action(), self.observation(goal, achieved), self.label()
            for buffer in buffers:
                buffer.add_step(action, reward, observation, terminated, label)
            self.steps += 1

    def episode(self, buffers) -> None:
        goal = self.start(buffers)
        self.steps_of(buffers, goal)
        for buffer in buffers:
            buffer.end_episode()


def assert_same_batches(buffers, batch_size: int, seed: int) -> None:
    """Every buffer samples the same batch, bit for bit, and draws as much from its generator."""
    rngs = [np.random.default_rng(seed) for _ in buffers]
    batches = [buffer.sample(batch_size, rng) for buffer, rng in zip(buffers, rngs, strict=True)]
    first = batches[0]
    for batch, rng in zip(batches[1:], rngs[1:], strict=True):
        assert list(batch) == list(first)
        for name in first:
            ours, theirs = batch[name], first[name]
            assert (ours.dtype, ours.shape) == (theirs.dtype, theirs.shape), name
            assert ours.tobytes() == theirs.tobytes(), name
        assert rng.bit_generator.state == rngs[0].bit_generator.state


STATE = (
    "frames", "frame_labels", "frame_index", "previous_actions", "goals", "actions", "rewards", "dones",
    "achieved", "finals", "size", "next_slot", "next_frame", "frames_written", "frame_capacity",
    "capacity", "goal_size", "images", "features",
)  # fmt: skip


def assert_same_state(buffers) -> None:
    """The arrays and counters the buffers show are equal (NaN labels included)."""
    for name in STATE:
        values = [getattr(buffer, name) for buffer in buffers]
        for value in values[1:]:
            if isinstance(values[0], np.ndarray):
                assert (value.dtype, value.shape, value.tobytes()) == (
                    values[0].dtype, values[0].shape, values[0].tobytes(),
                ), name  # fmt: skip
            else:
                assert value == values[0], name


def assert_same_files(paths) -> None:
    """Checkpoint files with the same keys, in order, of the same dtypes, shapes and bytes."""
    opened = [np.load(path) for path in paths]
    try:
        for data in opened[1:]:
            assert data.files == opened[0].files
            for name in data.files:
                ours, theirs = data[name], opened[0][name]
                assert (ours.dtype, ours.shape, ours.tobytes()) == (
                    theirs.dtype,
                    theirs.shape,
                    theirs.tobytes(),
                )
    finally:
        for data in opened:
            data.close()


def check_point(buffers, seed: int) -> None:
    """The buffers show the same state and sample the same batches."""
    assert_same_state(buffers)
    for batch_size in (1, 37):
        assert_same_batches(buffers, batch_size, seed + batch_size)


def loaded_pair(config: Config, files, seed: int, encoder=None):
    """A buffer of each implementation, used first (other episodes; with ``encoder``, if given, whose
    features are then recomputed on load), then loaded from the other's file."""
    pair = [config.make(before), config.make(after)]
    script = Script(config, seed)
    if encoder is not None:
        for buffer in pair:
            buffer.set_encoder(encoder, 16)
    for _ in range(5):
        script.episode(pair)
    old_file, new_file = files
    pair[0].load(new_file)  # the old implementation loads the new one's file
    pair[1].load(old_file)  # and the new one a file written before the split
    return pair


@pytest.mark.parametrize("name", list(CONFIGS))
def test_the_split_buffer_samples_as_the_buffer_before_it(name, tmp_path):
    config = CONFIGS[name]
    buffers = [config.make(before), config.make(after)]
    script = Script(config, seed=sum(map(ord, name)))
    encoder = None
    for episode in range(110):
        if config.encoder and episode in (8, 40):  # first fit, then a refit with an episode in progress
            goal = script.start(buffers)
            script.steps_of(buffers, goal, steps=2, end="timeout")
            encoder = block_sums if episode == 8 else halved_block_sums
            for buffer in buffers:
                buffer.set_encoder(encoder, 16, batch_size=7)
            script.steps_of(buffers, goal, steps=1, end="wrong")
            for buffer in buffers:
                buffer.end_episode()
        else:
            script.episode(buffers)
        check_point(buffers, seed=episode)
        if episode in (3, 60):
            # Checkpoints with an episode in progress (before and after the frame ring wrapped around),
            # each loaded into the other implementation and driven on.
            goal = script.start(buffers)
            script.steps_of(buffers, goal, steps=2, end="timeout")
            assert (buffers[0].frames_written < buffers[0].frame_capacity) == (episode == 3)
            files = [tmp_path / f"old-{episode}.npz", tmp_path / f"new-{episode}.npz"]
            for buffer, path in zip(buffers, files, strict=True):
                buffer.save(path)
            assert_same_files(files)
            loaded = loaded_pair(config, files, seed=episode, encoder=encoder)
            check_point(loaded, seed=1000 + episode)
            # The loaded buffers sample as the saved ones (whose episode in progress was not saved).
            assert_same_batches([*buffers, *loaded], 37, seed=1001 + episode)
            resumed = Script(config, seed=episode + 1)
            for more in range(15):
                resumed.episode(loaded)
                check_point(loaded, seed=2000 + 100 * episode + more)
            script.steps_of(buffers, goal, steps=1, end="right")
            for buffer in buffers:
                buffer.end_episode()
            check_point(buffers, seed=3000 + episode)
    assert script.steps >= 300
    assert buffers[0].frames_written > 2 * buffers[0].frame_capacity  # the frame ring wrapped around
    files = [tmp_path / "old-end.npz", tmp_path / "new-end.npz"]
    for buffer, path in zip(buffers, files, strict=True):
        buffer.save(path)
    assert_same_files(files)
    loaded = loaded_pair(config, files, seed=9, encoder=encoder)
    check_point(loaded, seed=4000)
    assert_same_batches([*buffers, *loaded], 37, seed=4001)


@pytest.mark.parametrize("missing", [("achieved", "finals"), ("frame_labels",)])
def test_older_files_load_alike_into_both(tmp_path, missing):
    config = CONFIGS["all"]
    written = config.make(before)
    script = Script(config, seed=11)
    for _ in range(12):
        script.episode([written])
    written.save(tmp_path / "full.npz")
    with np.load(tmp_path / "full.npz") as data:
        older = {name: data[name] for name in data.files if name not in missing}
    np.savez(tmp_path / "older.npz", **older)
    pair = loaded_pair(config, (tmp_path / "older.npz", tmp_path / "older.npz"), seed=12)
    check_point(pair, seed=13)


def test_both_refuse_the_same_files_and_change_nothing(tmp_path):
    vectors = CONFIGS["vectors-all"]
    written = vectors.make(after)
    Script(vectors, seed=1).episode([written])
    written.save(tmp_path / "vectors.npz")
    for config in (CONFIGS["all"], Config(relabel="all", vectors=True, continuous=True)):
        pair = [config.make(before), config.make(after)]
        script = Script(config, seed=2)
        script.episode(pair)
        kept = [copy.deepcopy(buffer) for buffer in pair]
        messages = []
        for buffer in pair:
            with pytest.raises(ValueError, match="does not fit") as error:
                buffer.load(tmp_path / "vectors.npz")
            messages.append(str(error.value))
        assert messages[0] == messages[1]
        assert_same_state([*pair, *kept])


# ---------------------------------------------------------------- the split buffer's parts
def test_a_frame_store_packs_any_binary_image_shape():
    store = FrameStore(5, (7, 9, 1))
    assert store.images and store.frames.shape == (5, 8) and store.frames.dtype == np.uint8  # 63 bits
    rng = np.random.default_rng(0)
    images = [((rng.random((7, 9, 1)) < 0.5) * 255).astype(np.uint8) for _ in range(7)]
    slots = [store.store(image, None if i % 2 else np.arange(5.0)) for i, image in enumerate(images)]
    assert slots == [0, 1, 2, 3, 4, 0, 1] and store.frames_written == 7 and store.next_frame == 2
    np.testing.assert_array_equal(store.written_slots(), np.arange(5))
    expected = np.stack([image.transpose(2, 0, 1) for image in images[5:] + images[2:5]])
    np.testing.assert_array_equal(store.observations(np.arange(5)), expected)
    shown, poses, pressed, under = store.labelled()  # slots 1, 2, 4 hold the labelled images 6, 2, 4
    np.testing.assert_array_equal(shown, expected[[1, 2, 4]])
    assert poses.shape == (3, 3) and pressed.tolist() == [3] * 3 and under.tolist() == [4] * 3
    assert FrameStore(3).frames.shape == (3, PACKED_BYTES)


def test_a_frame_store_gives_back_stacked_taps_channel_by_channel():
    store = FrameStore(4, (7, 9, 3))
    assert store.frames.shape == (4, 24)  # 189 bits
    rng = np.random.default_rng(1)
    images = [((rng.random((7, 9, 3)) < 0.5) * 255).astype(np.uint8) for _ in range(3)]
    slots = [store.store(image) for image in images]
    shown = store.observations(np.array(slots[::-1]))
    assert shown.shape == (3, 3, 7, 9) and shown.flags.c_contiguous
    for image, back in zip(images[::-1], shown, strict=True):
        for channel in range(3):
            np.testing.assert_array_equal(back[channel], image[..., channel])


@pytest.mark.parametrize("shape", [(10, 10), (100, 100), (100, 100, 0), (0, 5, 1), (5, 0, 1)])
def test_a_frame_store_refuses_other_shapes(shape):
    with pytest.raises(ValueError, match="images or vectors"):
        FrameStore(3, shape)


def test_a_buffer_of_small_images_samples_saves_and_encodes_them(tmp_path):
    buffer = EpisodeReplayBuffer(10, GOALS, (), PREVIOUS, observation_shape=(12, 8, 1), relabel="all")
    rng = np.random.default_rng(0)

    def observation(goal: int = 0) -> dict[str, np.ndarray]:
        return {
            "observation": ((rng.random((12, 8, 1)) < 0.5) * 255).astype(np.uint8),
            "previous_action": np.zeros(PREVIOUS, np.float32),
            "desired_goal": np.eye(GOALS, dtype=np.float32)[goal],
            "achieved_goal": np.zeros(GOALS, np.float32),
        }

    first = observation()
    buffer.start_episode(first, np.arange(5.0))
    second = observation()
    buffer.add_step(1, 0.0, second, False, np.arange(5.0))
    buffer.end_episode()
    batch = buffer.sample(4, np.random.default_rng(1))
    assert batch["images"].shape == (4, 1, 12, 8) and batch["images"].dtype == np.uint8
    np.testing.assert_array_equal(batch["images"][0], first["observation"].transpose(2, 0, 1))
    np.testing.assert_array_equal(batch["next_images"][0], second["observation"].transpose(2, 0, 1))
    assert buffer.labelled_frames()[0].shape == (2, 1, 12, 8)
    buffer.save(tmp_path / "small.npz")
    restored = EpisodeReplayBuffer(10, GOALS, (), PREVIOUS, observation_shape=(12, 8, 1), relabel="all")
    restored.set_encoder(
        lambda images, labels=None: images.reshape(len(images), -1)[:, :3].astype(np.float32), 3
    )
    restored.load(tmp_path / "small.npz")
    features = restored.sample(4, np.random.default_rng(1))["images"]
    np.testing.assert_array_equal(features, batch["images"].reshape(4, -1)[:, :3])
    with pytest.raises(ValueError, match="frames of shape"):
        EpisodeReplayBuffer(10, GOALS, (), PREVIOUS).load(tmp_path / "small.npz")


def test_a_feature_cache_follows_its_encoder():
    store = FrameStore(4)
    cache = FeatureCache(store)
    image = np.full((100, 100, 1), 255, np.uint8)
    cache.add(store.store(image))  # no encoder: nothing to compute
    assert cache.features is None
    cache.set(block_sums, 16)
    np.testing.assert_array_equal(cache.lookup(np.array([0])), np.full((1, 16), 625, np.float32))
    cache.add(store.store(np.zeros_like(image)))
    np.testing.assert_array_equal(cache.lookup(np.array([1, 0]))[:, 0], [0, 625])
    with pytest.raises(ValueError, match="buffer of images"):
        FeatureCache(FrameStore(4, (3,))).set(block_sums, 16)


def test_a_shallow_copy_set_to_images_leaves_the_buffers_features():
    config = CONFIGS["encoder-all"]
    buffer = config.make(after)
    Script(config, seed=0).episode([buffer])
    buffer.set_encoder(block_sums, 16)
    plain = copy.copy(buffer)
    plain.features = None
    assert buffer.features is not None and plain.features is None
    assert buffer.sample(3, np.random.default_rng(0))["images"].shape == (3, 16)
    assert plain.sample(3, np.random.default_rng(0))["images"].shape == (3, 1, 100, 100)


def test_relabelling_strategies_are_chosen_by_name():
    assert RELABELLING == before.RELABELLING == ("paper", "all")
    assert type(make_relabelling("paper")) is PaperRelabelling
    chosen = make_relabelling("all", final=0.3, random=0.5)
    assert isinstance(chosen, SampledRelabelling) and (chosen.final, chosen.random) == (0.3, 0.5)
    for name in RELABELLING:
        assert type(make_relabelling(name, her=False)) is Relabelling
    with pytest.raises(ValueError, match="relabel must be one of"):
        make_relabelling("future")
    assert type(EpisodeReplayBuffer(5, GOALS, (), PREVIOUS, relabel="all").relabelling) is SampledRelabelling
    assert type(EpisodeReplayBuffer(5, GOALS, (), PREVIOUS, her=False).relabelling) is Relabelling


def test_subclasses_still_see_every_frame_stored_through_store_frame():
    """Tests record frames by overriding ``_store_frame`` (``FrameRecordingBuffer``): it stays the
    one path of every frame, with the features cached as it stores them."""

    class Recording(EpisodeReplayBuffer):
        def __init__(self, *args, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            self.slots: list[int] = []

        def _store_frame(self, image, label=None) -> int:
            slot = super()._store_frame(image, label)
            self.slots.append(slot)
            return slot

    config = CONFIGS["encoder-all"]
    buffer = Recording(CAPACITY, GOALS, (), PREVIOUS, max_episode_steps=MAX_STEPS, relabel="all")
    buffer.set_encoder(block_sums, 16)
    script = Script(config, seed=3)
    for _ in range(20):
        script.episode([buffer])
    assert len(buffer.slots) == buffer.frames_written > buffer.frame_capacity
    slots = np.array(buffer.slots[-buffer.frame_capacity :])
    np.testing.assert_array_equal(buffer.features[slots], block_sums(buffer.store.observations(slots)))


# ---------------------------------------------------------------- n-step returns
@pytest.mark.parametrize("relabel", RELABELLING)
def test_n_step_returns_sum_their_episodes_rewards_and_stop_at_its_end(relabel):
    buffer = n_step_buffer(3, relabel)
    feature_episode(buffer, goal=1, pressed=1, steps=5, first_frame=0)  # right press: frames 0-5
    feature_episode(buffer, goal=0, pressed=2, steps=4, first_frame=10)  # wrong press: frames 10-14
    feature_episode(buffer, goal=3, pressed=None, steps=2, first_frame=20)  # time-out: frames 20-22
    lengths = {0: 5, 10: 4, 20: 2}
    batch = buffer.sample(4000, np.random.default_rng(0))
    goals = goal_indices(batch["goals"])
    for t, first, next_frame, goal, reward, done, steps in zip(
        batch["actions"], batch["images"][:, 0], batch["next_images"][:, 0], goals,
        batch["rewards"], batch["dones"], batch["steps"], strict=True,
    ):  # fmt: skip
        start = int(first) - t  # the episode's first frame
        length = lengths[start]
        span = min(length - 1 - t, 2)  # at most 3 steps, never past the episode's end
        assert steps == span + 1 and next_frame == first + span + 1
        reaches_end = t + span == length - 1
        pressed = {0: 1, 10: 2, 20: None}[start]
        assert done == float(reaches_end and pressed is not None)
        assert reward == (0.5**span if reaches_end and pressed == goal else 0.0)
    assert set(batch["steps"].tolist()) == {1.0, 2.0, 3.0}
    assert (batch["rewards"] == 0.25).any() and (batch["rewards"] == 1.0).any()  # discounted and not


def test_one_step_buffers_sample_and_save_as_before_and_n_step_ones_keep_their_windows(tmp_path):
    one, three = n_step_buffer(1), n_step_buffer(3)
    for buffer in (one, three):
        feature_episode(buffer, goal=1, pressed=1, steps=5, first_frame=0)
    assert "steps" not in one.sample(8, np.random.default_rng(0))
    one.save(tmp_path / "one.npz")
    three.save(tmp_path / "three.npz")
    with np.load(tmp_path / "one.npz") as data:
        assert "remaining" not in data.files  # the files one-step runs always wrote
    restored = n_step_buffer(3)
    restored.load(tmp_path / "three.npz")
    np.testing.assert_array_equal(restored.remaining[:5], [4, 3, 2, 1, 0])
    older = n_step_buffer(3)  # a one-step file in an n-step buffer: one-step windows, always valid
    older.load(tmp_path / "one.npz")
    assert (older.sample(64, np.random.default_rng(0))["steps"] == 1).all()


def test_n_step_windows_survive_the_ring_wrapping():
    buffer = n_step_buffer(4, "all", capacity=7)
    for episode in range(5):  # 3 steps each: the ring wraps and the oldest episodes are overwritten
        feature_episode(buffer, goal=0, pressed=0, steps=3, first_frame=10 * episode)
    batch = buffer.sample(500, np.random.default_rng(0))
    first_frames = batch["images"][:, 0] - batch["actions"]
    assert set(first_frames.tolist()) <= {20.0, 30.0, 40.0}  # whole episodes kept, 20's partly
    # Every window ends its episode.
    np.testing.assert_array_equal(batch["next_images"][:, 0], first_frames + 3)


@pytest.mark.parametrize(
    ("n_step", "gamma", "message"),
    [(0, 0.5, "n_step must be at least 1"), (2, None, "need the agent's discount")],
)
def test_n_step_settings_are_checked(n_step, gamma, message):
    with pytest.raises(ValueError, match=message):
        EpisodeReplayBuffer(10, GOALS, (), replay_helpers.PREVIOUS, n_step=n_step, gamma=gamma)
