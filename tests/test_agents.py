"""Agents: the HER replay buffer, DQN learning with HER, checkpoints that survive kill -9."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from tactile_braille.agents import EpisodeReplayBuffer, TrainConfig, train

GOALS = 4


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


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"task": "tactile_braille/Piano-v0"}, "unknown task"),
        ({"task": "tactile_braille/ContinuousArrows-v0"}, "discrete task"),
        ({"algo": "ppo"}, "unknown algorithm"),
        ({"epochs": 0}, "epochs"),
    ],
)
def test_train_config_rejects_bad_settings(kwargs, message):
    with pytest.raises(ValueError, match=message):
        TrainConfig(**kwargs)


def read_progress(run_dir) -> list[dict]:
    with open(run_dir / "progress.csv", newline="") as handle:
        return list(csv.DictReader(handle))


@pytest.mark.slow
def test_dqn_with_her_solves_discrete_arrows(env_datasets, tmp_path):
    """A real learning run (about a minute): the paper's DQN + HER, one update per step."""
    config = TrainConfig(
        task="tactile_braille/DiscreteArrows-v0",
        epochs=6,
        updates_per_step=1,
        dataset=str(env_datasets["tactile_braille/DiscreteArrows-v0"]),
        threads=1,
        evaluation={"test_episodes": 10},
        replay={"capacity": 10000},
    )
    run = train(config, run_dir=tmp_path / "run", progress=False)
    rows = read_progress(run)
    assert [int(r["epoch"]) for r in rows] == list(range(6))
    returns = [float(r["test/episodic_return"]) for r in rows]
    assert returns[-1] >= 0.9, returns
    assert returns[0] < 0.9  # it learned: an untrained policy does not type
    assert json.loads((run / "config.json").read_text())["task"] == config.task


def test_resume_after_kill_completes_every_epoch_once(env_datasets, tmp_path):
    run_dir = tmp_path / "run"
    dataset = str(env_datasets["tactile_braille/DiscreteArrows-v0"])
    script = (
        "from tactile_braille.agents import TrainConfig, train\n"
        f"config = TrainConfig(epochs=4, steps_per_epoch=60, start_steps=30, updates_per_step=1, "
        f"evaluation={{'test_episodes': 2}}, replay={{'capacity': 2000}}, dataset={dataset!r}, threads=1)\n"
        f"train(config, run_dir={str(run_dir)!r}, progress=False)\n"
    )
    child = subprocess.Popen(
        [sys.executable, "-c", script], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    deadline = time.monotonic() + 120
    try:
        while not (run_dir / "progress.csv").exists() or len(read_progress(run_dir)) < 1:
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
    done_before = len(read_progress(run_dir))
    assert 1 <= done_before < 4
    train(run_dir=run_dir, resume=True, progress=False)
    rows = read_progress(run_dir)
    assert [int(r["epoch"]) for r in rows] == [0, 1, 2, 3]
    steps = [int(r["env_steps"]) for r in rows]
    assert steps == [60, 120, 180, 240]  # nothing counted twice, nothing lost before the checkpoint
    with pytest.raises(FileExistsError):
        train(TrainConfig(dataset=dataset), run_dir=run_dir, progress=False)


def test_discrete_sac_trains_checkpoints_and_resumes(env_datasets, tmp_path):
    """A short discrete-SAC run: finite losses logged, a checkpoint that resumes to more epochs."""
    dataset = str(env_datasets["tactile_braille/DiscreteArrows-v0"])
    config = TrainConfig(
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
    (row,) = read_progress(run)
    for name in ("losses/qf_loss", "losses/actor_loss", "losses/alpha", "losses/entropy"):
        assert np.isfinite(float(row[name])), name
    assert 0.0 < float(row["losses/entropy"]) <= np.log(5) + 1e-6
    config_file = run / "config.json"
    data = json.loads(config_file.read_text())
    assert data["agent"]["gamma"] == 0.6  # the paper's discount for discrete SAC
    data["epochs"] = 2
    config_file.write_text(json.dumps(data))
    train(run_dir=run, resume=True, progress=False)
    assert [int(r["epoch"]) for r in read_progress(run)] == [0, 1]


def test_a_run_records_its_world_and_resumes_only_in_it(env_datasets, tmp_path):
    from tactile_braille.datasets import GENERATOR_VERSION
    from tactile_braille.evaluation.report import load_records
    from tactile_braille.keyboard.switch import SwitchModel

    dataset = str(env_datasets["tactile_braille/DiscreteArrows-v0"])
    config = TrainConfig(
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
    assert [int(r["epoch"]) for r in read_progress(run)] == [0, 1]

    # A run from before worlds were recorded resumes without a record being invented for it.
    (run / "world.json").unlink()
    (record,) = load_records([run], evaluate_missing=False)
    assert "earlier world" in record.variant
    data["epochs"] = 3
    (run / "config.json").write_text(json.dumps(data))
    train(run_dir=run, resume=True, progress=False)
    assert [int(r["epoch"]) for r in read_progress(run)] == [0, 1, 2]
    assert not (run / "world.json").exists()


def test_agent_config_must_match_the_algorithm():
    from tactile_braille.agents import DQNConfig

    with pytest.raises(ValueError, match="sac_discrete takes a DiscreteSACConfig"):
        TrainConfig(algo="sac_discrete", agent=DQNConfig())


def test_convergence_epoch_rules():
    from tactile_braille.agents.report import convergence_epoch

    curve = [0.1, 0.5, 0.8, 0.78, 0.9, 0.85]
    # Epochs count from 1, as in the paper's logs: curve[i] is the test after epoch i + 1.
    assert convergence_epoch(curve) == 5  # 95 % of the best (0.9) is 0.855: first reached by curve[4]
    assert convergence_epoch(curve, fraction=0.85) == 3  # 0.765
    assert convergence_epoch(curve, level=0.95) is None  # never reaches 0.95 in absolute terms
    assert convergence_epoch([0.0, 0.96, 1.0], level=0.95) == 2
    assert convergence_epoch([]) is None
    assert convergence_epoch([0.0, 0.0, 0.0]) is None  # a run that never scored has not converged


def test_report_evaluates_the_checkpoint_and_draws_the_curve(env_datasets, tmp_path):
    from tactile_braille.cli import main

    config = TrainConfig(
        epochs=2,
        steps_per_epoch=40,
        start_steps=20,
        updates_per_step=1,
        dataset=str(env_datasets["tactile_braille/DiscreteArrows-v0"]),
        threads=1,
        evaluation={"test_episodes": 2},
        replay={"capacity": 500},
    )
    run = train(config, run_dir=tmp_path / "run", progress=False)
    assert main(["report", str(run), "--episodes", "3"]) == 0
    report = (run / "report.md").read_text()
    assert "| epochs trained | 2 (80 env steps" in report
    assert "final evaluation (3 episodes)" in report
    assert (run / "curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["report", str(tmp_path / "missing")]) == 2  # a clear error, not a traceback
