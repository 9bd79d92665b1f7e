"""The typing bounds (evaluation/bounds.py): never above what a pose-aware policy or a trained policy
achieved in the same world, tight, and exact where it can be checked by hand."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from tactile_braille.envs.oracle import PoseScript
from tactile_braille.evaluation import bounds
from tactile_braille.evaluation.bounds import (
    RASTER_MM,
    KeyByKeyTypist,
    _ContinuousWorld,
    margin_cells,
    typing_bound,
)
from tactile_braille.evaluation.protocol import paper_sequences, type_sequences
from tactile_braille.evaluation.scoring import evaluate_policy

ROOT = Path(__file__).resolve().parents[2]
DISCRETE = ("tactile_braille/DiscreteArrows-v0", "tactile_braille/DiscreteAlphabet-v0")
CONTINUOUS = ("tactile_braille/ContinuousArrows-v0", "tactile_braille/ContinuousAlphabet-v0")


def test_the_discrete_bound_by_hand(env_datasets):
    # From a uniformly random cell of [[NONE, UP, NONE], [LEFT, DOWN, RIGHT]]: UP is 0, 1 or 2 moves
    # away (mean 7/6), then PRESS; DOWN the same.
    assert typing_bound("DiscreteArrows-v0", [("UP", "DOWN")], protocol="released") == pytest.approx(26 / 6)
    # With no reset, DOWN after UP is one move and a press away, whatever the start.
    env = gym.make(DISCRETE[0], dataset=env_datasets[DISCRETE[0]])  # the bound needs no dataset
    env.reset(seed=0, options={"goal_key": "UP"})
    start = env.unwrapped._core.cell[0]
    to_up = abs(start[0] - 0) + abs(start[1] - 1)
    assert typing_bound("DiscreteArrows-v0", [("UP", "DOWN")], seed=0) == to_up + 1 + 2


@pytest.mark.parametrize(
    ("task", "grid"), [(DISCRETE[0], "rig"), (DISCRETE[1], "rig"), (DISCRETE[1], "released")]
)
def test_a_pose_aware_script_types_the_discrete_tasks_in_exactly_the_bound(env_datasets, task, grid):
    env = gym.make(task, dataset=env_datasets[task], key_grid=grid)
    sequences = paper_sequences(env.unwrapped.task.keys)
    for seed in (0, 3):
        steps = type_sequences(PoseScript(env), env, sequences, seed=seed).total_steps
        assert typing_bound(task, sequences, seed=seed, dataset=env_datasets[task], grid=grid) == steps


def test_the_released_grid_moves_z_under_s_and_the_bound_follows():
    # The robot's grid puts Z under A, the released simulator's under S: A then Z is one move more there.
    sequence = [("A", "Z")]
    rig, released = (typing_bound(DISCRETE[1], sequence, seed=0, grid=grid) for grid in ("rig", "released"))
    assert released == rig + 1
    sequence = [("S", "Z")]
    rig, released = (typing_bound(DISCRETE[1], sequence, seed=0, grid=grid) for grid in ("rig", "released"))
    assert released == rig - 1


@pytest.mark.parametrize("task", CONTINUOUS)
def test_the_continuous_bound_is_below_the_centre_seeking_script(env_datasets, task):
    env = gym.make(task, dataset=env_datasets[task])
    sequences = paper_sequences(env.unwrapped.task.keys)[:4]
    steps = type_sequences(PoseScript(env), env, sequences, seed=1).total_steps
    bound = typing_bound(task, sequences, seed=1, dataset=env_datasets[task])
    assert sum(map(len, sequences)) <= bound <= steps


class EdgePresser:
    """Presses the goal at the nearest raster cell of its press region, at a depth that presses it there:
    a policy that knows the press regions the bound is computed from."""

    def __init__(self, env: gym.Env, world: _ContinuousWorld, margin: bool = False) -> None:
        self.env, self.world = env, world
        braille = env.unwrapped
        self.backend, self.task = braille._core.backend, braille.task
        self.cells = world.regions if margin else world.pressing  # with a margin: its shrunk regions

    def policy_action(self, observation, step, explore, rng, deterministic=False):
        braille = self.env.unwrapped
        core = braille._core
        goal = braille.goal_keys[int(core.goal[0])]
        cells = np.argwhere(self.cells[goal])
        centres = self.world.low + (cells + 0.5) * RASTER_MM
        here = core.position_mm[0]
        target = centres[np.abs(centres - here).max(axis=1).argmin()]
        move = (target - here) / self.task.max_move_mm
        if np.abs(move).max() > 1.0:  # not within reach: go as far as a step goes, tapping lightly
            return np.array([*np.clip(move, -1, 1), -1.0], dtype=np.float32)
        x, y = target + self.task.frame_origin_mm
        depths = self.backend.grid_depths_mm
        code = braille.layout.key(goal).index
        depth = depths[np.flatnonzero(self.backend.pressed_codes(x, y, depths) == code)[0]]
        low, high = self.task.depth_range_mm
        return np.array([*move, (depth - (low + high) / 2) / ((high - low) / 2)], dtype=np.float32)


@pytest.mark.parametrize("task", CONTINUOUS)
def test_the_continuous_bound_is_tight_a_policy_that_presses_at_the_region_edge_nearly_meets_it(
    env_datasets, task
):
    env = gym.make(task, dataset=env_datasets[task])
    braille = env.unwrapped
    world = _ContinuousWorld(braille.task, braille._core.backend, braille._core)
    policy = EdgePresser(env, world)
    keys = env.unwrapped.goal_keys
    gaps = []
    for seed in range(30):
        sequence = (keys[seed % len(keys)],)
        typed = type_sequences(policy, env, [sequence], seed=seed)
        assert typed.typed == [[sequence[0]]]  # it presses the goal
        bound = typing_bound(task, [sequence], seed=seed, dataset=env_datasets[task])
        gaps.append(typed.total_steps - bound)
    # Never below the bound; above it by at most the raster's rounding (one step), and mostly not at all.
    assert min(gaps) >= 0 and max(gaps) <= 1 and np.mean(gaps) < 0.2, gaps


def recording_presses(policy, braille) -> list[tuple[np.ndarray, str]]:
    """Wrap ``policy.policy_action`` so that each press's landing (work frame) and goal key are recorded
    in the list returned."""
    presses, original = [], policy.policy_action

    def act(*args, **kwargs):
        action = original(*args, **kwargs)
        if action[-1] > -1.0:  # a press (moves tap at -1): where it lands, and the key it is for
            goal = braille.goal_keys[int(braille._core.goal[0])]
            presses.append((braille._core.position_mm[0] + action[:2] * braille.task.max_move_mm, goal))
        return action

    policy.policy_action = act
    return presses


def presses_all_around(braille, landing: np.ndarray, key: str, margin_mm: float) -> bool:
    """Whether every point within ``margin_mm`` of ``landing`` (less the raster's rounding) presses ``key``
    at some stored depth, as the press regions are defined."""
    x, y = landing + braille.task.frame_origin_mm
    offsets = np.linspace(-(margin_mm - RASTER_MM / 2), margin_mm - RASTER_MM / 2, 4)
    ax, ay = np.meshgrid(x + offsets, y + offsets, indexing="ij")
    backend = braille._core.backend
    pressed = np.stack([backend.pressed_codes(ax, ay, depth) for depth in backend.grid_depths_mm])
    return bool((pressed == braille.layout.key(key).index).any(axis=0).all())


@pytest.mark.parametrize("task", CONTINUOUS)
def test_a_margin_keeps_every_press_that_far_inside_and_the_bound_is_tight_for_such_presses(
    env_datasets, task
):
    """With ``margin_mm`` the bound counts presses whose every point within the margin presses the key: a
    policy that presses at the nearest such cell meets it (within the raster's rounding), and presses
    nowhere nearer an edge; the bound only grows with the margin."""
    env = gym.make(task, dataset=env_datasets[task])
    braille = env.unwrapped
    margin = 1.0
    world = _ContinuousWorld(braille.task, braille._core.backend, braille._core, margin_cells(margin))
    policy = EdgePresser(env, world, margin=True)
    keys, gaps = braille.goal_keys, []
    presses = recording_presses(policy, braille)
    for seed in range(12):
        sequence = (keys[seed % len(keys)],)
        typed = type_sequences(policy, env, [sequence], seed=seed)
        assert typed.typed == [[sequence[0]]]
        bound = typing_bound(task, [sequence], seed=seed, dataset=env_datasets[task], margin_mm=margin)
        assert bound >= typing_bound(task, [sequence], seed=seed, dataset=env_datasets[task])
        gaps.append(typed.total_steps - bound)
        landing, goal = presses[-1]
        assert goal == sequence[0] and presses_all_around(braille, landing, goal, margin)
    assert min(gaps) >= 0 and max(gaps) <= 1, gaps
    sequences = paper_sequences(braille.task.keys)[:3]
    margins = [
        typing_bound(task, sequences, seed=1, dataset=env_datasets[task], margin_mm=m) for m in (0, 1, 2)
    ]
    assert margins == sorted(margins)


@pytest.mark.parametrize("task", CONTINUOUS)
def test_the_key_by_key_typist_types_every_key_between_the_bound_and_the_centre_seeking_script(
    env_datasets, task
):
    """It presses right, never below the bound with its margin, never above the script that presses at
    key centres; and each of its presses lies the margin inside the press region."""
    env = gym.make(task, dataset=env_datasets[task])
    braille = env.unwrapped
    sequences = paper_sequences(braille.task.keys)[:4]
    typist = KeyByKeyTypist(env, margin_mm=1.0)
    lands = recording_presses(typist, braille)
    typed = type_sequences(typist, env, sequences, seed=1)
    script = type_sequences(PoseScript(env), env, sequences, seed=1)
    assert typed.accuracy == 1.0 and len(lands) == sum(map(len, sequences))
    bound = typing_bound(task, sequences, seed=1, dataset=env_datasets[task], margin_mm=1.0)
    assert bound <= typed.total_steps <= script.total_steps
    assert all(presses_all_around(braille, landing, goal, 1.0) for landing, goal in lands)


def test_the_key_by_key_typist_refuses_a_world_whose_press_regions_it_cannot_read(env_datasets):
    env = gym.make(DISCRETE[0], dataset=env_datasets[DISCRETE[0]])
    with pytest.raises(ValueError, match=r"continuous task's dataset backend, got arrows \(discrete\)"):
        KeyByKeyTypist(env)
    env = gym.make(CONTINUOUS[0], dataset=env_datasets[CONTINUOUS[0]])
    with pytest.raises(ValueError, match=r"margin_mm must be a multiple of 0\.5 mm"):
        KeyByKeyTypist(env, margin_mm=0.2)


@pytest.mark.parametrize(
    ("task", "margin", "message"),
    [
        (DISCRETE[0], 1.0, "margin_mm is for the continuous tasks' press regions"),
        (CONTINUOUS[0], 0.3, r"margin_mm must be a multiple of 0.5 mm, at least 0, got 0.3"),
        (CONTINUOUS[0], -1.0, "at least 0, got -1.0"),
        (CONTINUOUS[0], 50.0, r"no press lands 50.0 mm inside the regions of \['UP'"),
    ],
)
def test_a_margin_that_cannot_be_counted_is_refused(env_datasets, task, margin, message):
    with pytest.raises(ValueError, match=message):
        typing_bound(task, [("UP",)], dataset=env_datasets.get(task), margin_mm=margin)


@pytest.mark.parametrize("task", CONTINUOUS)
def test_a_continuous_bound_with_a_reset_per_key_is_for_the_starts_the_evaluation_draws(env_datasets, task):
    env = gym.make(task, dataset=env_datasets[task])
    braille = env.unwrapped
    policy = EdgePresser(env, _ContinuousWorld(braille.task, braille._core.backend, braille._core))
    sequences = [tuple(braille.goal_keys[:4]), tuple(braille.goal_keys[-3:])]
    typed = type_sequences(policy, env, sequences, seed=7, protocol="released")
    bound = typing_bound(task, sequences, protocol="released", seed=7, dataset=env_datasets[task])
    assert typed.accuracy == 1.0 and bound <= typed.total_steps <= bound + 2


def test_pruning_dominated_masks_loses_no_better_path(env_datasets, monkeypatch):
    task = CONTINUOUS[1]
    keys = gym.make(task, dataset=env_datasets[task]).unwrapped.goal_keys
    sequences = [tuple(keys[i::5][:4]) for i in range(3)]
    pruned = [typing_bound(task, [s], seed=2, dataset=env_datasets[task]) for s in sequences]
    bounds._BOUNDS.clear()
    monkeypatch.setattr(_ContinuousWorld, "_undominated", lambda self, entries: entries)
    assert [typing_bound(task, [s], seed=2, dataset=env_datasets[task]) for s in sequences] == pruned
    bounds._BOUNDS.clear()


def test_the_bound_is_never_above_the_committed_runs_steps():
    files = sorted(ROOT.glob("results/**/typing.json"))
    assert files, "the repository commits run records with typing evaluations"
    for file in files:
        typing = json.loads(file.read_text())
        recorded = typing.get("typing_bound")
        if "Discrete" in typing["task"]:  # cheap to compute again: no dataset needed
            config = file.parent / "config.json"  # the key grid the run typed on
            grid = json.loads(config.read_text()).get("key_grid", "rig") if config.exists() else "rig"
            bound = typing_bound(typing["task"], seed=typing.get("typing_seed", 0), grid=grid)
            assert recorded in (None, bound), file
        else:  # computed at the evaluation, in the world the run typed in
            bound = recorded
            world = json.loads((file.parent / "world.json").read_text())
            if world["backend"] != "dataset":  # the bound is the grid's: the live renderer has none
                assert bound is None, file
                continue
        # The bound is for typing every key right: a run that pressed wrong keys may take fewer steps.
        if typing["accuracy"] == 1.0:
            assert bound <= typing["total_steps"], file


def test_an_evaluation_records_its_bound_and_a_proprio_policy_sees_the_pose(env_datasets):
    task = CONTINUOUS[0]
    seen = []

    def policy(observation):
        seen.append(set(observation))
        return np.array([0.0, 0.0, 1.0], dtype=np.float32)  # press where it is

    report = evaluate_policy(policy, task, dataset=env_datasets[task], track="proprio")
    assert report.typing_bound == typing_bound(task, dataset=env_datasets[task])
    assert "sensor_pose" in seen[0]
    # Pressing whatever is under the sensor takes one step a key: fewer than the bound, which is for
    # typing every key right, and wrong.
    assert report.total_steps == report.keys_asked < report.typing_bound and report.accuracy < 0.5
    seen.clear()
    evaluate_policy(policy, task, dataset=env_datasets[task], track="tactile")
    assert "sensor_pose" not in seen[0]


def test_bad_requests_are_refused():
    with pytest.raises(ValueError, match="not among"):
        typing_bound("DiscreteArrows-v0", [("UP", "Q")])
    with pytest.raises(ValueError, match="protocol must be"):
        typing_bound("DiscreteArrows-v0", protocol="mine")
    with pytest.raises(ValueError, match="unknown task"):
        typing_bound("Pendulum-v9")


def test_a_tactile_score_refuses_an_environment_that_shows_the_pose(env_datasets):
    task = CONTINUOUS[0]
    env = gym.make(task, dataset=env_datasets[task], proprio=True)
    with pytest.raises(ValueError, match="tactile-track policy must not see the arm's pose"):
        evaluate_policy(lambda observation: np.zeros(3, np.float32), task, env=env, track="tactile")
