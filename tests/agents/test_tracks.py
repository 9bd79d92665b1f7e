"""The benchmark's two tracks (docs/benchmark.md): each preset declares its own, a run using anything
outside its track is refused before anything is written, and a `tactile` run learns only from the
observation dictionary and the reward: scrambling everything else the environment reports changes
nothing in it, while a `proprio` run learns from it."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

import toys
from agents_helpers import read_progress_csv, touch_config, train_module
from tactile_braille.agents import DQNConfig, TrainConfig, train
from tactile_braille.agents.config import TRACKS, proprio_settings
from tactile_braille.agents.presets import PRESET_TRACKS, PRESETS, preset_config
from tactile_braille.cli import main
from tactile_braille.sweep import PAPER_SIM_RUNS

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize(("task", "algo"), PAPER_SIM_RUNS)
def test_every_preset_declares_its_track_and_keeps_to_it(preset, task, algo):
    config = preset_config(preset, f"tactile_braille/{task}", algo)
    assert config.track == PRESET_TRACKS[preset] in TRACKS
    assert (config.track == "proprio") == bool(proprio_settings(config))  # fast uses what it declares


@pytest.mark.parametrize(
    ("changes", "named"),
    [
        ({"touch": {"enabled": True}}, "touch.enabled labels every frame with the arm's pose"),
        ({"touch": {"enabled": True, "goal_positions": True}}, "touch.goal_positions places the goal"),
        ({"touch": {"enabled": True}, "agent": {"critic_pose": True}}, "agent.critic_pose shows the critics"),
        (
            {"touch": {"enabled": True, "pose_inputs": True}},
            "touch.pose_inputs shows the agent the arm's pose",
        ),
    ],
)
def test_a_tactile_run_using_pose_or_layout_is_refused_with_what_it_used(changes, named):
    paper = preset_config("paper", "tactile_braille/ContinuousAlphabet-v0", "sac")
    with pytest.raises(ValueError, match="the tactile track allows only the observation") as error:
        paper.with_changes(**changes)
    assert named in str(error.value) and "--track proprio" in str(error.value)
    assert paper.with_changes(track="proprio", **changes).track == "proprio"
    with pytest.raises(ValueError, match=r"touch\.enabled labels"):
        preset_config("fast", "tactile_braille/ContinuousAlphabet-v0", "sac", track="tactile")


@pytest.mark.parametrize("changes", [{"touch": {"pose_inputs": True}}, {"agent": {"critic_pose": True}}])
def test_an_encoder_fitted_on_observations_has_no_pose_to_show(changes):
    config = preset_config("fast-tactile", "tactile_braille/ContinuousAlphabet-v0", "sac", track="proprio")
    assert config.touch.labels == "observation" and not proprio_settings(config)
    with pytest.raises(ValueError, match=r"which touch\.labels='observation' does not record"):
        config.with_changes(**changes)


def test_the_command_line_refuses_an_out_of_track_run_before_writing_anything(tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["train", "DiscreteArrows-v0", "dqn", "--touch.enabled", "--run-dir", str(run)]) == 2
    assert "tactile track allows only" in capsys.readouterr().err
    assert not run.exists()


def test_a_config_json_from_before_tracks_reads_into_the_track_its_settings_need():
    fast = preset_config("fast", "tactile_braille/DiscreteArrows-v0", "dqn").to_json()
    paper = preset_config("paper", "tactile_braille/DiscreteArrows-v0", "dqn").to_json()
    for stored in (fast, paper):
        del stored["track"]
    assert TrainConfig.from_json(fast).track == "proprio"
    assert TrainConfig.from_json(paper).track == "tactile"
    stored = {**preset_config("paper", "tactile_braille/DiscreteArrows-v0", "dqn").to_json(), "track": "x"}
    with pytest.raises(ValueError, match="track must be one of 'tactile', 'proprio'"):
        TrainConfig.from_json(stored)


class ScrambledReports(gym.Wrapper):
    """Everything the environment reports besides the observation dictionary and the reward replaced
    by noise: the arm's pose, the goal key's and the pressed key's names."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.noise = np.random.default_rng(12345)

    def _scramble(self, info: dict) -> dict:
        keys = self.env.unwrapped.goal_keys
        return {
            **info,
            "sensor_pose_mm": self.noise.uniform(-50, 50, size=np.shape(info["sensor_pose_mm"])),
            "goal_key": keys[int(self.noise.integers(len(keys)))],
            "pressed_key": keys[int(self.noise.integers(len(keys)))] if info["pressed_key"] else None,
        }

    def reset(self, **kwargs):
        observation, info = self.env.reset(**kwargs)
        return observation, self._scramble(info)

    def step(self, action):
        observation, reward, terminated, truncated, info = self.env.step(action)
        return observation, reward, terminated, truncated, self._scramble(info)


def _learnt(config: TrainConfig, run_dir, monkeypatch, scrambled: bool) -> list[dict]:
    make_env = train_module.make_env
    if scrambled:
        monkeypatch.setattr(train_module, "make_env", lambda *a, **k: ScrambledReports(make_env(*a, **k)))
    train(config, run_dir=run_dir, progress=False)
    monkeypatch.setattr(train_module, "make_env", make_env)
    rows = read_progress_csv(run_dir)
    return [{k: v for k, v in row.items() if k not in ("charts/SPS", "time_s")} for row in rows]


@pytest.mark.parametrize("algo", ["dqn", "sac"])
def test_a_tactile_run_learns_identically_when_all_but_its_observations_and_rewards_are_scrambled(
    env_datasets, tmp_path, monkeypatch, algo
):
    tactile = touch_config(env_datasets, algo, track="tactile", touch={"enabled": False}, epochs=2)
    # fast-tactile's touch encoder: odometry, pressed keys and the layout learnt from its own presses
    learnt = {"labels": "observation", "inputs": "readout", "goal_positions": True}
    odometry = touch_config(env_datasets, algo, track="tactile", touch=learnt, epochs=2)
    proprio = touch_config(env_datasets, algo, epochs=2)
    assert (tactile.track, odometry.track, proprio.track) == ("tactile", "tactile", "proprio")
    for name, config, same in (
        ("paper", tactile, True),
        ("odometry", odometry, True),
        ("proprio", proprio, False),
    ):
        plain = _learnt(config, tmp_path / f"{name}-plain", monkeypatch, scrambled=False)
        scrambled = _learnt(config, tmp_path / f"{name}-scrambled", monkeypatch, scrambled=True)
        assert (plain == scrambled) is same, name
    assert json.loads((tmp_path / "paper-plain" / "config.json").read_text())["track"] == "tactile"
    assert (tmp_path / "odometry-plain" / "touch.json").exists()  # its encoder was fitted, and used


def test_a_pressed_key_loss_learns_from_the_observations_alone(env_datasets, tmp_path, monkeypatch):
    """DQN's pressed-key loss (its labels: the achieved goals) in a training run: the replay serves it
    press frames, the loss is logged, and scrambling what the environment reports besides the
    observation dictionary and the reward changes nothing."""
    config = touch_config(env_datasets, "dqn", track="tactile", touch={"enabled": False},
                          agent=DQNConfig(hidden=(16,), batch_size=8, pressed_key=0.5))  # fmt: skip
    plain = _learnt(config, tmp_path / "plain", monkeypatch, scrambled=False)
    assert plain == _learnt(config, tmp_path / "scrambled", monkeypatch, scrambled=True)
    assert any(row["losses/pressed_key_loss"] not in ("", None) for row in plain)


def test_a_run_with_pose_inputs_acts_on_the_pose_its_observation_carries(env_datasets, tmp_path):
    from tactile_braille.agents.report import load_run

    touch = {"pose_inputs": True, "inputs": "readout", "goal_positions": True}
    train(touch_config(env_datasets, "sac", epochs=2, touch=touch), run_dir=tmp_path / "run", progress=False)
    config, env, agent = load_run(tmp_path / "run")
    assert config.touch.pose_inputs and "sensor_pose" in env.observation_space.spaces  # made proprio
    observation, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    here = agent.policy_action(observation, 0, explore=False, rng=rng, deterministic=True)
    elsewhere = {**observation, "sensor_pose": observation["sensor_pose"] + np.float32([15, -15, 0])}
    assert not np.allclose(
        here, agent.policy_action(elsewhere, 0, explore=False, rng=rng, deterministic=True)
    )
    blind = {name: value for name, value in observation.items() if name != "sensor_pose"}
    with pytest.raises(ValueError, match="make its environment with proprio=True"):
        agent.policy_action(blind, 0, explore=False, rng=rng, deterministic=True)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"touch": {"enabled": False, "labels": "observation"}}, "set touch.enabled too"),
        ({"task": "toys/BitFlipPress-v0", "touch": {"labels": "observation"}},
         "reads the braille tasks' documented actions"),
    ],
)  # fmt: skip
def test_observation_labels_need_an_encoder_and_a_braille_task(changes, message):
    toys.register()
    with pytest.raises(ValueError, match=message):
        TrainConfig(**{"algo": "dqn", "start_steps": 20, "touch": {"enabled": True}, **changes})
