"""The vectorised braille environments (``gym.make_vec(..., vectorization_mode="vector_entry_point")``).

All tests run on small explicit datasets built once per session under pytest's
temporary folder.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

import tactile_braille  # noqa: F401 - registers the environments
from envs_helpers import assert_same
from tactile_braille.envs import ENV_IDS, MAX_EPISODE_STEPS
from tactile_braille.envs.core import compute_reward
from tactile_braille.envs.tasks import DISCRETE_ACTIONS

DISCRETE_IDS = tuple(i for i in ENV_IDS if "/Discrete" in i)
CONTINUOUS_IDS = tuple(i for i in ENV_IDS if "/Continuous" in i)
UP, DOWN, LEFT, RIGHT, PRESS = (DISCRETE_ACTIONS.index(a) for a in ("UP", "DOWN", "LEFT", "RIGHT", "PRESS"))
N = 8


# ----------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="session")
def vector_datasets(env_datasets) -> dict[str, Path]:
    """Small datasets keyed by env id (see ``env_datasets`` in conftest.py)."""
    return env_datasets


@pytest.fixture
def make_vec(vector_datasets):
    """``make_vec(env_id, num_envs=8, **kwargs)`` on the small datasets; closes after."""
    made = []

    def factory(env_id: str, num_envs: int = N, **kwargs):
        env = gym.make_vec(
            env_id,
            num_envs=num_envs,
            vectorization_mode="vector_entry_point",
            dataset=vector_datasets[env_id],
            **kwargs,
        )
        made.append(env)
        return env

    yield factory
    for env in made:
        env.close()


# ----------------------------------------------------------------------------- helpers
def _batch_actions(env_id: str, steps: int, num_envs: int = N, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if env_id in DISCRETE_IDS:
        return rng.integers(0, len(DISCRETE_ACTIONS), (steps, num_envs))
    return rng.uniform(-1.0, 1.0, (steps, num_envs, 3)).astype(np.float32)


def _non_press_batch(env_id: str, t: int, num_envs: int = N) -> np.ndarray:
    """Actions that never press: grid moves, or light 2 mm taps."""
    if env_id in DISCRETE_IDS:
        return np.full(num_envs, (UP, LEFT, DOWN, RIGHT)[t % 4])
    action = [0.3 * (-1) ** t, 0.3 * (-1) ** (t // 2), -1.0]
    return np.tile(np.array(action, dtype=np.float32), (num_envs, 1))


def _expected_previous_action(env_id: str, actions: np.ndarray) -> np.ndarray:
    if env_id in DISCRETE_IDS:
        return np.eye(len(DISCRETE_ACTIONS), dtype=np.float32)[actions]
    return np.clip(actions, -1.0, 1.0).astype(np.float32)


# ----------------------------------------------------------------------------- construction, spaces
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_make_vec_builds_batched_spaces(env_id, make_vec, vector_datasets):
    vec = make_vec(env_id)
    assert isinstance(vec, VectorEnv)
    assert vec.num_envs == N
    assert vec.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    single = gym.make(env_id, dataset=vector_datasets[env_id])
    assert vec.single_observation_space == single.observation_space
    assert vec.single_action_space == single.action_space
    assert vec.observation_space == batch_space(single.observation_space, N)
    assert vec.action_space == batch_space(single.action_space, N)
    single.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_step_returns_batched_arrays(env_id, make_vec):
    vec = make_vec(env_id)
    observations, infos = vec.reset(seed=0)
    assert observations in vec.observation_space
    assert infos["is_success"].shape == (N,) and not infos["is_success"].any()
    vec.action_space.seed(0)
    for _ in range(5):
        observations, rewards, terminated, truncated, infos = vec.step(vec.action_space.sample())
        assert observations in vec.observation_space
        for key, space in vec.single_observation_space.items():
            assert observations[key].shape == (N, *space.shape), key
            assert observations[key].dtype == space.dtype, key
        assert rewards.shape == (N,) and np.issubdtype(rewards.dtype, np.floating)
        assert terminated.shape == truncated.shape == (N,)
        assert terminated.dtype == truncated.dtype == np.bool_
        assert infos["is_success"].shape == (N,)
        np.testing.assert_array_equal(infos["is_success"], rewards == 1.0)


def test_vector_env_refuses_other_backends_and_empty_batches(make_vec):
    with pytest.raises(ValueError, match="dataset or render backend, not 'rig'"):
        make_vec("tactile_braille/DiscreteArrows-v0", backend="rig")
    with pytest.raises(ValueError, match="takes no dataset"):
        make_vec("tactile_braille/DiscreteArrows-v0", backend="render")
    with pytest.raises(ValueError, match="num_envs"):
        make_vec("tactile_braille/DiscreteArrows-v0", num_envs=0)
    with pytest.raises(ValueError, match="render_device is for the render backend"):
        make_vec("tactile_braille/DiscreteArrows-v0", render_device="cpu")
    with pytest.raises(ValueError, match="'gpu0' is not a torch device"):
        gym.make_vec("tactile_braille/DiscreteArrows-v0", num_envs=2, vectorization_mode="vector_entry_point",
                     backend="render", render_device="gpu0")  # fmt: skip


@pytest.mark.parametrize(
    "env_id", ["tactile_braille/DiscreteAlphabet-v0", "tactile_braille/ContinuousArrows-v0"]
)
def test_render_backend_vector_env_renders_batches_as_the_reference_would(env_id):
    """``make_vec(..., backend="render")``: batched spaces and steps; the batched renderer's taps are the
    single-tap renderer's (same seed: same rewards, images alike in over 99.2 % of pixels)."""
    runs = {}
    for device in ("cpu", None):
        vec = gym.make_vec(
            env_id,
            num_envs=4,
            vectorization_mode="vector_entry_point",
            backend="render",
            render_device=device,
        )
        assert vec.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
        assert vec.single_observation_space == gym.make(env_id, backend="render").observation_space
        observations, _ = vec.reset(seed=3)
        steps = [observations]
        for actions in _batch_actions(env_id, steps=4, num_envs=4, seed=3):
            observations, rewards, terminated, truncated, infos = vec.step(actions)
            assert observations in vec.observation_space
            assert rewards.shape == terminated.shape == truncated.shape == (4,)
            np.testing.assert_array_equal(infos["is_success"], rewards == 1.0)
            steps.append({**observations, "reward": rewards, "terminated": terminated})
        runs[device] = steps
        vec.close()
    for batched, reference in zip(runs["cpu"], runs[None], strict=True):
        for key in reference:
            if key != "observation":
                np.testing.assert_array_equal(batched[key], reference[key], err_msg=key)
        # Measured 0.9935-0.9974 per step; taps of other seeds agree in about 0.98.
        assert (batched["observation"] == reference["observation"]).mean() >= 0.992


def test_a_vector_env_refuses_a_step_before_its_first_reset(make_vec):
    from gymnasium.error import ResetNeeded

    env = make_vec("tactile_braille/DiscreteArrows-v0", num_envs=2)
    with pytest.raises(ResetNeeded, match="before its first reset"):
        env.step(np.zeros(2, dtype=np.int64))
    env.reset(seed=0)
    env.step(np.zeros(2, dtype=np.int64))


def test_a_single_env_refuses_a_step_after_termination_and_checks_its_options(vector_datasets):
    from gymnasium.error import ResetNeeded

    from tactile_braille.envs.oracle import oracle_action

    env_id = "tactile_braille/DiscreteArrows-v0"
    env = gym.make(env_id, dataset=vector_datasets[env_id])
    env.reset(seed=0)
    terminated = False
    while not terminated:  # the pose oracle goes to the goal key and presses it
        _, _, terminated, truncated, _ = env.step(oracle_action(env))
        assert not truncated
    with pytest.raises(ResetNeeded, match="call reset"):
        env.step(DISCRETE_ACTIONS.index("PRESS"))
    env.reset(options={"keep_pose": True})
    env.step(oracle_action(env))  # a reset lets it go on
    with pytest.raises(TypeError, match="keep_pose must be True or False, got 'no'"):
        env.reset(options={"keep_pose": "no"})


# ----------------------------------------------------------------------------- autoreset, truncation
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_next_step_autoreset_rules(env_id, make_vec):
    """Random actions over many episodes: sub-environments that ended last step are reset, others go on."""
    vec = make_vec(env_id)
    observations, _ = vec.reset(seed=3)
    actions = _batch_actions(env_id, 80, seed=1)
    ended = np.zeros(N, dtype=bool)
    lengths = np.zeros(N, dtype=np.int64)
    resets = goal_changes = terminations = 0
    for action in actions:
        previous_desired = observations["desired_goal"]
        observations, rewards, terminated, truncated, infos = vec.step(action)
        # The sub-environments that ended last step were reset: action ignored, reward 0, not ended.
        assert not terminated[ended].any() and not truncated[ended].any()
        assert not rewards[ended].any()
        assert not observations["previous_action"][ended].any()
        assert not observations["achieved_goal"][ended].any()
        assert not infos["is_success"][ended].any()
        resets += int(ended.sum())
        goal_changes += int((observations["desired_goal"][ended] != previous_desired[ended]).any(-1).sum())
        # The others stepped: same goal, their (clipped) action recorded, reward by compute_reward.
        going = ~ended
        np.testing.assert_array_equal(observations["desired_goal"][going], previous_desired[going])
        np.testing.assert_array_equal(
            observations["previous_action"][going], _expected_previous_action(env_id, action)[going]
        )
        recomputed = vec.unwrapped.compute_reward(
            observations["achieved_goal"], observations["desired_goal"], {}
        )
        np.testing.assert_array_equal(rewards[going], recomputed[going])
        np.testing.assert_array_equal(infos["is_success"], rewards == 1.0)
        # A termination is a key press; a reward needs one.
        assert (observations["achieved_goal"][rewards == 1.0].sum(-1) == 1).all()
        lengths = np.where(ended, 0, lengths + 1)
        # As gym.make's TimeLimit: the 25th step is truncated even when it also terminates.
        np.testing.assert_array_equal(truncated, lengths == MAX_EPISODE_STEPS)
        if env_id in DISCRETE_IDS:
            assert (action[terminated] == PRESS).all()
        terminations += int(terminated.sum())
        ended = terminated | truncated
    # The run did exercise resets, goal changes and terminations.
    assert resets > N and terminations > 0 and goal_changes > 0


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_truncation_after_25_steps_then_reset(env_id, make_vec):
    vec = make_vec(env_id)
    vec.reset(seed=5)
    for cycle in range(2):
        for t in range(1, MAX_EPISODE_STEPS + 1):
            _, rewards, terminated, truncated, _ = vec.step(_non_press_batch(env_id, t))
            assert not terminated.any(), f"cycle {cycle} step {t}"
            assert not rewards.any()
            assert truncated.all() if t == MAX_EPISODE_STEPS else not truncated.any(), (
                f"cycle {cycle} step {t}"
            )
        observations, rewards, terminated, truncated, _ = vec.step(_non_press_batch(env_id, 0))
        assert not terminated.any() and not truncated.any() and not rewards.any()
        assert not observations["previous_action"].any()  # reset, action ignored


@pytest.mark.parametrize("env_id", DISCRETE_IDS)
def test_one_sub_env_terminates_and_resets_while_the_others_continue(env_id, make_vec):
    vec = make_vec(env_id)
    vec.reset(seed=0)
    core = vec.unwrapped._core
    key_cell = np.argwhere(core.grid_codes >= 0)[0]
    core.cell[:] = key_cell  # everyone on a key
    action = np.full(N, UP)
    action[2] = PRESS
    observations, rewards, terminated, truncated, _ = vec.step(action)
    np.testing.assert_array_equal(terminated, np.arange(N) == 2)
    assert observations["achieved_goal"][2].sum() == 1.0
    assert not truncated.any()
    cells_before = core.cell.copy()
    observations, rewards, terminated, truncated, _ = vec.step(np.full(N, DOWN))
    assert not terminated.any() and not truncated.any() and rewards[2] == 0.0
    assert not observations["previous_action"][2].any() and not observations["achieved_goal"][2].any()
    others = np.arange(N) != 2
    np.testing.assert_array_equal(
        observations["previous_action"][others], np.eye(5, dtype=np.float32)[[DOWN] * 7]
    )
    rows = core.grid_codes.shape[0]
    np.testing.assert_array_equal(core.cell[others, 0], np.minimum(cells_before[others, 0] + 1, rows - 1))


def test_press_on_the_last_step_flags_like_the_single_env(make_vec, vector_datasets):
    env_id = "tactile_braille/DiscreteArrows-v0"
    single = gym.make(env_id, dataset=vector_datasets[env_id])
    single.reset(seed=0)
    single.unwrapped._core.cell[0] = (1, 1)  # DOWN: a key
    for t in range(1, MAX_EPISODE_STEPS):
        single.step((UP, DOWN)[t % 2])  # between the UP and DOWN keys
    _, _, single_terminated, single_truncated, _ = single.step(PRESS)
    assert single_terminated and single_truncated  # Gymnasium's TimeLimit

    vec = make_vec(env_id, num_envs=1)
    vec.reset(seed=0)
    vec.unwrapped._core.cell[0] = (1, 1)
    for t in range(1, MAX_EPISODE_STEPS):
        vec.step(np.array([(UP, DOWN)[t % 2]]))
    _, _, terminated, truncated, _ = vec.step(np.array([PRESS]))
    assert terminated[0]
    assert truncated[0] == single_truncated


def test_press_on_the_last_step_terminates_in_both(make_vec, vector_datasets):
    """What the single and vector environments agree on when the 25th step presses a key."""
    env_id = "tactile_braille/DiscreteArrows-v0"
    vec = make_vec(env_id, num_envs=1)
    vec.reset(seed=0)
    vec.unwrapped._core.cell[0] = (1, 1)
    for t in range(1, MAX_EPISODE_STEPS):
        assert not vec.step(np.array([(UP, DOWN)[t % 2]]))[2].any()
    observations, _, terminated, _, _ = vec.step(np.array([PRESS]))
    assert terminated[0] and observations["achieved_goal"][0].sum() == 1.0
    observations, rewards, terminated, truncated, _ = vec.step(np.array([UP]))
    assert not (terminated[0] or truncated[0]) and rewards[0] == 0.0


# ----------------------------------------------------------------------------- determinism
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_same_seed_same_batch_rollout(env_id, make_vec):
    actions = _batch_actions(env_id, 40, seed=2)

    def run(vec):
        records = [vec.reset(seed=13)]
        records += [vec.step(action) for action in actions]
        return records

    first, second = run(make_vec(env_id)), run(make_vec(env_id))
    assert_same(first, second)
    assert any(record[2].any() for record in first[1:])  # episodes ended (and were reset) on the way


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_different_seeds_give_different_goals(env_id, make_vec):
    vec = make_vec(env_id)
    goals = {tuple(vec.reset(seed=seed)[1]["goal"]) for seed in range(5)}
    assert len(goals) == 5
    # Within a batch, sub-environments do not all share a goal.
    assert len(set(vec.reset(seed=1)[1]["goal"].tolist())) > 1


@pytest.mark.parametrize(
    ("env_id", "edges"), [(i, "stop") for i in ENV_IDS] + [(i, "overrun") for i in CONTINUOUS_IDS]
)
def test_one_sub_env_matches_the_single_env(env_id, edges, make_vec, vector_datasets):
    """With one sub-environment and the same seed, the vector env plays exactly as the single env
    through ``gym.make`` (reset by hand after every episode end), with either workspace edge."""
    vec = make_vec(env_id, num_envs=1, edges=edges)
    single = gym.make(env_id, dataset=vector_datasets[env_id], edges=edges)
    vec_observations, _ = vec.reset(seed=21)
    observations, _ = single.reset(seed=21)
    episodes = 0
    needs_reset = False
    for action in _batch_actions(env_id, 120, num_envs=1, seed=4):
        vec_observations, vec_rewards, vec_terminated, vec_truncated, vec_infos = vec.step(action)
        if needs_reset:
            observations, info = single.reset()
            reward, terminated, truncated = 0.0, False, False
            episodes += 1
        else:
            observations, reward, terminated, truncated, info = single.step(action[0])
        for key in observations:
            np.testing.assert_array_equal(vec_observations[key][0], observations[key], err_msg=key)
        assert vec_rewards[0] == reward
        assert vec_terminated[0] == terminated
        assert vec_truncated[0] == truncated
        assert vec_infos["is_success"][0] == info["is_success"]
        assert single.unwrapped.goal_keys[vec_infos["goal"][0]] == info["goal_key"]
        needs_reset = terminated or truncated
    assert episodes >= 3


# ----------------------------------------------------------------------------- memory, rewards, actions
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_returned_arrays_never_share_memory_and_can_be_mutated(env_id, make_vec):
    mutated, clean = make_vec(env_id), make_vec(env_id)
    arrays = []
    out, clean_out = mutated.reset(seed=1), clean.reset(seed=1)
    for action in _batch_actions(env_id, 8, seed=6):
        assert_same(out, clean_out)
        arrays += list(out[0].values())
        for value in out[0].values():
            value[...] = 3 if value.dtype == np.uint8 else 0.25
        out, clean_out = mutated.step(action), clean.step(action)
    assert_same(out, clean_out)
    arrays += list(out[0].values())
    for i, a in enumerate(arrays):
        for b in arrays[i + 1 :]:
            assert not np.shares_memory(a, b)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_compute_reward_is_batch_safe(env_id, make_vec):
    vec = make_vec(env_id)
    size = vec.single_observation_space["desired_goal"].shape[0]
    eye = np.eye(size, dtype=np.float32)
    achieved = np.vstack([eye, np.zeros((2, size), dtype=np.float32)])
    desired = np.vstack([eye[::-1], eye[:2]])
    expected = np.array([float(i == size - 1 - i) for i in range(size)] + [0.0, 0.0])
    np.testing.assert_array_equal(vec.compute_reward(achieved, desired, {}), expected)
    np.testing.assert_array_equal(vec.compute_reward(achieved, achieved, {}), [1.0] * size + [0.0, 0.0])
    np.testing.assert_array_equal(
        compute_reward(achieved[None], achieved[None], {}), [[1.0] * size + [0.0] * 2]
    )


@pytest.mark.parametrize(
    ("env_id", "actions", "message"),
    [
        ("tactile_braille/DiscreteArrows-v0", np.zeros(N - 1, dtype=np.int64), "shape"),
        ("tactile_braille/DiscreteArrows-v0", np.full(N, 5), r"\[0, 5\)"),
        ("tactile_braille/DiscreteArrows-v0", np.full(N, -1), r"\[0, 5\)"),
        ("tactile_braille/DiscreteArrows-v0", np.zeros(N), "integers"),
        ("tactile_braille/ContinuousArrows-v0", np.zeros((N, 2)), "shape"),
        ("tactile_braille/ContinuousArrows-v0", np.full((N, 3), np.nan), "finite"),
        ("tactile_braille/ContinuousArrows-v0", np.full((N, 3), "x"), "real numbers"),
    ],
)
def test_bad_batch_actions_raise_value_error(env_id, actions, message, make_vec):
    vec = make_vec(env_id)
    vec.reset(seed=0)
    with pytest.raises(ValueError, match=message):
        vec.step(actions)


@pytest.mark.parametrize("env_id", CONTINUOUS_IDS)
def test_batch_actions_beyond_bounds_are_clipped(env_id, make_vec):
    wild, bounded = make_vec(env_id), make_vec(env_id)
    wild.reset(seed=2)
    bounded.reset(seed=2)
    actions = np.tile(np.array([4.0, -2.0, -9.0], dtype=np.float32), (N, 1))
    out = wild.step(actions)
    assert_same(out, bounded.step(np.clip(actions, -1.0, 1.0)))
    np.testing.assert_array_equal(out[0]["previous_action"], np.tile([1.0, -1.0, -1.0], (N, 1)))


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_vector_env_pickles_and_continues_identically(env_id, make_vec):
    vec = make_vec(env_id)
    vec.reset(seed=9)
    actions = _batch_actions(env_id, 20, seed=3)
    for action in actions[:5]:
        vec.step(action)
    clone = pickle.loads(pickle.dumps(vec))
    for action in actions[5:]:
        assert_same(vec.step(action), clone.step(action))


def test_frame_noise_is_refused_by_the_vector_env_with_what_to_use_instead():
    with pytest.raises(
        ValueError, match=r"frame_noise is not supported by the vectorised .* vectorization_mode='sync'\)"
    ):
        gym.make_vec("tactile_braille/ContinuousArrows-v0", num_envs=2, backend="render",
                     vectorization_mode="vector_entry_point", frame_noise=(1.0, 2.0))  # fmt: skip
