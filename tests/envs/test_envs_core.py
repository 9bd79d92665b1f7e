"""The single braille environments: Gymnasium contract, determinism, rewards, rules and rendering.

Every test runs on small explicit datasets (built once per session under pytest's
temporary folder); only ``test_default_dataset_is_generated_into_the_cache`` uses
a default dataset, generated into a temporary cache folder.
"""

from __future__ import annotations

import pickle
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import given, settings
from hypothesis import strategies as st

import tactile_braille  # noqa: F401 - registers the environments
from envs_helpers import assert_same
from tactile_braille.datasets import default_dataset_path
from tactile_braille.envs import ENV_IDS, MAX_EPISODE_STEPS
from tactile_braille.envs.continuous import ContinuousBrailleEnv
from tactile_braille.envs.core import action_effects, compute_reward
from tactile_braille.envs.discrete import DiscreteBrailleEnv
from tactile_braille.envs.oracle import oracle_action
from tactile_braille.envs.rendering import save_gif
from tactile_braille.envs.tasks import DISCRETE_ACTIONS
from tactile_braille.keyboard.layout import NONE_KEY
from tactile_braille.rigs.virtual import VirtualRig

DISCRETE_IDS = tuple(i for i in ENV_IDS if "/Discrete" in i)
CONTINUOUS_IDS = tuple(i for i in ENV_IDS if "/Continuous" in i)
SIMULATED_BACKENDS = ("dataset", "render")
UP, DOWN, LEFT, RIGHT, PRESS = (DISCRETE_ACTIONS.index(a) for a in ("UP", "DOWN", "LEFT", "RIGHT", "PRESS"))
MOVES = {UP: (-1, 0), DOWN: (1, 0), LEFT: (0, -1), RIGHT: (0, 1)}


# ----------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="session")
def datasets(env_datasets) -> dict[str, Path]:
    """Small datasets keyed by env id (see ``env_datasets`` in conftest.py)."""
    return env_datasets


def _backend_kwargs(env_id: str, backend: str, datasets: dict[str, Path]) -> dict:
    return {"dataset": datasets[env_id]} if backend == "dataset" else {"backend": backend}


@pytest.fixture
def make(datasets):
    """``make(env_id, backend="dataset", **kwargs)``: ``gym.make`` on the small datasets; closes after."""
    made = []

    def factory(env_id: str, backend: str = "dataset", **kwargs):
        env = gym.make(env_id, **_backend_kwargs(env_id, backend, datasets), **kwargs)
        made.append(env)
        return env

    yield factory
    for env in made:
        env.close()


# ----------------------------------------------------------------------------- helpers
def _actions(env_id: str, count: int, seed: int = 123) -> list:
    """A fixed action sequence: discrete indices (some PRESSes) or continuous actions in [-1, 1]."""
    rng = np.random.default_rng(seed)
    if env_id in DISCRETE_IDS:
        return [int(a) for a in rng.integers(0, len(DISCRETE_ACTIONS), count)]
    return list(rng.uniform(-1.0, 1.0, (count, 3)).astype(np.float32))


def _rollout(env, seed: int, actions: list, reset_first: bool = True) -> list[tuple]:
    """Step through ``actions``, resetting (unseeded) after every episode end; returns every output."""
    records = []
    if reset_first:
        records.append(env.reset(seed=seed))
    for action in actions:
        observation, reward, terminated, truncated, info = env.step(action)
        records.append((observation, reward, terminated, truncated, info))
        if terminated or truncated:
            records.append(env.reset())
    return records


def _one_hot(index: int, size: int) -> np.ndarray:
    vector = np.zeros(size, dtype=np.float32)
    if index >= 0:
        vector[index] = 1.0
    return vector


def _non_press_action(env_id: str, t: int):
    """An action that never presses a key: a grid move, or a light 2 mm tap."""
    if env_id in DISCRETE_IDS:
        return (UP, LEFT, DOWN, RIGHT)[t % 4]
    return np.array([0.3 * (-1) ** t, 0.3 * (-1) ** (t // 2), -1.0], dtype=np.float32)


# ----------------------------------------------------------------------------- 1. env checker
@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_check_env_passes_without_warnings(env_id, backend, datasets):
    env = gym.make(env_id, **_backend_kwargs(env_id, backend, datasets))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)
    env.close()


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_check_env_passes_with_rgb_array_rendering(env_id, datasets):
    env = gym.make(env_id, dataset=datasets[env_id], render_mode="rgb_array")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)
    env.close()


# ----------------------------------------------------------------------------- 2. registry, time limit
def test_all_four_ids_are_registered():
    assert len(ENV_IDS) == 4
    assert set(ENV_IDS) <= set(gym.registry)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_registry_max_episode_steps_is_25(env_id):
    assert MAX_EPISODE_STEPS == 25
    assert gym.spec(env_id).max_episode_steps == 25


@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_truncated_after_25_steps_through_gym_make(env_id, backend, make):
    env = make(env_id, backend)
    assert env.spec.max_episode_steps == 25
    env.reset(seed=0)
    for t in range(1, 26):
        _, reward, terminated, truncated, _ = env.step(_non_press_action(env_id, t))
        assert not terminated, f"a non-pressing action terminated at step {t}"
        assert reward == 0.0
        assert truncated == (t == 25), f"step {t}: truncated={truncated}"


# ----------------------------------------------------------------------------- 3. determinism
@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_same_seed_gives_identical_rollouts(env_id, backend, make):
    actions = _actions(env_id, 40)
    first = _rollout(make(env_id, backend), seed=11, actions=actions)
    second = _rollout(make(env_id, backend), seed=11, actions=actions)
    assert_same(first, second)
    # The episodes do end (the comparison spans resets) and rewards are seen.
    assert len(first) > len(actions) + 1


@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_reseeding_the_same_env_repeats_the_episode(env_id, backend, make):
    env = make(env_id, backend)
    actions = _actions(env_id, 10, seed=5)
    first = _rollout(env, seed=3, actions=actions)
    second = _rollout(env, seed=3, actions=actions)
    assert_same(first, second)


@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_different_seeds_give_different_goals_and_starts(env_id, backend, make):
    env = make(env_id, backend)
    goals, starts = set(), set()
    for seed in range(10):
        _, info = env.reset(seed=seed)
        goals.add(info["goal_key"])
        starts.add(tuple(np.round(info["sensor_pose_mm"][:2], 6)))
    assert len(goals) > 1
    assert len(starts) > 1


# ----------------------------------------------------------------------------- 4. pickling
@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_pickled_env_continues_identically(env_id, backend, make):
    env = make(env_id, backend)
    _rollout(env, seed=21, actions=_actions(env_id, 3, seed=1))
    clone = pickle.loads(pickle.dumps(env))
    actions = _actions(env_id, 30, seed=2)
    assert_same(
        _rollout(env, seed=0, actions=actions, reset_first=False),
        _rollout(clone, seed=0, actions=actions, reset_first=False),
    )
    clone.close()


@pytest.mark.parametrize("env_id", DISCRETE_IDS)
def test_pickled_env_keeps_its_step_count(env_id, make):
    env = make(env_id)
    env.reset(seed=4)
    for t in range(10):
        env.step(_non_press_action(env_id, t))
    clone = pickle.loads(pickle.dumps(env))
    for t in range(10, 25):
        truncated = env.step(_non_press_action(env_id, t))[3]
        assert clone.step(_non_press_action(env_id, t))[3] == truncated == (t == 24)


# ----------------------------------------------------------------------------- 5. no shared memory
@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_returned_arrays_never_share_memory(env_id, backend, make):
    env = make(env_id, backend)
    arrays = []
    observation, info = env.reset(seed=2)
    arrays += [*observation.values(), info["sensor_pose_mm"]]
    for action in _actions(env_id, 6, seed=9):
        observation, _, terminated, truncated, info = env.step(action)
        arrays += [*observation.values(), info["sensor_pose_mm"]]
        if terminated or truncated:
            observation, info = env.reset()
            arrays += [*observation.values(), info["sensor_pose_mm"]]
    for i, a in enumerate(arrays):
        for b in arrays[i + 1 :]:
            assert not np.shares_memory(a, b)


@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_mutating_returned_arrays_does_not_change_later_ones(env_id, backend, make):
    mutated, clean = make(env_id, backend), make(env_id, backend)
    actions = _actions(env_id, 12, seed=4)

    def scribble(observation, info):
        for value in observation.values():
            value[...] = 1 if value.dtype == np.uint8 else 0.5
        info["sensor_pose_mm"][...] = -1.0

    first, clean_first = mutated.reset(seed=8), clean.reset(seed=8)
    assert_same(first, clean_first)
    scribble(*first)
    for action in actions:
        out, clean_out = mutated.step(action), clean.step(action)
        assert_same(out, clean_out)
        scribble(out[0], out[4])
        if out[2] or out[3]:
            out, clean_out = mutated.reset(), clean.reset()
            assert_same(out, clean_out)
            scribble(*out)


# ----------------------------------------------------------------------------- 6. rewards
@pytest.fixture(scope="module")
def reward_functions(datasets):
    """compute_reward of an environment with 4 goal keys and of one with 27."""
    arrows = gym.make(
        "tactile_braille/DiscreteArrows-v0", dataset=datasets["tactile_braille/DiscreteArrows-v0"]
    )
    alphabet = gym.make(
        "tactile_braille/ContinuousAlphabet-v0", dataset=datasets["tactile_braille/ContinuousAlphabet-v0"]
    )
    assert len(arrows.unwrapped.goal_keys) == 4
    assert len(alphabet.unwrapped.goal_keys) == 27
    yield {4: arrows.unwrapped.compute_reward, 27: alphabet.unwrapped.compute_reward}
    arrows.close()
    alphabet.close()


@settings(max_examples=150, deadline=None)
@given(size=st.sampled_from([4, 27]), data=st.data())
def test_compute_reward_matches_reference_single_and_batched(reward_functions, size, data):
    """Goal index -1 stands for the zero vector (no key pressed, or a key outside the task)."""
    index = st.integers(-1, size - 1)
    pairs = data.draw(st.lists(st.tuples(index, index), min_size=1, max_size=12), label="pairs")
    achieved = np.stack([_one_hot(a, size) for a, _ in pairs])
    desired = np.stack([_one_hot(d, size) for _, d in pairs])
    expected = np.array([1.0 if a >= 0 and a == d else 0.0 for a, d in pairs])

    for function in (reward_functions[size], compute_reward):
        batched = np.asarray(function(achieved, desired, [{} for _ in pairs]))
        assert batched.shape == (len(pairs),)
        np.testing.assert_array_equal(batched, expected)
        for i in range(len(pairs)):
            single = np.asarray(function(achieved[i], desired[i], {}))
            assert single.shape == ()
            assert float(single) == expected[i]


@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("policy", ["random", "oracle"])
def test_step_reward_equals_compute_reward(env_id, backend, policy, make):
    env = make(env_id, backend)
    env.action_space.seed(17)
    rewards = []
    for episode in range(8):
        observation, info = env.reset(seed=100 + episode)
        done = False
        while not done:
            action = oracle_action(env) if policy == "oracle" else env.action_space.sample()
            observation, reward, terminated, truncated, info = env.step(action)
            recomputed = env.unwrapped.compute_reward(
                observation["achieved_goal"], observation["desired_goal"], info
            )
            assert reward == float(recomputed)
            assert isinstance(info["is_success"], bool)
            assert info["is_success"] == (reward == 1.0)
            assert reward in (0.0, 1.0)
            if reward == 1.0:
                assert terminated
            rewards.append(reward)
            done = terminated or truncated
    if policy == "oracle":
        assert sum(rewards) > 0  # the check covered rewarded steps too


# ----------------------------------------------------------------------------- 7. semantics
def _reset_at_cell(env, cell: tuple[int, int], seed: int):
    """Reset, then put the sensor on ``cell`` of the key grid (no tap is made there)."""
    env.reset(seed=seed)
    env.unwrapped._core.cell[0] = cell


@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", DISCRETE_IDS)
def test_discrete_moves_follow_the_grid_and_stop_at_its_edges(env_id, backend, make):
    env = make(env_id, backend)
    core = env.unwrapped._core
    rows, cols = core.grid_codes.shape
    off_grid_moves = 0
    for r in range(rows):
        for c in range(cols):
            for action, (dr, dc) in MOVES.items():
                _reset_at_cell(env, (r, c), seed=r * 1000 + c * 10 + action)
                _, reward, terminated, truncated, info = env.step(action)
                inside = 0 <= r + dr < rows and 0 <= c + dc < cols
                off_grid_moves += not inside
                target = (r + dr, c + dc) if inside else (r, c)
                assert tuple(core.cell[0]) == target
                np.testing.assert_allclose(info["sensor_pose_mm"][:2], core.cell_positions_mm[target])
                # The reading tap, short of actuation; NONE cells are tapped in the air.
                in_air = core.grid_codes[target] < 0
                assert info["sensor_pose_mm"][2] == (0.0 if in_air else 5.0)
                assert not terminated and not truncated and reward == 0.0
                assert info["pressed_key"] is None
    assert off_grid_moves == 2 * (rows + cols)


@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", DISCRETE_IDS)
def test_press_on_every_key_cell_terminates_with_that_key(env_id, backend, make):
    env = make(env_id, backend)
    braille = env.unwrapped
    grid = braille.task.key_grid
    key_cells = [(r, c) for r in range(grid.shape[0]) for c in range(grid.shape[1]) if grid[r, c] != NONE_KEY]
    assert key_cells
    for i, (r, c) in enumerate(key_cells):
        _reset_at_cell(env, (r, c), seed=i)
        observation, reward, terminated, truncated, info = env.step(PRESS)
        key = str(grid[r, c])
        assert terminated and not truncated
        assert info["pressed_key"] == key
        assert info["sensor_pose_mm"][2] == 8.0
        np.testing.assert_array_equal(
            observation["achieved_goal"], _one_hot(braille.goal_keys.index(key), len(braille.goal_keys))
        )
        assert reward == float(key == info["goal_key"])
        assert info["is_success"] == (key == info["goal_key"])


@pytest.mark.parametrize("env_id", DISCRETE_IDS)
def test_a_discrete_cell_shows_one_of_the_datasets_taps_of_its_key_drawn_anew_at_each_tap(env_id, make):
    """The released simulator's rule: a tap on a cell shows one of the stored jittered taps of the key
    under it (of a NONE tap on a NONE cell), drawn at random each time, not one image per cell."""
    from tactile_braille.datasets.store import load_dataset

    env = make(env_id)
    dataset = load_dataset(env.unwrapped.dataset.path)
    labels, stored = dataset.label_names(), dataset.observations
    grid = env.unwrapped.task.key_grid
    cells = {str(grid[r, c]): (r, c) for r in range(grid.shape[0]) for c in range(grid.shape[1])}
    for key, cell in sorted(cells.items()):
        taps = stored[labels == key]
        assert len(taps) == 3  # the test datasets' taps per key
        seen = []
        for i in range(24):
            _reset_at_cell(env, cell, seed=i)
            image = env.step(PRESS)[0]["observation"][..., 0]  # a press shows the key's taps too
            seen += [j for j, tap in enumerate(taps) if np.array_equal(tap, image)]
        assert len(seen) == 24, f"{key}: a tap showed an image that is not one of its stored taps"
        assert set(seen) == {0, 1, 2}, f"{key}: drawn anew at each tap, not fixed per cell"


@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", DISCRETE_IDS)
def test_press_on_a_none_cell_does_not_terminate(env_id, backend, make):
    env = make(env_id, backend)
    core = env.unwrapped._core
    none_cells = [tuple(int(v) for v in cell) for cell in np.argwhere(core.grid_codes == -1)]
    assert none_cells
    for i, cell in enumerate(none_cells):
        _reset_at_cell(env, cell, seed=i)
        observation, reward, terminated, truncated, info = env.step(PRESS)
        assert not terminated and not truncated
        assert reward == 0.0 and not info["is_success"]
        assert info["pressed_key"] is None
        assert tuple(core.cell[0]) == cell
        assert not observation["achieved_goal"].any()


@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", DISCRETE_IDS)
def test_pressing_a_wrong_key_terminates_without_reward(env_id, backend, make):
    env = make(env_id, backend)
    grid = env.unwrapped.task.key_grid
    for seed in range(6):
        _, info = env.reset(seed=seed)
        wrong = next(
            (r, c)
            for r in range(grid.shape[0])
            for c in range(grid.shape[1])
            if grid[r, c] not in (NONE_KEY, info["goal_key"])
        )
        env.unwrapped._core.cell[0] = wrong
        observation, reward, terminated, _, info = env.step(PRESS)
        assert terminated
        assert reward == 0.0 and info["is_success"] is False
        assert info["pressed_key"] == grid[wrong]
        assert observation["achieved_goal"].sum() == 1.0
        assert not np.array_equal(observation["achieved_goal"], observation["desired_goal"])


@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", CONTINUOUS_IDS)
def test_continuous_deep_tap_on_the_goal_key_terminates_with_it(env_id, backend, make):
    env = make(env_id, backend)
    for seed in range(4):
        _, info = env.reset(seed=seed)
        for _ in range(25):
            observation, reward, terminated, _, info = env.step(oracle_action(env))
            if terminated:
                break
        assert terminated
        assert info["pressed_key"] == info["goal_key"]
        assert reward == 1.0
        np.testing.assert_array_equal(observation["achieved_goal"], observation["desired_goal"])


@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_goals_and_achieved_goals_in_observations(env_id, backend, make):
    env = make(env_id, backend)
    goal_keys = env.unwrapped.goal_keys
    for seed in range(5):
        observation, info = env.reset(seed=seed)
        desired = _one_hot(goal_keys.index(info["goal_key"]), len(goal_keys))
        np.testing.assert_array_equal(observation["desired_goal"], desired)
        assert not observation["achieved_goal"].any()
        assert info["pressed_key"] is None and info["is_success"] is False
        for t in range(3):
            observation, _, terminated, _, info = env.step(_non_press_action(env_id, t))
            assert not terminated
            np.testing.assert_array_equal(observation["desired_goal"], desired)
            assert info["goal_key"] == goal_keys[int(desired.argmax())]
            assert not observation["achieved_goal"].any()


@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", DISCRETE_IDS)
def test_discrete_previous_action_is_zero_then_one_hot(env_id, backend, make):
    env = make(env_id, backend)
    observation, _ = env.reset(seed=0)
    assert observation["previous_action"].dtype == np.float32
    np.testing.assert_array_equal(observation["previous_action"], np.zeros(len(DISCRETE_ACTIONS)))
    for action in (UP, RIGHT, DOWN, LEFT, LEFT, UP):
        observation, *_ = env.step(action)
        np.testing.assert_array_equal(observation["previous_action"], _one_hot(action, len(DISCRETE_ACTIONS)))
    observation, _ = env.reset()
    assert not observation["previous_action"].any()


@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", CONTINUOUS_IDS)
def test_continuous_previous_action_is_zero_then_the_clipped_action(env_id, backend, make):
    env = make(env_id, backend)
    observation, _ = env.reset(seed=0)
    np.testing.assert_array_equal(observation["previous_action"], np.zeros(3))
    action = np.array([0.25, -0.5, -1.0], dtype=np.float32)
    observation, *_ = env.step(action)
    assert observation["previous_action"].dtype == np.float32
    np.testing.assert_array_equal(observation["previous_action"], action)
    observation, _ = env.reset()
    assert not observation["previous_action"].any()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_action_effects_read_what_each_step_did_off_its_previous_action(env_id, make):
    """The planar move each observation's previous action documents is the move the sensor made, or
    one the grid's or the workspace's edge shortened (never lengthened or reversed); presses and tap
    depths are read as documented; a reset did nothing known."""
    env = make(env_id)
    continuous = env.unwrapped.continuous
    scale = env.unwrapped.task.max_move_mm
    observation, info = env.reset(seed=3)
    assert np.isnan(action_effects(observation["previous_action"][None], continuous)).all()
    exact = 0
    core = env.unwrapped._core

    def where():  # the sensor's position: in mm, or its (row, column) on the discrete key grid
        return info["sensor_pose_mm"][:2] / scale if continuous else core.cell[0].astype(float)

    for action in _actions(env_id, 60, seed=4):
        before = where()
        observation, _, terminated, truncated, info = env.step(action)
        effect = action_effects(observation["previous_action"][None], continuous)[0]
        moved = where() - before
        if continuous:
            assert effect[2] == pytest.approx(float(np.clip(action[2], -1, 1)))
        else:
            assert effect[2] == (action == PRESS)
            assert effect[:2].tolist() == list(MOVES.get(action, (0, 0)))
        assert np.all(np.abs(moved) <= np.abs(effect[:2]) + 1e-4) and np.all(moved * effect[:2] >= 0)
        exact += np.allclose(moved, effect[:2], atol=1e-4)
        if terminated or truncated:
            observation, info = env.reset()
    assert exact >= 25  # most steps move as their action says


@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", CONTINUOUS_IDS)
def test_continuous_actions_beyond_bounds_are_clipped(env_id, backend, make):
    clipped_env, bounded_env = make(env_id, backend), make(env_id, backend)
    assert_same(clipped_env.reset(seed=6), bounded_env.reset(seed=6))
    wild = np.array([3.0, -7.5, 0.5], dtype=np.float32)
    bounded = np.array([1.0, -1.0, 0.5], dtype=np.float32)
    out, bounded_out = clipped_env.step(wild), bounded_env.step(bounded)
    np.testing.assert_array_equal(out[0]["previous_action"], bounded)
    assert_same(out, bounded_out)
    assert out[4]["sensor_pose_mm"][2] == pytest.approx(6.5)  # depth 5 + 3 * 0.5 mm


@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", CONTINUOUS_IDS)
def test_continuous_sensor_stays_in_the_workspace(env_id, backend, make):
    env = make(env_id, backend)
    task = env.unwrapped.task
    (x_low, x_high), (y_low, y_high) = task.workspace_mm
    origin = np.array(task.frame_origin_mm)
    env.reset(seed=1)
    corners = set()
    for direction in [(1, 1)] * 10 + [(-1, -1)] * 10:
        _, _, terminated, _, info = env.step(np.array([*direction, -1.0], dtype=np.float32))
        assert not terminated
        x, y = info["sensor_pose_mm"][:2] - origin
        assert x_low - 1e-9 <= x <= x_high + 1e-9 and y_low - 1e-9 <= y <= y_high + 1e-9
        corners.add((round(x, 6), round(y, 6)))
    # Pushed long enough, the sensor ends in the workspace's corners.
    assert (x_high, y_high) in corners
    assert (x_low, y_low) in corners


@pytest.mark.parametrize("env_id", CONTINUOUS_IDS)
def test_an_overrun_edge_taps_inside_and_keeps_the_commanded_position(env_id, make):
    """``edges="overrun"`` (the released simulator's): pushed into a corner, the taps stay at the
    corner as with ``"stop"``, but the commanded position runs on, so the same moves back leave the
    sensor further out than where the stopping edge's sensor returns."""
    stopping, overrunning = make(env_id), make(env_id, edges="overrun")
    task = stopping.unwrapped.task
    (x_low, x_high), (y_low, y_high) = task.workspace_mm
    origin = np.array(task.frame_origin_mm)
    assert_same(stopping.reset(seed=3), overrunning.reset(seed=3))
    out, back = np.array([1.0, 1.0, -1.0], dtype=np.float32), np.array([-1.0, -1.0, -1.0], dtype=np.float32)
    pushes = int(np.ceil(max(x_high - x_low, y_high - y_low) / task.max_move_mm)) + 2
    for _ in range(pushes):  # far enough to reach the corner and run past it
        stop_step, overrun_step = stopping.step(out), overrunning.step(out)
        assert_same(stop_step, overrun_step)  # the same taps while the sensor is pushed into the corner
    np.testing.assert_allclose(overrun_step[4]["sensor_pose_mm"][:2] - origin, (x_high, y_high))
    stop_step, overrun_step = stopping.step(back), overrunning.step(back)
    stop_xy = stop_step[4]["sensor_pose_mm"][:2] - origin
    overrun_xy = overrun_step[4]["sensor_pose_mm"][:2] - origin
    np.testing.assert_allclose(stop_xy, np.array([x_high, y_high]) - task.max_move_mm)
    assert (overrun_xy > stop_xy + 1.0).all()  # the move back first undoes the overrun
    assert x_low <= overrun_xy[0] <= x_high and y_low <= overrun_xy[1] <= y_high  # taps stay inside


@pytest.mark.parametrize("env_id", CONTINUOUS_IDS)
def test_an_overrun_edge_is_kept_between_the_keys_of_a_sequence(env_id, make):
    env = make(env_id, edges="overrun")
    env.reset(seed=0)
    for _ in range(12):
        env.step(np.array([1.0, 1.0, -1.0], dtype=np.float32))
    commanded = env.unwrapped._core.position_mm[0].copy()
    assert (commanded > np.array(env.unwrapped.task.workspace_mm)[:, 1]).all()
    env.reset(options={"keep_pose": True})  # typing without a reset: the sensor is where it was
    np.testing.assert_array_equal(env.unwrapped._core.position_mm[0], commanded)
    env.reset()  # a new episode starts inside the workspace
    assert (env.unwrapped._core.position_mm[0] <= np.array(env.unwrapped.task.workspace_mm)[:, 1]).all()


@pytest.mark.parametrize("env_id", CONTINUOUS_IDS)
def test_the_released_depth_lookup_reads_the_stored_tap_2_mm_deeper(env_id, make):
    """``tap_depth="released"``: the released simulator compared the commanded 2-8 mm with its data's
    0-6 mm labels, so a tap reads the sample 2 mm deeper (the deepest from 6 mm on); the pose reported
    is the commanded one."""
    released, commanded = make(env_id, tap_depth="released"), make(env_id)
    for seed, (depth, deeper) in enumerate([(-1.0, -1 / 3), (-2 / 3, 0.0), (1 / 3, 1.0), (1.0, 1.0)]):
        released.reset(seed=seed)
        commanded.reset(seed=seed)
        move = np.array([0.3, -0.2], dtype=np.float32)
        ours = released.step(np.array([*move, depth], dtype=np.float32))
        theirs = commanded.step(np.array([*move, deeper], dtype=np.float32))
        np.testing.assert_array_equal(ours[0]["observation"], theirs[0]["observation"])
        assert (ours[1], ours[2], ours[4]["pressed_key"]) == (theirs[1], theirs[2], theirs[4]["pressed_key"])
        np.testing.assert_allclose(ours[4]["sensor_pose_mm"][:2], theirs[4]["sensor_pose_mm"][:2])
        assert ours[4]["sensor_pose_mm"][2] == pytest.approx(5.0 + 3.0 * depth)  # as commanded
    with pytest.raises(ValueError, match="on the dataset backend"):
        make(env_id, "render", tap_depth="released")


def test_the_released_key_grid_puts_z_under_s_and_the_world_records_it(make):
    env_id = "tactile_braille/DiscreteAlphabet-v0"
    rig, released = make(env_id), make(env_id, key_grid="released")
    assert "key_grid" not in rig.unwrapped.world and released.unwrapped.world["key_grid"] == "released"
    for env, under_a, under_s in ((rig, "Z", "X"), (released, NONE_KEY, "Z")):
        grid = env.unwrapped.task.key_grid
        assert grid[2, 0] == under_a and grid[2, 1] == under_s
        assert sorted(set(grid.ravel()) - {NONE_KEY}) == sorted(env.unwrapped.goal_keys)
    # The moves follow the grid: from S, DOWN then PRESS presses Z in the released grid only.
    for env, pressed in ((rig, "X"), (released, "Z")):
        env.reset(seed=0)
        env.unwrapped._core.cell[0] = (1, 1)  # S
        env.step(DOWN)
        *_, info = env.step(PRESS)
        assert info["pressed_key"] == pressed
    np.testing.assert_allclose(  # Z's cell lies at Z in both grids
        rig.unwrapped._core.cell_positions_mm[2, 0], released.unwrapped._core.cell_positions_mm[2, 1]
    )
    with pytest.raises(ValueError, match="key_grid='released' is the discrete braille tasks' grid"):
        make("tactile_braille/ContinuousArrows-v0", key_grid="released")
    with pytest.raises(ValueError, match="key_grid must be one of"):
        make(env_id, key_grid="qwertz")


@pytest.mark.parametrize("env_id", DISCRETE_IDS)
def test_an_overrun_edge_is_refused_on_a_discrete_task(env_id, make):
    with pytest.raises(ValueError, match="edges='overrun' is the continuous braille tasks'"):
        make(env_id, edges="overrun")
    with pytest.raises(ValueError, match="edges must be one of"):
        make(env_id, edges="wrap")
    with pytest.raises(ValueError, match="tap_depth='released' is the released simulator's lookup"):
        make(env_id, tap_depth="released")


@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_reset_goal_key_option(env_id, backend, make):
    env = make(env_id, backend)
    goal_keys = env.unwrapped.goal_keys
    goal = "UP" if "Arrows" in env_id else "Q"
    for seed in range(6):
        observation, info = env.reset(seed=seed, options={"goal_key": goal})
        assert info["goal_key"] == goal
        np.testing.assert_array_equal(
            observation["desired_goal"], _one_hot(goal_keys.index(goal), len(goal_keys))
        )
    with pytest.raises(ValueError, match="goal_key"):
        env.reset(seed=0, options={"goal_key": "NOT_A_KEY"})
    wrong_task = "Q" if "Arrows" in env_id else "UP"
    with pytest.raises(ValueError, match=wrong_task):
        env.reset(seed=0, options={"goal_key": wrong_task})


# ----------------------------------------------------------------------------- 8. bad actions
BAD_CONTINUOUS = [
    pytest.param(np.array([np.nan, 0.0, 0.0], dtype=np.float32), "finite", id="nan"),
    pytest.param(np.array([0.0, np.inf, 0.0]), "finite", id="inf"),
    pytest.param(np.zeros(2, dtype=np.float32), "shape", id="shape-2"),
    pytest.param(np.zeros((2, 3), dtype=np.float32), "shape", id="shape-2x3"),
    pytest.param(np.array(["a", "b", "c"]), "real numbers", id="str"),
    pytest.param(np.array([True, False, True]), "real numbers", id="bool"),
    pytest.param(np.array([0.1 + 1j, 0.0, 0.0]), "real numbers", id="complex"),
]
BAD_DISCRETE = [
    pytest.param(5, r"\[0, 5\)", id="5"),
    pytest.param(-1, r"\[0, 5\)", id="-1"),
    pytest.param(1.0, "integers", id="float"),
    pytest.param(np.float32(2.0), "integers", id="float32"),
    pytest.param("1", "integers", id="str"),
    pytest.param(np.array([1, 2]), "shape", id="shape-2"),
]


@pytest.mark.parametrize(("action", "message"), BAD_CONTINUOUS)
@pytest.mark.parametrize("env_id", CONTINUOUS_IDS)
def test_bad_continuous_actions_raise_value_error(env_id, action, message, make):
    env = make(env_id)
    observation, _ = env.reset(seed=0)
    with pytest.raises(ValueError, match=message):
        env.step(action)
    # A rejected action changes nothing.
    assert not env.unwrapped._core.previous_action.any()
    np.testing.assert_array_equal(env.unwrapped._core.images[0, :, :, None], observation["observation"])


@pytest.mark.parametrize(("action", "message"), BAD_DISCRETE)
@pytest.mark.parametrize("env_id", DISCRETE_IDS)
def test_bad_discrete_actions_raise_value_error(env_id, action, message, make):
    env = make(env_id)
    env.reset(seed=0)
    cell = tuple(env.unwrapped._core.cell[0])
    with pytest.raises(ValueError, match=message):
        env.step(action)
    assert tuple(env.unwrapped._core.cell[0]) == cell
    assert not env.unwrapped._core.previous_action.any()


@pytest.mark.parametrize("env_id", DISCRETE_IDS)
def test_discrete_actions_of_any_integer_type_are_accepted(env_id, make):
    env = make(env_id)
    env.reset(seed=0)
    for action in (UP, np.int64(DOWN), np.uint8(LEFT), np.array(RIGHT), np.int32(UP)):
        observation, *_ = env.step(action)
        np.testing.assert_array_equal(
            observation["previous_action"], _one_hot(int(action), len(DISCRETE_ACTIONS))
        )


@pytest.mark.parametrize("env_id", CONTINUOUS_IDS)
def test_wrong_shape_message_names_the_action_space_shape(env_id, make):
    env = make(env_id)
    env.reset(seed=0)
    with pytest.raises(ValueError) as error:
        env.step(np.zeros(2, dtype=np.float32))
    assert "(3,)" in str(error.value) and "(2,)" in str(error.value)


# ----------------------------------------------------------------------------- 11. rendering
@pytest.mark.parametrize("backend", SIMULATED_BACKENDS)
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_rgb_array_render_is_an_image_that_follows_the_episode(env_id, backend, make):
    env = make(env_id, backend, render_mode="rgb_array")
    env.reset(seed=3)
    before = env.render()
    assert isinstance(before, np.ndarray)
    assert before.dtype == np.uint8 and before.ndim == 3 and before.shape[2] == 3
    assert before.shape[0] > 10 and before.shape[1] > 10
    assert env.render() is not before  # a fresh frame each call
    env.step(_non_press_action(env_id, 0))
    after = env.render()
    assert after.shape == before.shape and after.dtype == np.uint8
    assert np.any(after != before)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_save_gif_writes_an_oracle_episode(env_id, make, tmp_path):
    env = make(env_id, render_mode="rgb_array")
    env.reset(seed=5)
    frames = [env.render()]
    done = False
    while not done:
        _, _, terminated, truncated, _ = env.step(oracle_action(env))
        frames.append(env.render())
        done = terminated or truncated
    assert len(frames) >= 2
    written = save_gif(frames, tmp_path / "episode.gif")
    assert Path(written) == tmp_path / "episode.gif"
    assert written.read_bytes()[:6] in (b"GIF89a", b"GIF87a")
    from PIL import Image

    with Image.open(written) as gif:
        assert gif.format == "GIF"
        assert gif.size == (frames[0].shape[1], frames[0].shape[0])
        assert gif.n_frames == len(frames)


def test_save_gif_refuses_no_frames(tmp_path):
    with pytest.raises(ValueError):
        save_gif([], tmp_path / "empty.gif")
    assert not (tmp_path / "empty.gif").exists()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_invalid_render_mode_raises(env_id, datasets):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # gym.make warns before the environment refuses
        with pytest.raises(ValueError, match="render_mode"):
            gym.make(env_id, dataset=datasets[env_id], render_mode="bogus")
    env_class = DiscreteBrailleEnv if env_id in DISCRETE_IDS else ContinuousBrailleEnv
    with pytest.raises(ValueError, match="render_mode"):
        env_class(dataset=datasets[env_id], render_mode="rgb")


# ----------------------------------------------------------------------------- backends, defaults
@pytest.mark.parametrize("env_id", DISCRETE_IDS)
def test_rig_backend_needs_a_rig_and_drives_the_one_given(env_id, make):
    with pytest.raises(ValueError, match="rig"):
        gym.make(env_id, backend="rig")
    with pytest.raises(ValueError, match="backend"):
        gym.make(env_id, backend="simulator")
    rig_env = gym.make(env_id, backend="rig", rig=VirtualRig())
    render_env = make(env_id, "render")
    actions = _actions(env_id, 15, seed=8)
    assert_same(_rollout(rig_env, seed=9, actions=actions), _rollout(render_env, seed=9, actions=actions))
    rig_env.close()


def test_default_dataset_is_generated_into_the_cache(_cache_in_tmp):
    """The one test on a default dataset (``keys-train``: a few seconds to generate)."""
    path = default_dataset_path("keys-train")
    assert path.parent == _cache_in_tmp
    env = gym.make("tactile_braille/DiscreteArrows-v0")
    assert path.exists()
    observation, info = env.reset(seed=0)
    assert observation["observation"].shape == (100, 100, 1)
    for _ in range(25):
        observation, reward, terminated, truncated, info = env.step(oracle_action(env))
        if terminated or truncated:
            break
    assert terminated and reward == 1.0 and info["is_success"]
    env.close()


# ----------------------------------------------------------------------------- the proprio observation
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_a_proprio_observation_adds_the_arms_pose_and_nothing_else(make, env_id):
    plain, proprio = make(env_id), make(env_id, proprio=True)
    assert "sensor_pose" not in plain.observation_space.spaces  # the paper's observation by default
    assert set(proprio.observation_space) == {*plain.observation_space, "sensor_pose"}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a bounded, well-formed space
        check_env(proprio.unwrapped, skip_render_check=True)
    actions = _actions(env_id, 40)
    observation, info = proprio.reset(seed=5)
    reference, _ = plain.reset(seed=5)
    for action in actions:
        assert proprio.observation_space.contains(observation)
        np.testing.assert_allclose(observation["sensor_pose"], info["sensor_pose_mm"], rtol=1e-6)
        assert_same({k: v for k, v in observation.items() if k != "sensor_pose"}, reference)
        observation, _, terminated, truncated, info = proprio.step(action)
        reference, _, *_ = plain.step(action)
        if terminated or truncated:
            observation, info = proprio.reset()
            reference, _ = plain.reset()


def test_the_vector_env_gives_the_proprio_observation_too(datasets):
    env_id = DISCRETE_IDS[0]
    vector = gym.make_vec(env_id, num_envs=3, dataset=datasets[env_id], proprio=True)
    observations, _ = vector.reset(seed=2)
    poses = vector.unwrapped._core.sensor_pose_mm()
    np.testing.assert_allclose(observations["sensor_pose"], poses, rtol=1e-6)
    assert len({tuple(p) for p in poses}) > 1  # each environment's own
    assert vector.single_observation_space["sensor_pose"].shape == (3,)
    with pytest.raises(TypeError, match="proprio must be True or False"):
        gym.make(env_id, dataset=datasets[env_id], proprio="yes")


# ----------------------------------------------------------------------------- frame noise
@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize(
    "env_id", ["tactile_braille/ContinuousAlphabet-v0", "tactile_braille/DiscreteArrows-v0"]
)
def test_frame_noise_draws_a_calibration_error_per_episode_from_the_envs_seed(env_id):
    env = gym.make(env_id, backend="render", frame_noise=(1.0, 2.0))
    check_env(env.unwrapped)
    rig = env.unwrapped._core.backend.rig

    def error():
        return (*rig.offset_mm, rig.rotation_deg)

    env.reset(seed=5)
    first = error()
    assert first != (0.0, 0.0, 0.0) and max(map(abs, first[:2])) <= 1.0 and abs(first[2]) <= 2.0
    env.step(env.action_space.sample())
    env.reset(options={"keep_pose": True})  # the next key of a sentence: the same calibration
    assert error() == first
    env.reset()
    assert error() != first  # a new episode: a new error
    env.reset(seed=5)
    assert error() == first  # the seed decides
    assert env.unwrapped.world["work_frame_noise"]["max_rotation_deg"] == 2.0
    with pytest.raises(ValueError, match="use backend='render', not 'dataset'"):
        gym.make(env_id, frame_noise=(1.0, 2.0))
