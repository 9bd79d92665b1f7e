"""The training loop (agents/training.py, run.py, rollout.py, extensions.py): update bursts, checkpoints
and resumes (after kill -9 too), the run's seed, snapshots and world record, and runs with a touch
encoder: labelled frames, the encoder's fits and refits, features in the replay, asymmetric critics,
placed goals and the readout.

The runs are tiny real trainings on the small test datasets (one torch
thread, a few dozen steps, a few passes of the encoder's fit).
"""

from __future__ import annotations

import copy
import importlib
import inspect
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from typing import ClassVar, NamedTuple

import gymnasium
import numpy as np
import pytest
import torch

from agents_helpers import (
    CONTINUOUS_TASK,
    DISCRETE_TASK,
    HIDDEN,
    read_progress_csv,
    same_weights,
    touch_config,
    train_module,
)
from feature_agents import ACTIONS, GOALS, PREVIOUS
from replay_helpers import as_images
from tactile_braille.agents import (
    DiscreteSACConfig,
    DQNAgent,
    DQNConfig,
    EpisodeReplayBuffer,
    SACConfig,
    TD3Config,
    TrainConfig,
    read_progress,
    train,
)
from tactile_braille.agents.common import POSE_SIZE
from tactile_braille.agents.extensions import RunExtension, touch_fit_steps
from tactile_braille.agents.replay import FRAME_LABELS, PACKED_BYTES
from tactile_braille.agents.report import evaluate_run, load_run
from tactile_braille.agents.run import setting_differences
from tactile_braille.agents.touch import TouchAgent
from tactile_braille.agents.training import Episodes, make_env, make_replay
from tactile_braille.evaluation.protocol import paper_sequences
from tactile_braille.evaluation.results import read_result
from tactile_braille.evaluation.runs import (
    LEGACY_VERSION,
    RESULT_FILE,
    TRANSFER_FILE,
    evaluate_transfer,
    evaluate_typing,
    run_result,
)
from tactile_braille.keyboard.layout import ARROW_KEYS, KeyboardLayout
from tactile_braille.supervised.touch import KeyLocator, TouchEncoder, TouchEncoderConfig, fit_touch_encoder

extensions_module = importlib.import_module("tactile_braille.agents.extensions")


pytestmark = pytest.mark.usefixtures("one_torch_thread")


# ---------------------------------------------------------------- update bursts, checkpoints and resumes
class RecordingBuffer(EpisodeReplayBuffer):
    """The replay buffer, noting its size when each step's update check runs, and its samples."""

    made: ClassVar[list[RecordingBuffer]] = []

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.sizes: list[int] = []
        self.samples = 0
        RecordingBuffer.made.append(self)

    def add_step(self, *args, **kwargs) -> None:
        super().add_step(*args, **kwargs)
        self.sizes.append(self.size)

    def end_episode(self) -> None:  # the loop ends an episode right after its last step
        super().end_episode()
        if self.sizes:
            self.sizes[-1] = self.size

    def sample(self, *args, **kwargs):
        self.samples += 1
        return super().sample(*args, **kwargs)


def expected_updates(sizes: list[int], steps_before: int, config: TrainConfig) -> int:
    """The burst rule: at env step k (counted from 1), if k >= start_steps (or update_after, where
    set), k % update_every == 0 and the buffer holds a batch, do update_every * updates_per_step updates."""
    burst = config.update_every * config.updates_per_step
    first = config.start_steps if config.update_after is None else config.update_after
    return sum(
        burst
        for step, size in enumerate(sizes, start=steps_before + 1)
        if step >= first and step % config.update_every == 0 and size >= config.agent.batch_size
    )


def run_files(run) -> dict[str, list[str]]:
    names = sorted(path.name for path in run.iterdir())
    return {
        "events": [name for name in names if name.startswith("events.out.tfevents")],
        "replay": [name for name in names if name.startswith("replay.")],
        "other": [name for name in names if not name.startswith(("events.out.tfevents", "replay."))],
    }


@pytest.fixture
def recording(monkeypatch):
    RecordingBuffer.made = []
    monkeypatch.setattr(train_module, "EpisodeReplayBuffer", RecordingBuffer)
    return RecordingBuffer.made


def test_td3_training_bursts_checkpoints_and_resumes(env_datasets, tmp_path, recording):
    config = TrainConfig(
        task=CONTINUOUS_TASK,
        algo="td3",
        epochs=2,
        steps_per_epoch=30,
        start_steps=10,
        update_every=5,
        threads=1,
        dataset=str(env_datasets[CONTINUOUS_TASK]),
        agent=TD3Config(hidden=(16,), batch_size=8),
        evaluation={"test_episodes": 1},
        replay={"capacity": 500},
    )
    run = train(config, run_dir=tmp_path / "td3", progress=False)
    rows = read_progress(run)
    assert all(isinstance(value, float) for row in rows for value in row.values())
    assert [row["epoch"] for row in rows] == [0.0, 1.0]
    assert [row["env_steps"] for row in rows] == [30.0, 60.0]
    (buffer,) = recording
    assert len(buffer.sizes) == 60
    expected = expected_updates(buffer.sizes, 0, config)
    assert expected > 0  # the buffer filled within the run, so the rule was exercised
    assert rows[-1]["updates"] == expected == buffer.samples
    assert rows[-1]["updates"] % 5 == 0  # whole bursts of update_every * updates_per_step
    assert rows[0]["updates"] == expected_updates(buffer.sizes[:30], 0, config)
    for row in rows:
        if row["updates"] > 0:
            assert math.isfinite(row["losses/qf_loss"]) and math.isfinite(row["losses/q_values"])
    files = run_files(run)
    assert files["replay"] == ["replay.1.npz"]
    assert files["other"] == [
        ".lock",
        "checkpoint.pt",
        "config.json",
        "progress.csv",
        "snapshots",
        "world.json",
    ]
    assert sorted(p.name for p in (run / "snapshots").iterdir()) == ["epoch_0000.pt", "epoch_0001.pt"]
    assert len(files["events"]) >= 1

    data = json.loads((run / "config.json").read_text())
    data["epochs"] = 3
    (run / "config.json").write_text(json.dumps(data))
    # The episode in progress at the checkpoint is played again into the replay first.
    replayed = len(torch.load(run / "checkpoint.pt", weights_only=False)["episode"]["actions"])
    train(run_dir=run, resume=True, progress=False)
    rows = read_progress(run)
    assert [row["epoch"] for row in rows] == [0.0, 1.0, 2.0]
    assert rows[-1]["env_steps"] == 90.0
    resumed = recording[-1]
    assert len(resumed.sizes) == replayed + 30
    more = expected_updates(resumed.sizes[replayed:], 60, config)
    assert rows[-1]["updates"] == expected + more
    assert resumed.samples == more
    assert run_files(run)["replay"] == ["replay.2.npz"]
    assert torch.load(run / "checkpoint.pt", weights_only=False)["epoch"] == 2


def test_sac_bf16_training_logs_finite_losses(env_datasets, tmp_path, recording):
    config = TrainConfig(
        task=CONTINUOUS_TASK,
        algo="sac",
        epochs=1,
        steps_per_epoch=40,
        start_steps=10,
        threads=1,
        precision="bf16",
        dataset=str(env_datasets[CONTINUOUS_TASK]),
        agent=SACConfig(hidden=(64,), batch_size=8),
        evaluation={"test_episodes": 1},
        replay={"capacity": 500},
    )
    run = train(config, run_dir=tmp_path / "sac", progress=False)
    (row,) = read_progress(run)
    (buffer,) = recording
    assert row["updates"] == expected_updates(buffer.sizes, 0, config) == buffer.samples
    assert row["updates"] > 0 and row["updates"] % 2 == 0  # bursts of updates_per_step = 2
    for name in ("losses/qf_loss", "losses/actor_loss", "losses/alpha", "losses/entropy"):
        assert math.isfinite(row[name]), name
    assert "losses/q_loss" not in row  # the log names the losses its agent returns: not DQN's
    assert 0.0 <= row["test/success_rate"] <= 1.0
    files = run_files(run)
    assert files["replay"] == ["replay.0.npz"] and len(files["events"]) >= 1
    assert json.loads((run / "config.json").read_text())["precision"] == "bf16"


@pytest.mark.parametrize("algo", ["dqn", "sac_discrete", "sac"])
def test_an_all_goals_run_replays_the_pressed_keys_and_learns_every_goal(
    env_datasets, tmp_path, recording, algo
):
    task = CONTINUOUS_TASK if algo == "sac" else DISCRETE_TASK
    heads = {} if algo == "sac" else {"goal_heads": True}  # SAC's goal is an input
    agent_config = {"dqn": DQNConfig, "sac_discrete": DiscreteSACConfig, "sac": SACConfig}[algo]
    config = TrainConfig(
        task=task,
        algo=algo,
        epochs=1,
        steps_per_epoch=40,
        start_steps=10,
        threads=1,
        dataset=str(env_datasets[task]),
        agent=agent_config(hidden=(64,), batch_size=8, all_goals=True, **heads),
        evaluation={"test_episodes": 1},
        replay={"capacity": 500, "relabel": "all"},
    )
    run = train(config, run_dir=tmp_path / "all-goals", progress=False)
    (row,) = read_progress(run)
    (buffer,) = recording
    # The agent's replay serves every goal's outcome: its batches carry the pressed keys and goal weights.
    assert [type(extra).__name__ for extra in buffer.extras] == ["GoalOutcomes"]
    loss = "losses/q_loss" if algo == "dqn" else "losses/qf_loss"
    assert row["updates"] == buffer.samples > 0 and math.isfinite(row[loss])
    assert json.loads((run / "config.json").read_text())["agent"]["all_goals"] is True


def test_updates_start_after_update_after_steps_where_set_as_the_released_code(
    env_datasets, tmp_path, recording
):
    """The paper's runs update after their random start steps; the released code from its first step
    (``update_after=1``: from the step its replay holds a batch)."""
    runs = {}
    for update_after in (None, 1):
        config = TrainConfig(
            task=DISCRETE_TASK,
            epochs=1,
            steps_per_epoch=40,
            start_steps=30,
            update_after=update_after,
            threads=1,
            dataset=str(env_datasets[DISCRETE_TASK]),
            agent=DQNConfig(hidden=(16,), batch_size=8),
            evaluation={"test_episodes": 1},
        )
        run = train(config, run_dir=tmp_path / f"after-{update_after}", progress=False)
        buffer = recording[-1]
        (row,) = read_progress(run)
        assert row["updates"] == buffer.samples == expected_updates(buffer.sizes, 0, config)
        runs[update_after] = row["updates"]
    assert runs[None] == 2 * (40 - 30 + 1)  # steps 30-40, two updates each
    assert runs[1] - runs[None] >= 2 * 20  # and in most start steps too, once the replay held a batch


def test_td3_progress_logs_the_actor_loss_whenever_the_actor_learned(env_datasets, tmp_path):
    config = TrainConfig(
        task=CONTINUOUS_TASK,
        algo="td3",
        epochs=1,
        steps_per_epoch=5,
        start_steps=5,
        update_every=5,
        max_episode_steps=1,
        threads=1,
        dataset=str(env_datasets[CONTINUOUS_TASK]),
        agent=TD3Config(hidden=HIDDEN, batch_size=1),
        evaluation={"test_episodes": 1},
        replay={"capacity": 100},
    )
    (row,) = read_progress(train(config, run_dir=tmp_path / "td3", progress=False))
    if row["updates"] != 5:  # not an assertion: a broken setup must fail, not pass as the known bug
        raise RuntimeError(f"expected one burst of 5 updates, got {row['updates']}")
    assert math.isfinite(row["losses/qf_loss"])
    assert math.isfinite(row["losses/actor_loss"])  # updates 2 and 4 of the 5 trained the actor


def test_resume_after_kill_completes_every_epoch_once(env_datasets, tmp_path):
    run_dir = tmp_path / "run"
    dataset = str(env_datasets["tactile_braille/DiscreteArrows-v0"])
    script = (
        "from tactile_braille.agents import TrainConfig, train\n"
        f"config = TrainConfig(epochs=4, steps_per_epoch=60, start_steps=30, updates_per_step=1, "
        "agent={'batch_size': 8, 'hidden': (16,)}, "
        f"evaluation={{'test_episodes': 2}}, replay={{'capacity': 2000}}, dataset={dataset!r}, threads=1)\n"
        f"train(config, run_dir={str(run_dir)!r}, progress=False)\n"
    )
    child = subprocess.Popen(
        [sys.executable, "-c", script], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    deadline = time.monotonic() + 120
    try:
        while not (run_dir / "progress.csv").exists() or len(read_progress_csv(run_dir)) < 1:
            if child.poll() is not None:
                pytest.fail(f"the run ended before it was killed: {child.stderr.read().decode()}")
            if time.monotonic() > deadline:
                pytest.fail("no epoch was checkpointed within 120 s")
            time.sleep(0.05)
        os.kill(child.pid, signal.SIGKILL)
        child.wait()
    finally:
        if child.poll() is None:
            child.kill()
    done_before = len(read_progress_csv(run_dir))
    assert 1 <= done_before < 4
    train(run_dir=run_dir, resume=True, progress=False)
    rows = read_progress_csv(run_dir)
    assert [int(r["epoch"]) for r in rows] == [0, 1, 2, 3]
    steps = [int(r["env_steps"]) for r in rows]
    assert steps == [60, 120, 180, 240]  # nothing counted twice, nothing lost before the checkpoint
    with pytest.raises(FileExistsError):
        train(TrainConfig(dataset=dataset), run_dir=run_dir, progress=False)


def test_discrete_sac_trains_checkpoints_and_resumes(env_datasets, tmp_path):
    """A short discrete-SAC run: finite losses logged, a checkpoint that resumes to more epochs."""
    dataset = str(env_datasets["tactile_braille/DiscreteArrows-v0"])
    config = TrainConfig(
        agent={"batch_size": 8, "hidden": (16,)},  # a small agent: the test is of the loop, not of learning
        algo="sac_discrete",
        epochs=1,
        steps_per_epoch=60,
        start_steps=20,
        updates_per_step=1,
        dataset=dataset,
        threads=1,
        evaluation={"test_episodes": 2},
        replay={"capacity": 2000},
    )
    run = train(config, run_dir=tmp_path / "run", progress=False)
    (row,) = read_progress_csv(run)
    for name in ("losses/qf_loss", "losses/actor_loss", "losses/alpha", "losses/entropy"):
        assert np.isfinite(float(row[name])), name
    assert 0.0 < float(row["losses/entropy"]) <= np.log(5) + 1e-6
    config_file = run / "config.json"
    data = json.loads(config_file.read_text())
    assert data["agent"]["gamma"] == 0.6  # the paper's discount for discrete SAC
    data["epochs"] = 2
    config_file.write_text(json.dumps(data))
    train(run_dir=run, resume=True, progress=False)
    assert [int(r["epoch"]) for r in read_progress_csv(run)] == [0, 1]


# ---------------------------------------------------------------- the run's seed, snapshots and world
def test_the_run_seed_fixes_the_initial_weights(env_datasets, tmp_path):
    dataset = str(env_datasets["tactile_braille/DiscreteArrows-v0"])

    def first_weights(seed: int, name: str) -> torch.Tensor:
        config = TrainConfig(
            seed=seed,
            epochs=1,
            steps_per_epoch=5,
            start_steps=5,
            dataset=dataset,
            threads=1,
            agent=DQNConfig(hidden=(16,)),
            evaluation={"test_episodes": 1, "snapshots": 1},
            replay={"capacity": 100},
        )
        torch.manual_seed(1234 + len(name))  # whatever the global generator holds before
        run = train(config, run_dir=tmp_path / name, progress=False)
        snapshot = torch.load(run / "snapshots" / "epoch_0000.pt", weights_only=False)
        return snapshot["q"]["trunk.encoder.layers.0.weight"]

    assert torch.equal(first_weights(0, "a"), first_weights(0, "bb"))  # no update ran: initial weights
    assert not torch.equal(first_weights(0, "c"), first_weights(1, "d"))


def test_snapshot_epochs_spread_from_first_to_last():
    from tactile_braille.agents.run import snapshot_epochs

    assert snapshot_epochs(25, 3) == {0, 12, 24}
    assert snapshot_epochs(2, 3) == {0, 1}
    assert snapshot_epochs(10, 0) == set()


def test_a_run_records_its_world_and_resumes_only_in_it(env_datasets, tmp_path):
    from tactile_braille.datasets import GENERATOR_VERSION
    from tactile_braille.evaluation.report import load_records
    from tactile_braille.keyboard.switch import SwitchModel

    dataset = str(env_datasets["tactile_braille/DiscreteArrows-v0"])
    config = TrainConfig(
        agent={"batch_size": 8, "hidden": (16,)},  # a small agent: the test is of the loop, not of learning
        epochs=1,
        steps_per_epoch=40,
        start_steps=20,
        updates_per_step=1,
        dataset=dataset,
        threads=1,
        evaluation={"test_episodes": 2},
        replay={"capacity": 500},
    )
    run = train(config, run_dir=tmp_path / "run", progress=False)
    world = json.loads((run / "world.json").read_text())
    assert world["backend"] == "dataset" and world["dataset"] == dataset
    assert world["procedure"]["procedure"] == "perturbed" and world["seed"] == 0
    assert world["generator_version"] == GENERATOR_VERSION
    assert SwitchModel(**world["keyboard"]["switch"]) == SwitchModel()
    (record,) = load_records([run], evaluate_missing=False)
    assert "world" not in record.variant  # the present world goes without saying

    # A resume in another world is refused before anything changes.
    data = json.loads((run / "config.json").read_text())
    data["epochs"] = 2
    (run / "config.json").write_text(json.dumps(data))
    progress = (run / "progress.csv").read_text()
    other_switch = json.loads(json.dumps(world))
    other_switch["keyboard"]["switch"]["travel_offsets_mm"] = [["A", 0.3]]
    (run / "world.json").write_text(json.dumps({**other_switch, "dataset": "/elsewhere/keys.h5"}))
    refused = r"another world than this one \(keyboard\.switch\.travel_offsets_mm: .* -> "
    with pytest.raises(ValueError, match=refused):
        train(run_dir=run, resume=True, progress=False)  # the same generator, another switch
    (run / "world.json").write_text(json.dumps({**world, "generator_version": "0.0.1+samples1"}))
    with pytest.raises(ValueError, match=r'generator_version: "0.0.1\+samples1" -> '):
        train(run_dir=run, resume=True, progress=False)
    assert (run / "progress.csv").read_text() == progress
    (record,) = load_records([run], evaluate_missing=False)
    assert "world 0.0.1+samples1" in record.variant

    # The same world with its dataset at another path resumes.
    (run / "world.json").write_text(json.dumps({**world, "dataset": "/elsewhere/keys.h5"}))
    train(run_dir=run, resume=True, progress=False)
    assert [int(r["epoch"]) for r in read_progress_csv(run)] == [0, 1]

    # A run from before worlds were recorded resumes without a record being invented for it.
    (run / "world.json").unlink()
    (record,) = load_records([run], evaluate_missing=False)
    assert "earlier world" in record.variant
    data["epochs"] = 3
    (run / "config.json").write_text(json.dumps(data))
    train(run_dir=run, resume=True, progress=False)
    assert [int(r["epoch"]) for r in read_progress_csv(run)] == [0, 1, 2]
    assert not (run / "world.json").exists()


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


def unpack(packed: np.ndarray) -> np.ndarray:
    """Bit-packed frames of a replay file as (N, 1, 100, 100) uint8 images."""
    return (np.unpackbits(packed, axis=-1).reshape(-1, 1, 100, 100) * 255).astype(np.uint8)


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
    # The benchmark's results file: the same report, in the run's track, under its fingerprint.
    result = read_result(run / RESULT_FILE)
    assert result["track"] == "proprio" and result["fingerprint"] == typing["fingerprint"]
    assert result["report"]["accuracy"] == typing["accuracy"] and result["budget"]["epochs"] == 1
    # A results file written with its typing.json is not guessed when lost ...
    (run / RESULT_FILE).unlink()
    with pytest.raises(ValueError, match=r"lacks the result\.json of its typing evaluation"):
        run_result(run)
    # ... but a record archived before results files existed gets one made from its typing.json.
    old = {k: v for k, v in typing.items() if k not in ("fingerprint", "typing_seed", "touch_optimum")}
    (run / "typing.json").write_text(json.dumps(old))
    derived = run_result(run)
    assert derived["report"]["conditions"] == {
        **result["report"]["conditions"],
        "project_version": LEGACY_VERSION,
    }
    assert {k: derived["report"][k] for k in ("accuracy", "total_steps", "confusion", "touch_optimum")} == {
        k: result["report"][k] for k in ("accuracy", "total_steps", "confusion", "touch_optimum")
    }


def test_transfer_evaluation_types_in_another_world_and_keeps_the_others(touch_runs, monkeypatch):
    run, _, _ = touch_runs["sac"]
    # The plumbing, not the policy, is under test: type the first of the paper's sequences only.
    import tactile_braille.evaluation.scoring as scoring

    monkeypatch.setattr(scoring, "paper_sequences", lambda keys: paper_sequences(keys)[:1])
    with pytest.raises(ValueError, match="unknown world 'grid'"):
        evaluate_transfer(run, ["frame:+1,0,+2", "grid"])
    assert not (run / TRANSFER_FILE).exists()  # refused before anything ran
    # An earlier evaluation of the same checkpoint in another world stays in the file.
    earlier = {"checkpoint_epoch": 0, "typing_seed": 0, "worlds": {"render": {"accuracy": 0.5}}}
    (run / TRANSFER_FILE).write_text(json.dumps(earlier))
    output = evaluate_transfer(run, ["frame:+1,0,+2"])
    assert output == json.loads((run / TRANSFER_FILE).read_text())
    assert output["worlds"]["render"] == {"accuracy": 0.5}
    scored = output["worlds"]["frame:+1,0,+2"]
    assert scored["keys_asked"] == len(paper_sequences("arrows")[0]) and 0.0 <= scored["accuracy"] <= 1.0
    assert scored["world"]["backend"] == "rig" and scored["world"]["work_frame_error"]["rotation_deg"] == 2.0
    assert scored["world"]["sensor"]["name"] == "braille_331"  # the run's own sensor


def test_a_run_in_the_released_simulators_world_keeps_its_edge_in_every_transfer_world(
    touch_runs, monkeypatch, tmp_path
):
    run, _, _ = touch_runs["sac"]
    import tactile_braille.evaluation.scoring as scoring

    monkeypatch.setattr(scoring, "paper_sequences", lambda keys: paper_sequences(keys)[:1])
    overrun = tmp_path / "overrun"
    shutil.copytree(run, overrun)
    (overrun / TRANSFER_FILE).unlink(missing_ok=True)
    config = json.loads((overrun / "config.json").read_text())
    (overrun / "config.json").write_text(json.dumps({**config, "edges": "overrun"}))
    scored = evaluate_transfer(overrun, ["frame:+1,0,+2"])["worlds"]["frame:+1,0,+2"]
    assert scored["world"]["edges"] == "overrun" and "tap_depth" not in scored["world"]  # a grid's lookup


# ---------------------------------------------------------------- asymmetric critics, placed goals, readout
def test_a_touch_run_trains_asymmetric_critics_on_the_labelled_poses(env_datasets, tmp_path):
    seen = []
    original = TouchAgent.update

    def recording_update(self, data):
        seen.append(data)
        return original(self, data)

    config = TrainConfig(
        task=CONTINUOUS_TASK,
        algo="sac",
        epochs=1,
        steps_per_epoch=30,
        start_steps=12,
        threads=1,
        dataset=str(env_datasets[CONTINUOUS_TASK]),
        agent=SACConfig(hidden=(16,), batch_size=8, critic_pose=True),
        evaluation={"test_episodes": 1, "snapshots": 1},
        replay={"capacity": 200},
        track="proprio",
        touch={"enabled": True, "epochs": 2},
    )
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(TouchAgent, "update", recording_update)
        run = train_module.train(config, run_dir=tmp_path / "run", progress=False)
    (row,) = read_progress(run)
    assert len(seen) == row["updates"] > 0
    for data in seen:
        assert data["poses"].shape == data["next_poses"].shape == (8, POSE_SIZE)
        # Work-frame poses of the arrow task, in mm: x in [-20, 0] around the block, depths 2..8 mm.
        assert (
            np.isfinite(data["poses"]).all()
            and ((data["poses"][:, 2] >= 2) & (data["poses"][:, 2] <= 8)).all()
        )
    _, _, agent = load_run(run)
    assert agent.agent.config.critic_pose and agent.agent.critics[0].pose_size == POSE_SIZE


def test_a_run_with_placed_goals_acts_on_env_observations_and_learns_on_placed_goals(env_datasets, tmp_path):
    config = TrainConfig(
        task=CONTINUOUS_TASK,
        algo="sac",
        epochs=1,
        steps_per_epoch=30,
        start_steps=12,
        threads=1,
        dataset=str(env_datasets[CONTINUOUS_TASK]),
        agent=SACConfig(hidden=(16,), batch_size=8, critic_pose=True),
        evaluation={"test_episodes": 2, "snapshots": 1},
        replay={"capacity": 200},
        track="proprio",
        touch={"enabled": True, "epochs": 2, "goal_positions": True},
    )
    run = train_module.train(config, run_dir=tmp_path / "run", progress=False)
    _, env, agent = load_run(run)
    layout = env.unwrapped.layout
    expected = np.array([layout.centre_mm(key) for key in env.unwrapped.goal_keys], np.float32)
    np.testing.assert_array_equal(agent.key_positions_mm, expected)
    observation, _ = env.reset(seed=0)
    assert observation["desired_goal"].shape == (GOALS,)  # the environment is unchanged
    placed = agent.features(observation)["desired_goal"]
    goal = int(observation["desired_goal"].argmax())
    mean, scale = agent.touch.pose_mean.numpy()[:2], agent.touch.pose_scale.numpy()[:2]
    np.testing.assert_allclose(placed[GOALS:] * scale + mean, expected[goal], rtol=1e-5)
    assert agent.policy_action(observation, 0, explore=False, rng=np.random.default_rng(0)).shape == (
        ACTIONS,
    )


def test_a_run_on_the_readout_learns_and_acts_on_it(env_datasets, tmp_path):
    config = TrainConfig(
        task=CONTINUOUS_TASK,
        algo="sac",
        epochs=1,
        steps_per_epoch=30,
        start_steps=12,
        threads=1,
        dataset=str(env_datasets[CONTINUOUS_TASK]),
        agent=SACConfig(hidden=(16,), batch_size=8),
        evaluation={"test_episodes": 2, "snapshots": 1},
        replay={"capacity": 200},
        track="proprio",
        touch={"enabled": True, "epochs": 2, "inputs": "readout"},
    )
    run = train_module.train(config, run_dir=tmp_path / "run", progress=False)
    _, env, agent = load_run(run)
    assert agent.inputs == "readout" and agent.agent.actor.trunk.dense[0].in_features == (
        agent.touch.readout_size + GOALS + PREVIOUS
    )
    observation, _ = env.reset(seed=0)
    np.testing.assert_array_equal(
        agent.features(observation)["observation"], agent.touch.read(observation["observation"][None])[0]
    )
    assert agent.policy_action(observation, 0, explore=False, rng=np.random.default_rng(0)).shape == (
        ACTIONS,
    )
    with pytest.raises(ValueError, match=r"TouchConfig.inputs must be one of"):
        config.with_changes(touch={"inputs": "pixels"})


def test_a_run_with_every_addition_resumes_on_its_readout(env_datasets, tmp_path):
    sizes = []
    original = EpisodeReplayBuffer.set_encoder

    def recording_set_encoder(self, encode, size, *args, **kwargs):
        sizes.append(size)
        return original(self, encode, size, *args, **kwargs)

    config = TrainConfig(
        task=CONTINUOUS_TASK,
        algo="sac",
        epochs=2,
        steps_per_epoch=20,
        start_steps=12,
        threads=1,
        dataset=str(env_datasets[CONTINUOUS_TASK]),
        agent=SACConfig(hidden=(16,), batch_size=8, critic_pose=True),
        evaluation={"test_episodes": 1, "snapshots": 1},
        replay={"capacity": 200},
        track="proprio",
        touch={
            "enabled": True,
            "epochs": 2,
            "refits": 1,
            "refit_every": 20,
            "goal_positions": True,
            "inputs": "readout",
        },
    )
    run = tmp_path / "run"
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(EpisodeReplayBuffer, "set_encoder", recording_set_encoder)
        train_module.train(config, run_dir=run, progress=False)
        before = torch.load(run / "checkpoint.pt", weights_only=False)["agent"]
        stored = json.loads((run / "config.json").read_text())
        stored["epochs"] = 3
        (run / "config.json").write_text(json.dumps(stored))
        train_module.train(run_dir=run, resume=True, progress=False)
    readout = TouchEncoder(GOALS).readout_size
    assert sizes == [readout] * len(sizes) and len(sizes) == 3  # the first fit, the refit, the resume
    assert [row["epoch"] for row in read_progress(run)] == [0, 1, 2]
    assert setting_differences(run, config) == []
    _, _, agent = load_run(run)
    after = agent.state_dict()
    assert not torch.equal(before["critics"]["0.q.weight"], after["critics"]["0.q.weight"])  # it learnt on
    assert agent.inputs == "readout" and agent.key_positions_mm is not None and agent.agent.config.critic_pose


def test_a_rig_handed_to_a_run_on_the_dataset_is_refused_before_the_folder_is_written(env_datasets, tmp_path):
    """The trap of old: a robot connected, then ignored while the run trained on the dataset."""
    from tactile_braille.rigs.virtual import VirtualRig

    config = TrainConfig(dataset=str(env_datasets["tactile_braille/DiscreteArrows-v0"]), threads=1)
    with pytest.raises(ValueError, match="backend is 'dataset': set backend='rig'"):
        train(config, run_dir=tmp_path / "run", progress=False, rig=VirtualRig())
    assert not (tmp_path / "run").exists()


def test_a_run_with_tap_memory_replays_stacked_taps_resumes_and_is_evaluated_with_them(
    env_datasets, tmp_path, recording
):
    config = TrainConfig(
        task=CONTINUOUS_TASK, algo="sac", epochs=1, steps_per_epoch=40, start_steps=10, threads=1, taps=2,
        dataset=str(env_datasets[CONTINUOUS_TASK]), agent=SACConfig(hidden=(64,), batch_size=8),
        evaluation={"test_episodes": 1}, replay={"capacity": 500},
    )  # fmt: skip
    run = train(config, run_dir=tmp_path / "taps", progress=False)
    run = train(config.with_changes(epochs=2), run_dir=run, resume=True, progress=False)
    assert [row["epoch"] for row in read_progress(run)] == [0, 1]
    buffer = recording[-1]
    assert buffer.samples > 0 and buffer.store.image_shape == (2, 100, 100)
    batch = buffer.sample(64, np.random.default_rng(0))
    assert batch["images"].shape == (64, 2, 100, 100)
    assert batch["previous_actions"].shape == (64, 3)  # one action: the move between the two taps
    # A transition's next observation remembers the tap its observation made last.
    np.testing.assert_array_equal(batch["next_images"][:, 0], batch["images"][:, 1])
    _, env, agent = load_run(run)
    assert env.observation_space["observation"].shape == (100, 100, 2)
    assert agent.actor.trunk.encoder.layers[0].in_channels == 2
    assert 0.0 <= evaluate_run(run, episodes=2)["test/success_rate"] <= 1.0


class PoseLog(gymnasium.Wrapper):
    """Where each episode starts and where each step leaves the sensor (``info``'s pose)."""

    def __init__(self, env):
        super().__init__(env)
        self.starts, self.ends = [], []

    def reset(self, **kwargs):
        observation, info = self.env.reset(**kwargs)
        self.starts.append(np.array(info["sensor_pose_mm"]))
        self.ends.append(self.starts[-1])
        return observation, info

    def step(self, action):
        result = self.env.step(action)
        self.ends[-1] = np.array(result[-1]["sensor_pose_mm"])
        return result


@pytest.mark.parametrize("fraction", [0.0, 0.5, 1.0])
def test_episodes_start_where_the_last_one_left_the_sensor_at_the_kept_share(env_datasets, fraction):
    config = TrainConfig(dataset=str(env_datasets[DISCRETE_TASK]), threads=1, keep_pose_fraction=fraction)
    env = PoseLog(make_env(config))
    episodes = Episodes(env, make_replay(config, env), RunExtension(), np.random.default_rng(0), fraction)
    rng = np.random.default_rng(1)
    for _ in range(400):
        episodes.step(int(rng.integers(env.action_space.n)))
    # Kept: the sensor's x and y where the last episode ended (the new tap is light where a press was deep).
    kept = [np.allclose(start[:2], end[:2]) for start, end in zip(env.starts[1:], env.ends[:-1], strict=True)]
    assert len(kept) > 40 and episodes.kept_starts <= sum(kept)
    if fraction == 0.0:
        assert episodes.kept_starts == 0 and sum(kept) < len(kept) / 4  # random starts, a few on the spot
    elif fraction == 1.0:
        assert episodes.kept_starts == len(kept) and all(kept)
    else:
        assert 0.3 < episodes.kept_starts / len(kept) < 0.7


class ActionLog(gymnasium.Wrapper):
    """The actions each episode was stepped with, as the environment received them."""

    def __init__(self, env):
        super().__init__(env)
        self.episodes = []

    def reset(self, **kwargs):
        self.episodes.append([])
        return self.env.reset(**kwargs)

    def step(self, action):
        self.episodes[-1].append(np.array(action, copy=True))
        return self.env.step(action)


@pytest.mark.parametrize("task", [DISCRETE_TASK, CONTINUOUS_TASK])
@pytest.mark.parametrize("final_press", [False, True])
def test_a_final_press_ends_each_episode_the_time_limit_would_cut(env_datasets, task, final_press):
    algo = "dqn" if task == DISCRETE_TASK else "sac"
    dataset = str(env_datasets[task])
    config = TrainConfig(task=task, algo=algo, dataset=dataset, threads=1, final_press=final_press)
    env = ActionLog(make_env(config))
    replay, rng = make_replay(config, env), np.random.default_rng(1)
    episodes = Episodes(env, replay, RunExtension(), np.random.default_rng(0), 0.0, final_press)
    for _ in range(300):  # moves and light taps only: no episode ends by itself
        move = np.array([*rng.uniform(-1, 1, 2), -1.0], "f4")
        episodes.step(int(rng.integers(4)) if algo == "dqn" else move)
    done = env.episodes[:-1]
    assert len(done) == 12 and all(len(actions) == 25 for actions in done)
    pressed = [actions[-1] == 4 if algo == "dqn" else actions[-1][2] == 1.0 for actions in done]
    assert all(pressed) if final_press else not any(pressed)
    assert episodes.final_presses == (12 if final_press else 0)
    if algo == "sac":  # the press keeps the move that was asked
        assert all(np.all(np.abs(actions[-1][:2]) <= 1.0) and actions[-1][:2].any() for actions in done)
    for actions in done:  # only the last step is changed
        assert all((a != 4) if algo == "dqn" else a[2] == -1.0 for a in actions[:-1])


def test_a_run_with_final_presses_trains_and_records_the_setting(env_datasets, tmp_path):
    config = TrainConfig(
        dataset=str(env_datasets[DISCRETE_TASK]), epochs=1, steps_per_epoch=60, start_steps=10, threads=1,
        final_press=True, agent=DQNConfig(hidden=HIDDEN, batch_size=8), evaluation={"test_episodes": 1},
    )  # fmt: skip
    run = train(config, run_dir=tmp_path / "pressed", progress=False)
    assert json.loads((run / "config.json").read_text())["final_press"] is True
    assert read_progress(run)[0]["train/episodes"] >= 60 // 25


def test_a_run_with_shifted_images_trains_and_records_the_setting(env_datasets, tmp_path):
    config = TrainConfig(
        dataset=str(env_datasets[DISCRETE_TASK]), epochs=1, steps_per_epoch=40, start_steps=10, threads=1,
        replay={"shift": 4}, agent=DQNConfig(hidden=HIDDEN, batch_size=8), evaluation={"test_episodes": 1},
    )  # fmt: skip
    run = train(config, run_dir=tmp_path / "shifted", progress=False)
    assert json.loads((run / "config.json").read_text())["replay"]["shift"] == 4
    assert read_progress(run)[0]["updates"] > 0


def test_a_run_that_keeps_poses_trains_resumes_and_names_the_setting(env_datasets, tmp_path):
    config = TrainConfig(
        dataset=str(env_datasets[DISCRETE_TASK]), epochs=1, steps_per_epoch=40, start_steps=10, threads=1,
        keep_pose_fraction=0.5, agent=DQNConfig(hidden=HIDDEN, batch_size=8), evaluation={"test_episodes": 1},
    )  # fmt: skip
    run = train(config, run_dir=tmp_path / "kept", progress=False)
    run = train(config.with_changes(epochs=2), run_dir=run, resume=True, progress=False)
    assert [row["epoch"] for row in read_progress(run)] == [0, 1]
    assert json.loads((run / "config.json").read_text())["keep_pose_fraction"] == 0.5
    with pytest.raises(ValueError, match="keep_pose_fraction"):
        train(config.with_changes(epochs=3, keep_pose_fraction=0.0), run_dir=run, resume=True, progress=False)
