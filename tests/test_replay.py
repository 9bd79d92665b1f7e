"""The replay buffer split into a frame store, a relabelling strategy and a feature cache.

The split buffer is checked against a frozen copy of the implementation before the split
(``tests/_replay_before.py``): both are driven with the same random episodes, and every sampled
batch must be equal bit for bit, the sampling generators left in the same state, and the
checkpoint files of each must load into the other.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np
import pytest

import _replay_before as before
from tactile_braille.agents import replay as after
from tactile_braille.agents.replay import (
    PACKED_BYTES,
    RELABELLING,
    EpisodeReplayBuffer,
    FeatureCache,
    FrameStore,
    PaperRelabelling,
    Relabelling,
    SampledRelabelling,
    make_relabelling,
)

GOALS = 4
PREVIOUS = 3
MAX_STEPS = 6
CAPACITY = 23  # small: transitions and frames wrap around the rings many times
VECTOR = 7
ACTIONS = 2


# ---------------------------------------------------------------- a deterministic encoder
def block_sums(images: np.ndarray) -> np.ndarray:
    """Features of (B, 1, 100, 100) images: the white pixels of a 4x4 grid of blocks (exact floats)."""
    blocks = (images.reshape(len(images), 4, 25, 4, 25) > 0).sum(axis=(2, 4))
    return blocks.reshape(len(images), 16).astype(np.float32)


def halved_block_sums(images: np.ndarray) -> np.ndarray:
    """Another encoder (a refit), of the same size."""
    return 0.5 * block_sums(images)


# ---------------------------------------------------------------- driving both implementations
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
            observation_shape=(VECTOR,) if self.vectors else (100, 100, 1), poses=self.poses, **self.kwargs,
        )  # fmt: skip


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


# ---------------------------------------------------------------- the parts
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


@pytest.mark.parametrize("shape", [(10, 10), (100, 100), (100, 100, 3), (0, 5, 1), (5, 0, 1)])
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
    restored.set_encoder(lambda images: images.reshape(len(images), -1)[:, :3].astype(np.float32), 3)
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
