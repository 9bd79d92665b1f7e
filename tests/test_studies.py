"""Scripts of studies/ (and benchmarks/) that read training runs, run on tiny runs made here."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from tactile_braille.agents import DiscreteSACConfig, DQNConfig, MRQConfig, SACConfig, TrainConfig, train
from tactile_braille.agents.config import replace_settings

ROOT = Path(__file__).resolve().parents[1]
ARROWS = "tactile_braille/DiscreteArrows-v0"


def _load(name: str):
    (path,) = [p for p in (ROOT / "studies" / f"{name}.py", ROOT / "benchmarks" / f"{name}.py") if p.exists()]
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _tiny_run(env_datasets, folder: Path, algo: str, agent) -> Path:
    config = TrainConfig(task=ARROWS, algo=algo, epochs=1, steps_per_epoch=30, start_steps=20, threads=1,
                         dataset=str(env_datasets[ARROWS]), agent=agent,
                         evaluation={"test_episodes": 1})  # fmt: skip
    return train(config, run_dir=folder, progress=False)


def test_policy_critic_agreement_measures_where_the_policy_leaves_its_critics(env_datasets, tmp_path):
    script = _load("policy_critic_agreement")
    run = _tiny_run(
        env_datasets, tmp_path / "sac", "sac_discrete", DiscreteSACConfig(hidden=(16,), batch_size=8)
    )
    env, agent, epoch = script.load_agent(run)
    assert epoch == 0
    rows = script.step_measures(env, agent, episodes=3, seed=0)
    agree, regret, gap, presses, best_presses, confidence = rows.T
    assert len(rows) >= 3 and set(np.unique(agree)) <= {0.0, 1.0}
    assert np.all(regret >= 0) and np.all(regret[agree == 1] == 0) and np.all(regret[agree == 0] > 0)
    assert np.all(gap >= 0) and np.all((confidence > 0.2) & (confidence <= 1.0))  # five actions
    assert np.all(presses[agree == 1] == best_presses[agree == 1])  # the same action where they agree
    dqn = _tiny_run(env_datasets, tmp_path / "dqn", "dqn", DQNConfig(hidden=(16,), batch_size=8))
    with pytest.raises(ValueError, match="a dqn run; this compares a discrete SAC"):
        script.load_agent(dqn)


def test_mrq_values_reads_the_value_under_every_goal_and_the_policy_beside_it(env_datasets, tmp_path):
    script = _load("mrq_values")
    tiny = MRQConfig(batch_size=8, target_every=4, hidden_units=16, state_size=16, state_action_size=16,
                     action_size=8)  # fmt: skip
    run = _tiny_run(env_datasets, tmp_path / "mrq", "mrq", tiny)
    env, agent = script.load_agent(run)
    replay = script.replay_measures(env, agent, script.load_replay(run, env), batch_size=64, seed=0)
    assert all(0 < spread < 2 for pair in replay["spread"].values() for spread in pair)
    assert replay["spread"]["trained"] != replay["spread"]["fresh"]  # an update changed the encoder
    assert set(replay["presses"]) == {"right", "wrong"}
    wrong = replay["presses"]["wrong"]
    assert wrong["count"] > 0 and np.isfinite([wrong["model_reward"], wrong["value"]]).all()
    assert wrong["target"] == 0  # a wrong press ends its episode with nothing to bootstrap
    rows = script.start_measures(env, agent, starts=3, seed=0)
    assert len(rows) == 3
    for row in rows:
        assert row["values"].shape == (4, 5) and np.isfinite(row["values"]).all()  # 4 arrows, 5 actions
        assert row["best"] == row["values"][row["goal"]].argmax() and 0 <= row["greedy"] < 5
        assert np.ptp(row["values"], axis=0).max() > 0  # a goal one-hot changes an untrained value
    dqn = _tiny_run(env_datasets, tmp_path / "dqn", "dqn", DQNConfig(hidden=(16,), batch_size=8))
    with pytest.raises(ValueError, match=r"not a discrete MR\.Q run"):
        script.load_agent(dqn)


def test_typing_edges_counts_the_moves_an_edge_stopped_and_types_in_each_world(env_datasets, tmp_path):
    script = _load("typing_edges")
    task = "tactile_braille/ContinuousArrows-v0"
    env = script.EdgeCount(gym.make(task, dataset=env_datasets[task]))
    _, info = env.reset(seed=0)
    x = info["sensor_pose_mm"][0] - env.unwrapped.task.frame_origin_mm[0]
    stopped = 0
    for _ in range(6):  # six moves of 10 mm one way cross the 20 mm workspace: the last ones are stopped
        env.step(np.array([1.0, 0.0, -1.0], dtype=np.float32))
        stopped += x + 10.0 > 0.0 + script.CUT_MM  # the workspace ends at x = 0
        x = min(x + 10.0, 0.0)
    assert env.steps == 6 and env.at_edge == stopped >= 4
    config = TrainConfig(task=task, algo="sac", epochs=1, steps_per_epoch=30, start_steps=20, threads=1,
                         dataset=str(env_datasets[task]), agent=SACConfig(hidden=(16,), batch_size=8),
                         evaluation={"test_episodes": 1})  # fmt: skip
    sequences = [("UP", "LEFT"), ("RIGHT", "DOWN")]
    rows = script.measure(train(config, run_dir=tmp_path / "ours", progress=False), sequences)
    assert [row[0] for row in rows] == list(script.WORLDS)
    for _, accuracy, steps, share in rows:
        assert 0.0 <= accuracy <= 1.0 and 4 <= steps <= 4 * 25 and 0.0 <= share <= 1.0
    released = replace_settings(config, {"edges": "overrun", "tap_depth": "released"})
    with pytest.raises(ValueError, match="made in the released simulator's world"):
        script.measure(train(released, run_dir=tmp_path / "released", progress=False), sequences)


def test_typing_overrun_measures_how_far_out_each_key_starts_and_splits_keys_by_it(env_datasets, tmp_path):
    script = _load("typing_overrun")
    task = "tactile_braille/ContinuousArrows-v0"
    env = script.StartOverrun(gym.make(task, dataset=env_datasets[task], edges="overrun"))
    _, info = env.reset(seed=0)
    x = info["sensor_pose_mm"][0] - env.unwrapped.task.frame_origin_mm[0]
    for _ in range(6):  # 60 mm one way from inside a 20 mm workspace ending at x = 0: 40-60 mm past it
        env.step(np.array([1.0, 0.0, -1.0], dtype=np.float32))
    env.reset(options={"goal_key": "UP", "keep_pose": True})
    env.reset(options={"goal_key": "UP"})  # a fresh start pose is drawn inside
    assert env.starts_mm[0] == 0.0 and env.starts_mm[1] == pytest.approx(x + 60.0) and env.starts_mm[2] == 0.0
    config = TrainConfig(task=task, algo="sac", epochs=1, steps_per_epoch=30, start_steps=20, threads=1,
                         dataset=str(env_datasets[task]), agent=SACConfig(hidden=(16,), batch_size=8),
                         evaluation={"test_episodes": 1}, edges="overrun")  # fmt: skip
    sequences = [("UP", "LEFT", "DOWN"), ("RIGHT", "DOWN", "UP")]
    found = script.measure(train(config, run_dir=tmp_path / "overrun", progress=False), sequences)
    assert len(found.starts_mm) == len(found.correct) == len(found.steps) == 6
    assert found.starts_mm[0] == found.starts_mm[3] == 0.0  # each sequence starts from a fresh pose
    assert np.all(found.starts_mm >= 0) and np.all((found.steps >= 1) & (found.steps <= 25))
    inside, outside = found.split(False), found.split(True)
    assert inside[0] + outside[0] == 6 and inside[0] >= 2
    assert inside[1] == pytest.approx(found.correct[found.starts_mm < script.OUT_MM].mean())
    assert list(found.goals) == [key for sequence in sequences for key in sequence]
    by_key = {
        goal: (found.split(False, goal), found.split(True, goal)) for goal in ("UP", "LEFT", "DOWN", "RIGHT")
    }
    assert sum(i[0] + o[0] for i, o in by_key.values()) == 6 and by_key["UP"][0][0] + by_key["UP"][1][0] == 2
    first = found.goals == "UP"  # UP starts the first sequence from a fresh pose inside
    assert by_key["UP"][0][0] >= 1 and by_key["UP"][0][1] == pytest.approx(
        found.correct[first & (found.starts_mm < script.OUT_MM)].mean()
    )
    stopping = replace_settings(config, {"edges": "stop"})
    with pytest.raises(ValueError, match="made with edges='stop': every key starts inside"):
        script.measure(train(stopping, run_dir=tmp_path / "stop", progress=False), sequences)


def test_tap_identifiability_finds_twin_start_images_far_apart(env_datasets):
    script = _load("tap_identifiability")
    a = np.zeros(100, dtype=np.float32)
    a[:10] = 1
    b = a.copy()
    b[10:13] = 1  # 3 pixels from a
    c = np.zeros(100, dtype=np.float32)
    c[50:90] = 1  # 50 from a
    groups = [
        (a, np.array([[0.0, 0.0], [0.3, 0.2]])),
        (b, np.array([[10.0, 0.0]])),
        (c, np.array([[1.0, 0.0]])),
    ]
    found = script.measure(groups, [0, 5])
    assert found["starts"] == 4 and found["images"] == 3
    assert found[">= 5 mm at 0"] == 0.0  # no image repeats 5 mm away
    assert found[">= 5 mm at 5"] == 0.75  # a (2 starts) and b (1) are 3 pixels apart, 10 mm apart
    assert found["fewest 5 mm apart"] == 3 and found["1 mm apart"] == 50  # a's and c's starts ~0.9 mm apart
    groups[2] = (c, np.array([[1.0, 0.0], [7.0, 0.0]]))  # one image from starts 6 mm apart: its own twin
    assert script.measure(groups, [0])[">= 5 mm at 0"] == 0.4  # its 2 starts of 5
    task = "ContinuousArrows-v0"
    seen = script.start_images(task, {"dataset": env_datasets[f"tactile_braille/{task}"]}, 40, 0)
    assert sum(len(poses) for _, poses in seen) == 40
    assert all(image.shape == (10_000,) and set(np.unique(image)) <= {0, 1} for image, _ in seen)
    # the nearest-sample lookup: one image per grid sample, its starts within one cell of the 5 mm test grid
    assert all(np.ptp(poses, axis=0).max() <= 5.0 for _, poses in seen) and len(seen) > 10


def test_planner_traces_scores_the_reader_and_the_refit_labels_against_the_taps_keys(env_datasets, tmp_path):
    from tactile_braille.agents import PlannerConfig
    from tactile_braille.agents.planner import PRESS

    script = _load("planner_traces")
    config = TrainConfig(task=ARROWS, algo="planner", epochs=1, steps_per_epoch=60, start_steps=0, threads=1,
                         dataset=str(env_datasets[ARROWS]), agent=PlannerConfig(batch_size=8, refit_every=10),
                         replay={"relabel": "all"}, evaluation={"test_episodes": 1})  # fmt: skip
    run = train(config, run_dir=tmp_path / "planner", progress=False)
    row = script.traces(str(run), refit=True)
    assert 0.0 <= row["accuracy"] <= 1.0 and sum(row["misses"].values()) <= len(row["episodes"])
    every, on, off, confusions = script.reader_accuracy(row["agent"], row["env"], taps=400)
    assert min(every, on, off) >= 0.0 and max(every, on, off) <= 1.0
    assert sum(confusions.values()) == round((1 - every) * 400)
    agent, buffer = row["agent"], row["buffer"]
    truth = script.label_truth(row)
    labels, wrong = script.label_accuracy(row)
    assert labels == len(truth) == len(agent.label_frames) > 0
    assert sum(wrong.values()) == int((truth != agent.label_classes).sum())
    # A press's frame shows the key it pressed (its achieved goal): the truth read from the stored
    # samples agrees there.
    slots = np.flatnonzero((buffer.actions[: buffer.size] == PRESS) & (buffer.achieved[: buffer.size] >= 0))
    frames = buffer.frame_index[slots, 0]
    where = {frame: i for i, frame in enumerate(agent.label_frames)}
    assert len(slots) > 0
    np.testing.assert_array_equal([truth[where[f]] for f in frames], buffer.achieved[slots])
    # Other typing seeds: every key typed from each seed's starts, as that seed alone types them; the
    # figures are the seeds' means.
    both = script.traces(str(run), seeds=(0, 1))
    second = script.traces(str(run), seeds=(1,))
    assert len(both["episodes"]) == 2 * len(second["episodes"]) == 2 * 96
    assert both["episodes"][96:] == second["episodes"]
    first = np.mean([goal == typed for goal, typed, *_ in both["episodes"][:96]])
    assert both["accuracy"] == pytest.approx((first + second["accuracy"]) / 2)


def test_alphabet_gap_reads_each_groups_seeds_and_draws_their_mean_beside_the_releases_log(
    env_datasets, tmp_path, capsys
):
    script = _load("alphabet_gap")
    for seed in (0, 1):
        config = TrainConfig(task=ARROWS, algo="dqn", seed=seed, epochs=2, steps_per_epoch=30, start_steps=20,
                             threads=1, dataset=str(env_datasets[ARROWS]),
                             agent=DQNConfig(hidden=(16,), batch_size=8),
                             evaluation={"test_episodes": 2})  # fmt: skip
        train(config, run_dir=tmp_path / f"tiny_{seed}", progress=False)
    figure = tmp_path / "gap.png"
    assert script.main([f"tiny={tmp_path}/tiny_*", "--figure", str(figure)]) == 0
    out = capsys.readouterr().out
    assert "tiny (2 seeds, 2 epochs)" in out and "per seed (95 % of best / 0.95): 0: " in out
    assert "the release's logged run: first 95 % of its best at epoch 36" in out
    assert figure.read_bytes().startswith(b"\x89PNG")
    with pytest.raises(SystemExit, match="no folder matches"):
        script.main([f"none={tmp_path}/nothing_*"])
    with pytest.raises(SystemExit, match="a group is LABEL=GLOB"):
        script.main(["no pattern"])


@pytest.mark.slow
def test_alphabet_gap_counts_the_images_the_per_key_offsets_change():
    lines = _load("alphabet_gap").offsets_effect()
    assert lines[0].startswith("without the per-key offsets, ") and lines[0].endswith(
        " of 3200 images of keys-train change"
    )
    changed = int(lines[0].split(", ")[1].split(" of ")[0])
    assert 0 < changed < 3200 // 10 and len(lines) > 1  # a few images of the keys whose offsets matter
