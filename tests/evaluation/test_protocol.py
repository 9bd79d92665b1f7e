"""The paper's typing evaluation: sequences, no reset between keys, metrics with known answers."""

from __future__ import annotations

import itertools

import gymnasium as gym
import numpy as np
import pytest

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.envs.oracle import oracle_action
from tactile_braille.envs.tasks import DISCRETE_ACTIONS
from tactile_braille.evaluation import SENTENCES, paper_sequences, text_keys, type_sequences
from tactile_braille.evaluation.protocol import NONE, OTHER

ARROWS = "tactile_braille/DiscreteArrows-v0"
PRESS = DISCRETE_ACTIONS.index("PRESS")
# Moves between arrow keys on the grid ((NONE, UP, NONE), (LEFT, DOWN, RIGHT)).
GRID_DISTANCE = {
    frozenset(("UP", "DOWN")): 1, frozenset(("DOWN", "LEFT")): 1, frozenset(("DOWN", "RIGHT")): 1,
    frozenset(("LEFT", "RIGHT")): 2, frozenset(("UP", "LEFT")): 2, frozenset(("UP", "RIGHT")): 2,
}  # fmt: skip


class Oracle:
    """Acts with the true pose (envs/oracle.py) through the agents' interface."""

    def __init__(self, env):
        self.env = env

    def policy_action(self, observation, step, explore, rng, deterministic=False):
        assert deterministic  # the protocol asks for deterministic actions
        return oracle_action(self.env)


class PressAtOnce:
    def policy_action(self, observation, step, explore, rng, deterministic=False):
        return PRESS


@pytest.fixture
def arrows_env(env_datasets):
    return gym.make(ARROWS, dataset=env_datasets[ARROWS])


def test_paper_sequences():
    arrows = paper_sequences("arrows")
    assert len(arrows) == 24 and len(set(arrows)) == 24
    assert all(sorted(s) == sorted(("UP", "DOWN", "LEFT", "RIGHT")) for s in arrows)
    alphabet = paper_sequences("alphabet")
    assert len(alphabet) == 10 and len(set(alphabet)) == 10
    assert all(len(s) == 27 and len(set(s)) == 27 and "SPACE" in s for s in alphabet)
    assert alphabet == paper_sequences("alphabet")  # fixed by its seed
    assert alphabet[0][:5] == ("B", "H", "P", "X", "SPACE")  # the list in docs/evaluation.md
    with pytest.raises(ValueError, match="arrows"):
        paper_sequences("piano")


def test_text_keys():
    assert text_keys("a bc") == ("A", "SPACE", "B", "C")
    assert all(text_keys(sentence) for sentence in SENTENCES)
    with pytest.raises(ValueError, match="cannot type '!'"):
        text_keys("hi!")


def test_the_oracle_types_every_arrow_sequence_in_the_fewest_steps(arrows_env):
    result = type_sequences(Oracle(arrows_env), arrows_env, paper_sequences("arrows"), seed=3)
    assert result.accuracy == 1.0
    # After the first key (from a random pose) each key costs its grid distance plus the press.
    for sequence, steps in zip(result.sequences, result.steps, strict=True):
        for previous, goal, cost in zip(sequence[:-1], sequence[1:], steps[1:], strict=True):
            assert cost == GRID_DISTANCE[frozenset((previous, goal))] + 1, (sequence, steps)
        assert 1 <= steps[0] <= 4  # at most 3 moves on a 2x3 grid, then the press
    matrix = result.confusion()
    np.testing.assert_array_equal(np.diag(matrix), [24] * 4)
    assert matrix.sum() == 96
    assert result.summary()["keys_asked"] == 96


def test_pressing_at_once_types_one_key_of_each_sequence_right(arrows_env):
    """The sensor never moves: every key of a sequence gets the same press (or none, on a NONE cell)."""
    result = type_sequences(PressAtOnce(), arrows_env, paper_sequences("arrows"), seed=0)
    on_a_key = [len(set(typed)) == 1 and typed[0] != NONE for typed in result.typed]
    assert all(len(set(typed)) == 1 for typed in result.typed)
    assert result.accuracy == pytest.approx(0.25 * np.mean(on_a_key))  # each key once per permutation
    assert 0 < np.mean(on_a_key) < 1  # random starts put the sensor on keys and on NONE cells
    for typed, steps in zip(result.typed, result.steps, strict=True):
        # A press on a key ends each attempt at once; on a NONE cell nothing registers: 25-step time-outs.
        assert steps == ([25] * 4 if typed[0] == NONE else [1] * 4)
    assert result.total_steps == sum(map(sum, result.steps))
    assert result.columns[-2:] == (OTHER, NONE)


def test_typing_continues_from_where_the_last_press_left_the_sensor(arrows_env):
    arrows_env.reset(seed=0, options={"goal_key": "UP"})
    for action in itertools.islice(itertools.cycle([0, 3]), 3):
        arrows_env.step(action)
    moved = arrows_env.unwrapped._core.cell[0].copy()
    for seed in range(5):  # a new random pose would differ for some seed; the kept one never does
        _, info = arrows_env.reset(seed=seed, options={"goal_key": "LEFT", "keep_pose": True})
        np.testing.assert_array_equal(arrows_env.unwrapped._core.cell[0], moved)
        assert info["goal_key"] == "LEFT"
    with pytest.raises(ValueError, match="unknown reset options"):
        arrows_env.reset(options={"keep_poses": True})


def test_the_released_protocol_starts_every_key_from_a_random_pose(arrows_env):
    """The released scripts reset before every key: pressing at once then types each key of a sequence
    from wherever its own random start fell, not one key for the whole sequence."""
    paper = type_sequences(PressAtOnce(), arrows_env, paper_sequences("arrows"), seed=0)
    released = type_sequences(
        PressAtOnce(), arrows_env, paper_sequences("arrows"), seed=0, protocol="released"
    )
    assert all(len(set(typed)) == 1 for typed in paper.typed)
    assert any(len(set(typed)) > 1 for typed in released.typed)
    oracle = type_sequences(
        Oracle(arrows_env), arrows_env, paper_sequences("arrows"), seed=3, protocol="released"
    )
    assert oracle.accuracy == 1.0
    assert all(1 <= steps <= 4 for sequence in oracle.steps for steps in sequence)  # each from its own start
    with pytest.raises(ValueError, match="protocol must be one of"):
        type_sequences(Oracle(arrows_env), arrows_env, [("UP",)], protocol="robot")


def test_unknown_keys_in_a_sequence_are_refused(arrows_env):
    with pytest.raises(ValueError, match="not among the task's keys"):
        type_sequences(PressAtOnce(), arrows_env, [("UP", "Q")])


def test_keep_pose_needs_an_earlier_reset(env_datasets):
    env = gym.make(ARROWS, dataset=env_datasets[ARROWS])
    with pytest.raises(ValueError, match="earlier reset"):
        env.reset(options={"keep_pose": True})
