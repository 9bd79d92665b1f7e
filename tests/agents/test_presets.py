"""The presets (agents/presets.py): the paper's settings, the released code's changes, "fast", overrides."""

from __future__ import annotations

import numpy as np
import pytest

from agents_helpers import ALGOS, CONTINUOUS_TASK, DISCRETE_TASK
from tactile_braille.agents import preset_config
from tactile_braille.agents.config import flatten
from tactile_braille.agents.presets import preset_differences
from tactile_braille.envs.registry import task_of
from tactile_braille.sweep import PAPER_SIM_RUNS

pytestmark = pytest.mark.usefixtures("one_torch_thread")


PAPER_EPOCHS = {
    "tactile_braille/DiscreteArrows-v0": 25,
    "tactile_braille/DiscreteAlphabet-v0": 100,
    "tactile_braille/ContinuousArrows-v0": 100,
    "tactile_braille/ContinuousAlphabet-v0": 2000,
}


PAIRS = [
    (task, algo)
    for task in PAPER_EPOCHS
    for algo in ALGOS
    if ("Continuous" in task) == (ALGOS[algo][2] == "continuous")
]


@pytest.mark.parametrize(("task", "algo"), PAIRS)
def test_paper_preset_values(task, algo):
    config = preset_config("paper", task, algo)
    assert (config.task, config.algo, config.preset) == (task, algo, "paper")
    assert config.epochs == PAPER_EPOCHS[task]
    assert config.updates_per_step == (1 if algo == "td3" else 2)
    assert (config.steps_per_epoch, config.start_steps, config.update_every) == (250, 200, 1)
    assert (config.evaluation.test_episodes, config.replay.capacity, config.replay.her) == (20, 100_000, True)
    assert config.max_episode_steps == 25
    continuous = "Continuous" in task  # the released simulator's world
    assert (config.edges, config.tap_depth) == (
        ("overrun", "released") if continuous else ("stop", "commanded")
    )
    assert isinstance(config.agent, ALGOS[algo][1])
    assert config.agent.batch_size == 32
    paper_agent = {
        "dqn": {"gamma": 0.95, "learning_rate": 5e-4, "test_epsilon": 0.0, "hidden": (512,)},
        "sac_discrete": {"gamma": 0.6, "learning_rate": 5e-4, "hidden": (512,)},
        "sac": {"gamma": 0.95, "target_entropy": -6.0, "hidden": (512,)},
        "td3": {"gamma": 0.95, "learning_rate": 5e-5, "policy_delay": 2, "hidden": (512,)},
    }[algo]
    for name, value in paper_agent.items():
        assert getattr(config.agent, name) == value, name


RELEASED = {
    "dqn": {
        "agent.test_epsilon": (0.0, 0.05), "agent.target_update": ("update", "epoch"),
        "agent.tau": (0.005, 0.995), "agent.schedule_interval": (1, 250),
        "agent.dueling_split": (False, True), "agent.weights_init": ("he", "released"),
        "update_after": (None, 1),
    },
    "sac_discrete": {
        "agent.initial_alpha": (1.0, pytest.approx(np.exp(0.1 * np.log(5)))), "update_after": (None, 1),
        "agent.dueling": (True, False), "agent.weights_init": ("he", "released"),
    },
    "sac": {
        "agent.hidden": ([512], [1024, 512]), "max_episode_steps": (25, 35), "update_after": (None, 1),
        "agent.weights_init": ("he", "released"), "agent.log_std": ("clamp", "tanh"),
        "agent.action_input_scale": (1.0, "largest move"),  # the task's, in mm
    },
    "td3": {
        "agent.learning_rate": (5e-5, 7.5e-5), "update_every": (1, 100), "agent.schedule_interval": (1, 250),
        "agent.weights_init": ("he", "released"), "agent.action_input_scale": (1.0, "largest move"),
    },
}  # fmt: skip
"""What the released code's configurations change from the paper's (dotted setting -> (paper, released))."""


@pytest.mark.parametrize(("task", "algo"), PAIRS)
def test_released_preset_differs_exactly_by_the_listed_settings(task, algo):
    paper, released = (
        flatten(preset_config("paper", task, algo)),
        flatten(preset_config("released", task, algo)),
    )
    assert released.pop("preset") == "released" and paper.pop("preset") == "paper"
    changed = {key for key in paper if paper[key] != released[key]}
    assert changed == set(RELEASED[algo])
    for key, (paper_value, released_value) in RELEASED[algo].items():
        if released_value == "largest move":  # the released code's networks read actions in mm
            released_value = task_of(task).max_move_mm
        assert (paper[key], released[key]) == (paper_value, released_value), key
    assert len(preset_differences("released", task, algo)) == len(RELEASED[algo])


@pytest.mark.parametrize("name", ["fast", "fast-tactile"])
def test_our_presets_keep_the_rigs_world_and_a_discrete_task_refuses_the_released_one(name):
    config = preset_config(name, CONTINUOUS_TASK, "sac")
    assert (config.edges, config.tap_depth) == ("stop", "commanded")  # the real rig's world
    differences = preset_differences(name, CONTINUOUS_TASK, "sac")
    assert {"edges: 'overrun' -> 'stop'", "tap_depth: 'released' -> 'commanded'"} <= set(differences)
    with pytest.raises(ValueError, match="edges='overrun' is the continuous braille tasks'"):
        preset_config(name, DISCRETE_TASK, "dqn", edges="overrun")
    with pytest.raises(ValueError, match="tap_depth='released' is the released simulator's lookup"):
        preset_config(name, DISCRETE_TASK, "dqn", tap_depth="released")
    with pytest.raises(ValueError, match="key_grid='released' is the discrete braille tasks' grid"):
        preset_config(name, CONTINUOUS_TASK, "sac", key_grid="released")
    with pytest.raises(ValueError, match="on the render backend"):
        preset_config("paper", CONTINUOUS_TASK, "sac", backend="render")


def test_released_preset_values():
    td3 = preset_config("released", CONTINUOUS_TASK, "td3")
    assert (td3.agent.learning_rate, td3.update_every) == (7.5e-5, 100)
    sac = preset_config("released", CONTINUOUS_TASK, "sac")
    assert (sac.agent.hidden, sac.max_episode_steps) == ((1024, 512), 35)
    # Its networks read actions in mm: the scale is the task's largest move (20 mm on the alphabet).
    alphabet = preset_config("released", "tactile_braille/ContinuousAlphabet-v0", "td3")
    assert alphabet.agent.action_input_scale == 20.0
    dqn = preset_config("released", DISCRETE_TASK, "dqn").agent
    assert (dqn.test_epsilon, dqn.target_update, dqn.tau, dqn.loss, dqn.adam_eps) == (
        0.05,
        "epoch",
        0.995,
        "mse",
        1e-4,
    )
    assert (dqn.dueling_split, dqn.weights_init) == (True, "released")
    assert preset_differences("released", DISCRETE_TASK, "sac_discrete") == [
        "agent.dueling: True -> False",
        "agent.initial_alpha: 1.0 -> 1.174618943088019",
        "agent.weights_init: 'he' -> 'released'",
        "update_after: None -> 1",
    ]


@pytest.mark.parametrize("keys", ["arrows", "alphabet"])
def test_td3_noise_is_the_released_codes_in_mm_for_both_paper_presets(keys):
    task = f"tactile_braille/Continuous{keys.title()}-v0"
    move_mm = {"arrows": 10.0, "alphabet": 20.0}[keys]
    for preset in ("paper", "released"):
        agent = preset_config(preset, task, "td3").agent
        in_mm = [round(v * move_mm, 9) for v in (agent.noise_start, agent.noise_end, agent.target_noise,
                                                 agent.noise_clip)]  # fmt: skip
        assert in_mm == [1.0, 0.05, 0.05, 0.2]


def test_preset_errors_and_overrides():
    with pytest.raises(ValueError, match="unknown preset"):
        preset_config("sota", DISCRETE_TASK, "dqn")
    with pytest.raises(ValueError, match="gama"):
        preset_config("paper", DISCRETE_TASK, "dqn", agent={"gama": 0.9})
    with pytest.raises(ValueError, match="unknown algorithm"):
        preset_config("paper", DISCRETE_TASK, "ppo")
    with pytest.raises(ValueError, match="unknown task"):
        preset_config("paper", "tactile_braille/Piano-v0", "dqn")
    import toys

    toys.register()
    with pytest.raises(ValueError, match="no preset for task"):
        preset_config("paper", "toys/BitFlipPress-v0", "dqn")
    config = preset_config(
        "released", CONTINUOUS_TASK, "td3", epochs=3, agent={"gamma": 0.9}, evaluation={"test_episodes": 2}
    )
    assert (config.epochs, config.evaluation.test_episodes, config.agent.gamma) == (3, 2, 0.9)
    assert (config.agent.learning_rate, config.update_every) == (7.5e-5, 100)  # the rest of the preset stays
    assert config.agent.batch_size == 32


def test_fast_changes_the_papers_settings():
    from tactile_braille.agents.presets import preset_config

    paper = preset_config("paper", "tactile_braille/DiscreteAlphabet-v0", "dqn")
    fast = preset_config("fast", "tactile_braille/DiscreteAlphabet-v0", "dqn")
    assert (paper.replay.relabel, paper.touch.enabled, paper.epochs) == ("paper", False, 100)
    assert (fast.replay.relabel, fast.touch.enabled, fast.epochs) == ("all", True, 25)
    assert fast.agent.hidden == (256, 256) and fast.agent.epsilon_decay_steps == 1000
    assert (fast.touch.refit_every, fast.touch.refits) == (250, 16)
    assert preset_config("fast", "tactile_braille/ContinuousAlphabet-v0", "sac").epochs == 90


def test_the_fast_preset_acts_on_the_pose_everywhere_and_gives_asymmetric_critics_to_one_task():
    for task, algo in PAPER_SIM_RUNS:
        config = preset_config("fast", f"tactile_braille/{task}", algo)
        touch = config.touch
        assert touch.pose_inputs and touch.goal_positions and touch.inputs == "readout", task
        assert getattr(config.agent, "critic_pose", False) == (task == "ContinuousAlphabet-v0"), task
        paper = preset_config("paper", f"tactile_braille/{task}", algo)
        assert not (paper.touch.pose_inputs or paper.touch.goal_positions or paper.touch.enabled)
