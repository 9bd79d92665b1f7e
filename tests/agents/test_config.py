"""The run's configuration (agents/config.py): the agents' hyperparameters, TrainConfig's checks (tasks,
algorithms, replay, touch encoder, asymmetric critics, placed goals), its JSON round trip, and the
config.json of runs from before later settings existed."""

from __future__ import annotations

import json

import pytest

import toys
from agents_helpers import ALGOS, CONTINUOUS_TASK, DISCRETE_TASK, touch_config
from tactile_braille.agents import (
    DiscreteSACConfig,
    DQNConfig,
    SACConfig,
    TD3Config,
    TrainConfig,
    preset_config,
)
from tactile_braille.agents.run import setting_differences

toys.register()

pytestmark = pytest.mark.usefixtures("one_torch_thread")


# ---------------------------------------------------------------- the agents' hyperparameters
@pytest.mark.parametrize(
    ("config_class", "changes", "message"),
    [
        (DQNConfig, {"batch_size": 0}, "batch_size"),
        (SACConfig, {"gamma": 1.5}, "gamma"),
        (TD3Config, {"tau": 0.0}, "tau"),
        (DiscreteSACConfig, {"alpha_learning_rate": -1.0}, "alpha_learning_rate"),
        (DQNConfig, {"hidden": ()}, "hidden"),
    ],
)
def test_hyperparameters_are_checked(config_class, changes, message):
    with pytest.raises(ValueError, match=message):
        config_class(**changes)


def test_agent_config_must_match_the_algorithm():
    from tactile_braille.agents import DQNConfig

    with pytest.raises(ValueError, match="sac_discrete takes a DiscreteSACConfig"):
        TrainConfig(algo="sac_discrete", agent=DQNConfig())


# ---------------------------------------------------------------- TrainConfig's checks
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


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"task": DISCRETE_TASK, "algo": "sac"}, "sac needs a continuous task"),
        ({"task": DISCRETE_TASK, "algo": "td3"}, "td3 needs a continuous task"),
        ({"task": CONTINUOUS_TASK, "algo": "dqn"}, "dqn needs a discrete task"),
        ({"task": CONTINUOUS_TASK, "algo": "sac_discrete"}, "sac_discrete needs a discrete task"),
        ({"precision": "x"}, "precision"),
        ({"update_every": 0}, "update_every"),
        ({"max_episode_steps": 0}, "max_episode_steps"),
        ({"taps": 0}, "TrainConfig.taps must be at least 1, got 0"),
        ({"keep_pose_fraction": 1.5}, r"keep_pose_fraction is a share of episodes, in \[0, 1\], got 1.5"),
        ({"keep_pose_fraction": -0.1}, "keep_pose_fraction is a share of episodes"),
        ({"task": "toys/BitFlipPress-v0", "keep_pose_fraction": 0.5}, "keep_pose_fraction starts episodes"),
        ({"task": "toys/BitFlipPress-v0", "final_press": True}, "final_press ends episodes with the braille"),
        ({"replay": {"shift": -2}}, "shift must be at least 0"),
        (
            {"touch": {"enabled": True}, "replay": {"shift": 2}},
            "replay.shift=2 moves images, but with the touch",
        ),
        ({"start_steps": -1}, "start_steps"),
        ({"frame_noise": (1.0, 2.0)}, "frame_noise randomises the live renderer's .* not 'dataset'"),
        ({"frame_noise": (1.0,), "backend": "render"}, r"frame_noise is \(mm, degrees\), both >= 0"),
        ({"frame_noise": (1.0, -2.0), "backend": "render"}, r"frame_noise is \(mm, degrees\)"),
        ({"frame_noise": (1.0, 40.0), "backend": "render"}, "degrees at most 30"),
    ],
)
def test_train_config_rejects(kwargs, message):
    with pytest.raises(ValueError, match=message):
        TrainConfig(**kwargs)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"replay": {"relabel": "bogus"}}, "relabel must be one of"),
        ({"start_steps": 9}, "at least 10"),
        ({"touch": {"epochs": 0}}, "TouchConfig.epochs must be at least 1"),
        ({"replay": {"n_step": 0}}, "ReplayConfig.n_step must be at least 1"),
        ({"touch": {"refits": -1}}, "TouchConfig.refits must be at least 0"),
        ({"taps": 2}, "the touch encoder reads one tap at a time: taps=2 stacks several"),
    ],
)
def test_train_config_rejects_bad_touch_and_relabel_settings(env_datasets, changes, message):
    with pytest.raises(ValueError, match=message):
        touch_config(env_datasets, **changes)


def test_few_start_steps_are_fine_without_a_touch_encoder(env_datasets):
    assert touch_config(env_datasets, start_steps=5, touch={"enabled": False}).start_steps == 5


def test_critic_pose_needs_the_touch_encoders_labelled_frames(env_datasets):
    with pytest.raises(ValueError, match=r"critic_pose learns from a touch encoder.*set touch.enabled too"):
        TrainConfig(
            task=CONTINUOUS_TASK,
            algo="sac",
            dataset=str(env_datasets[CONTINUOUS_TASK]),
            agent=SACConfig(critic_pose=True),
        )


def test_goal_positions_need_a_touch_encoder_and_a_keyboard(env_datasets):
    with pytest.raises(
        ValueError, match=r"touch.goal_positions learns from a touch encoder.* set touch.enabled too"
    ):
        TrainConfig(
            task=CONTINUOUS_TASK,
            algo="sac",
            dataset=str(env_datasets[CONTINUOUS_TASK]),
            touch={"goal_positions": True},
        )
    with pytest.raises(ValueError, match=r"touch.inputs='readout' learns from a touch encoder"):
        TrainConfig(
            task=CONTINUOUS_TASK,
            algo="sac",
            dataset=str(env_datasets[CONTINUOUS_TASK]),
            touch={"inputs": "readout"},
        )
    with pytest.raises(ValueError, match="a keyboard layout"):
        TrainConfig(
            task="toys/BitFlipPress-v0", algo="dqn", track="proprio",
            touch={"enabled": True, "goal_positions": True},
        )  # fmt: skip


# ---------------------------------------------------------------- JSON, and the configs of older runs
@pytest.mark.parametrize("algo", list(ALGOS))
def test_train_config_json_round_trip(algo):
    task = CONTINUOUS_TASK if ALGOS[algo][2] == "continuous" else DISCRETE_TASK
    for config in (
        preset_config("released", task, algo),
        preset_config("paper", task, algo, seed=3, precision="bf16", agent={"hidden": (64, 32)}),
        preset_config("fast", task, algo, backend="render", frame_noise=(1.0, 2.0), init_from="runs/x"),
    ):
        again = TrainConfig.from_json(json.loads(json.dumps(config.to_json())))
        assert again == config
        assert isinstance(again.agent.hidden, tuple)


def test_a_run_from_before_these_settings_compares_with_their_defaults(env_datasets, tmp_path):
    config = TrainConfig(
        task=CONTINUOUS_TASK, algo="sac", dataset=str(env_datasets[CONTINUOUS_TASK]), track="proprio",
        touch={"enabled": True},
    )  # fmt: skip
    old = json.loads(json.dumps(config.to_json()))
    for key in ("goal_positions", "inputs"):
        del old["touch"][key]
    del old["agent"]["critic_pose"]
    (tmp_path / "config.json").write_text(json.dumps({**old, "epochs": 99}))
    assert setting_differences(tmp_path, config) == []  # epochs may differ
    changed = config.with_changes(
        agent={"critic_pose": True}, touch={"goal_positions": True, "inputs": "readout"}
    )
    assert setting_differences(tmp_path, changed) == [
        "agent.critic_pose: False -> True",
        "touch.goal_positions: False -> True",
        "touch.inputs: 'features' -> 'readout'",
    ]


def test_a_flat_config_json_from_before_the_groups_reads_into_them():
    flat = {
        "task": "tactile_braille/DiscreteArrows-v0", "algo": "dqn", "epochs": 7, "replay_capacity": 500,
        "her": False, "relabel": "all", "touch_encoder": True, "touch_epochs": 3, "touch_inputs": "readout",
        "goal_positions": True, "touch_refits": 2, "touch_refit_every": 50, "test_episodes": 4,
        "snapshots": 1, "agent": {"hidden": [16], "batch_size": 8},
    }  # fmt: skip
    config = TrainConfig.from_json(flat)
    assert (config.epochs, config.agent.hidden, config.agent.batch_size) == (7, (16,), 8)
    assert (config.replay.capacity, config.replay.her, config.replay.relabel) == (500, False, "all")
    assert (config.touch.enabled, config.touch.epochs, config.touch.inputs) == (True, 3, "readout")
    assert (config.touch.goal_positions, config.touch.refits, config.touch.refit_every) == (True, 2, 50)
    assert (config.evaluation.test_episodes, config.evaluation.snapshots) == (4, 1)
    assert TrainConfig.from_json(json.loads(json.dumps(config.to_json()))) == config


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (
            {"task": "tactile_braille/DiscreteArrows-v0", "algo": "dqn", "epoch": 3},
            r"no settings \['epoch'\]",
        ),
        ({"algo": "dqn", "replay": {"size": 3}}, r"ReplayConfig has no settings \['size'\] \(replay"),
        ({"algo": "dqn", "agent": {"critic_pose": True}}, r"DQNConfig has no settings \['critic_pose'\]"),
        ({"task": "tactile_braille/DiscreteArrows-v0"}, "name no algorithm"),
        ({"algo": "ppo"}, "unknown algorithm 'ppo'"),
    ],
)
def test_a_config_json_with_unknown_or_missing_settings_is_refused(data, message):
    with pytest.raises(ValueError, match=message):
        TrainConfig.from_json(data)


def test_a_config_json_from_before_adam_eps_and_the_dqn_loss_reads_what_it_was_trained_with():
    for algo, task in (("dqn", "DiscreteArrows-v0"), ("sac", "ContinuousArrows-v0")):
        stored = TrainConfig(task=f"tactile_braille/{task}", algo=algo).to_json()
        stored["agent"] = {k: v for k, v in stored["agent"].items() if k not in ("adam_eps", "loss")}
        old = TrainConfig.from_json(stored)
        assert old.agent.adam_eps == 1e-8  # torch's default, which every run used before the setting
        if algo == "dqn":
            assert old.agent.loss == "huber"
        assert (
            TrainConfig.from_json(
                TrainConfig(task=f"tactile_braille/{task}", algo=algo).to_json()
            ).agent.adam_eps
            == 1e-4
        )


REMOVED = {
    "dqn": ({"inverse_dynamics": 0.0}, "inverse_dynamics", 0.5),
    "sac_discrete": ({"shared_encoder": False}, "shared_encoder", True),
    "sac": ({"shared_encoder": False}, "shared_encoder", True),
    "td3": ({"shared_encoder": False}, "shared_encoder", True),
    "planner": (
        {"locate": False, "locate_accept": 0.9, "locate_margin": 0.15, "locate_span": 3,
         "locate_learning_rate": 3e-3, "locate_ready": 0.95, "reckon": 0, "nothing_carry": False,
         "move_press": False, "press_accept": None, "backtrack_evidence": 0.0},
        "press_accept", 0.9,
    ),
}  # fmt: skip
"""Each algorithm's removed settings as its records hold them, and one given another value."""


@pytest.mark.parametrize("algo", list(REMOVED))
def test_a_record_of_removed_settings_reads_only_with_the_values_the_code_still_runs(algo):
    kept, name, other = REMOVED[algo]
    task = CONTINUOUS_TASK if algo in ("sac", "td3") else DISCRETE_TASK
    stored = TrainConfig(task=task, algo=algo).to_json()
    stored["agent"] = {**stored["agent"], **kept}
    assert TrainConfig.from_json(stored) == TrainConfig(task=task, algo=algo)
    stored["agent"][name] = other
    with pytest.raises(ValueError, match=rf"agent\.{name}={other!r}: this setting was removed"):
        TrainConfig.from_json(stored)
