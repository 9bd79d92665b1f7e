"""The examples/ scripts run as users run them (tiny budgets here; the leaderboard's are in their notes)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from tactile_braille.envs.oracle import oracle_action
from tactile_braille.evaluation.results import read_result
from tactile_braille.keyboard.layout import ARROW_KEYS

ARROWS = "tactile_braille/DiscreteArrows-v0"

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # as an import would: dataclasses read their module's names
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(("task", "algo"), [("DiscreteArrows-v0", "dqn"), ("ContinuousArrows-v0", "sac")])
def test_sb3_her_trains_scores_and_writes_a_results_file(env_datasets, tmp_path, task, algo):
    pytest.importorskip("stable_baselines3")
    output = tmp_path / f"{task}__{algo}.json"
    argv = [task, algo, "--steps", "50", "--learning-starts", "30", "--seed", "3", "--output", str(output),
            "--dataset", str(env_datasets[f"tactile_braille/{task}"])]  # fmt: skip
    assert _load("sb3_her").main(argv) == 0
    result = read_result(output)
    assert result["method"] == f"SB3 {algo.upper()} + HER" and result["track"] == "tactile"
    assert result["seed"] == 3 and result["budget"]["env_steps"] == 50
    assert result["report"]["keys_asked"] == 96 and 0.0 <= result["report"]["accuracy"] <= 1.0
    with pytest.raises(SystemExit):  # an existing results file is never overwritten
        _load("sb3_her").main(argv)


def test_the_cleanrl_style_script_trains_scores_and_writes_a_results_file(env_datasets, tmp_path):
    output = tmp_path / "cleanrl.json"
    argv = ["--task", "DiscreteArrows-v0", "--steps", "60", "--learning-starts", "30", "--batch-size", "8",
            "--output", str(output), "--dataset", str(env_datasets[ARROWS])]  # fmt: skip
    assert _load("cleanrl_dqn_her").main(argv) == 0
    result = read_result(output)
    assert result["method"] == "CleanRL-style DQN + HER" and result["track"] == "tactile"
    assert result["budget"]["env_steps"] == 60 and result["report"]["keys_asked"] == 96


def record_a_press_of_down(env, replay, wanted: np.ndarray) -> None:
    """An episode driven by the pose oracle to DOWN and pressing it, stored with ``wanted`` as its goal."""
    observation, _ = env.reset(seed=0, options={"goal_key": "DOWN"})
    terminated = False
    while not terminated:
        action = oracle_action(env)
        following, _, terminated, truncated, _ = env.step(action)
        replay.add({**observation, "desired_goal": wanted}, action, following, terminated)
        observation = following
        assert not truncated


def test_the_cleanrl_replay_relabels_with_the_key_an_episode_ended_on(env_datasets):
    env = gym.make(ARROWS, dataset=env_datasets[ARROWS])
    replay = _load("cleanrl_dqn_her").EpisodeReplay(env, 30)
    up, down = (np.eye(4, dtype=np.float32)[ARROW_KEYS.index(k)] for k in ("UP", "DOWN"))
    record_a_press_of_down(env, replay, wanted=up)  # an episode that wanted UP but ended on DOWN
    replay.end_episode()
    np.testing.assert_array_equal(replay.final[: replay.size], np.tile(down, (replay.size, 1)))
    rng = np.random.default_rng(0)
    hindsight = replay.sample(env, 64, her_fraction=1.0, rng=rng)
    assert np.all(hindsight["goal"].numpy() == down)
    # Rewarded exactly on the step that pressed DOWN (the last one: any press ends an episode).
    rewarded = hindsight["reward"].numpy() == 1.0
    assert rewarded.any() and np.all(rewarded == (hindsight["terminated"].numpy() == 1.0))
    as_asked = replay.sample(env, 64, her_fraction=0.0, rng=rng)
    assert np.all(as_asked["goal"].numpy() == up) and not as_asked["reward"].numpy().any()


def test_the_cleanrl_papers_her_stores_a_wrong_press_again_with_the_pressed_key(env_datasets):
    env = gym.make(ARROWS, dataset=env_datasets[ARROWS])
    replay = _load("cleanrl_dqn_her").EpisodeReplay(env, 60)
    up, down = (np.eye(4, dtype=np.float32)[ARROW_KEYS.index(k)] for k in ("UP", "DOWN"))
    for wanted, copies in ((up, 2), (down, 1)):  # DOWN pressed when UP was wanted, then when DOWN was
        start = replay.size
        record_a_press_of_down(env, replay, wanted)
        length = replay.size - start
        replay.end_episode(copy_wrong_press=True)
        assert replay.size - start == copies * length
    stored = replay.sample(env, 256, her_fraction=0.0, rng=np.random.default_rng(0))
    rewarded = stored["reward"].numpy() == 1.0
    # Rewarded: the last step of the copy (goal DOWN) and of the right press, never under goal UP.
    assert rewarded.any() and np.all(stored["goal"].numpy()[rewarded] == down)
    assert np.all(rewarded == (stored["terminated"].numpy() == 1.0) & (stored["goal"].numpy() == down).all(1))


def test_a_custom_agent_is_one_file_registered_trained_by_the_loop_and_scored(
    env_datasets, tmp_path, capsys, monkeypatch
):
    """examples/custom_agent.py: an agent defined and registered outside src/, trained for an epoch by the
    project's own loop and typed by evaluate_policy; the registry then lists it like our own."""
    from tactile_braille.agents import registry
    from tactile_braille.agents.config import TrainConfig

    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))  # the other tests' registry is ours
    from tactile_braille.agents.registry import agent_names, agent_spec
    from tactile_braille.agents.run import read_progress

    module = _load("custom_agent")
    run = tmp_path / "pooled_q"
    argv = [
        "--epochs",
        "1",
        "--steps-per-epoch",
        "60",
        "--run-dir",
        str(run),
        "--dataset",
        str(env_datasets[ARROWS]),
    ]
    assert module.main(argv) == 0
    (row,) = read_progress(run)
    assert row["env_steps"] == 60 and row["updates"] > 0 and np.isfinite(row["losses/q_loss"])
    assert "typing accuracy" in capsys.readouterr().out
    assert "pooled_q" in agent_names() and agent_spec("pooled_q").label == "Pooled Q"
    config = TrainConfig(algo="pooled_q", agent={"pool": 20})  # its settings are checked as ours are
    assert config.agent.pool == 20 and config.updates_per_step == 2
    with pytest.raises(ValueError, match="pool must divide"):
        TrainConfig(algo="pooled_q", agent={"pool": 7})
    with pytest.raises(ValueError, match="pooled_q needs a discrete task"):
        TrainConfig(algo="pooled_q", task="tactile_braille/ContinuousArrows-v0")
    source = Path(__file__).resolve().parents[1] / "src"
    assert not any("pooled_q" in path.read_text() for path in source.rglob("*.py"))  # src/ never names it
