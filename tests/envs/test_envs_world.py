"""The world's rules (envs/world.py): one check, which the environments and the training config both call,
so that a setting the environment would refuse is refused, with the same words, when a config is made."""

from __future__ import annotations

import gymnasium as gym
import pytest

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.agents.config import TrainConfig
from tactile_braille.envs.world import BACKENDS, EDGES, GRIDS, TAP_DEPTHS, check_world

DISCRETE, CONTINUOUS = "tactile_braille/DiscreteAlphabet-v0", "tactile_braille/ContinuousArrows-v0"
ALGO = {DISCRETE: "dqn", CONTINUOUS: "sac"}

REFUSED = [
    (DISCRETE, {"edges": "overrun"}, "edges='overrun' is the continuous braille tasks'"),
    (DISCRETE, {"tap_depth": "released"}, "tap_depth='released' is the released simulator's lookup"),
    (CONTINUOUS, {"tap_depth": "released", "backend": "render"}, "stored grid, on the dataset backend"),
    (CONTINUOUS, {"key_grid": "released"}, "key_grid='released' is the discrete braille tasks' grid"),
    (CONTINUOUS, {"frame_noise": (1.0, 2.0)}, "use backend='render', not 'dataset'"),
    (CONTINUOUS, {"frame_noise": (1.0,), "backend": "render"}, r"frame_noise is \(mm, degrees\), both >= 0"),
    (DISCRETE, {"frame_noise": (1.0, -2.0), "backend": "render"}, r"frame_noise is \(mm, degrees\)"),
    (DISCRETE, {"frame_noise": (1.0, 40.0), "backend": "render"}, "degrees at most 30"),
]


@pytest.mark.parametrize(("task", "world", "message"), REFUSED)
def test_the_environment_and_the_config_refuse_a_world_alike(task, world, message):
    with pytest.raises(ValueError, match=message):
        gym.make(task, **world)  # refused before any dataset is read or rig built
    with pytest.raises(ValueError, match=message):
        TrainConfig(task=task, algo=ALGO[task], **world)


def test_the_config_names_the_task_and_what_to_set():
    with pytest.raises(ValueError, match=f"set edges='stop' for {DISCRETE}$"):
        TrainConfig(task=DISCRETE, algo="dqn", edges="overrun")
    with pytest.raises(ValueError, match=f"set tap_depth='commanded' for {CONTINUOUS} on the render backend"):
        TrainConfig(task=CONTINUOUS, algo="sac", backend="render", tap_depth="released")


@pytest.mark.parametrize("continuous", [False, True])
def test_the_accepted_worlds_pass(continuous):
    for backend in BACKENDS:
        check_world(continuous, backend)
    check_world(continuous, "render", frame_noise=(2, 5.0))
    if continuous:
        check_world(True, "dataset", edges="overrun", tap_depth="released")
    else:
        check_world(False, "dataset", key_grid="released")


def test_a_task_without_a_keyboard_takes_only_our_world():
    check_world(None, "dataset")
    for rule, values in (("edges", EDGES), ("tap_depth", TAP_DEPTHS), ("key_grid", GRIDS)):
        for value in values[1:]:
            with pytest.raises(ValueError, match=f"{rule}={value!r}"):
                check_world(None, "dataset", **{rule: value})


@pytest.mark.parametrize(
    ("world", "message"),
    [
        ({"backend": "simulator"}, "unknown backend 'simulator'; choose one of"),
        ({"edges": "wrap"}, "edges must be one of"),
        ({"tap_depth": "deep"}, "tap_depth must be one of"),
        ({"key_grid": "qwertz"}, "key_grid must be one of"),
        ({"backend": "render", "frame_noise": (float("nan"), 1.0)}, "finite"),
    ],
)
def test_an_unknown_value_is_refused_with_the_choices(world, message):
    world = {"backend": "dataset", **world}
    with pytest.raises(ValueError, match=message):
        check_world(True, world.pop("backend"), **world)
