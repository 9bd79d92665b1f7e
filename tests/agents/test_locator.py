"""The planner's metric key map (``locate``): its pairs, its press points and targets, its aim, and a
planner that fits it from a real replay and acts with it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from test_planner import random_replay

from agents_helpers import CONTINUOUS_TASK
from tactile_braille.agents import PlannerConfig, TrainConfig
from tactile_braille.agents import locator as maps
from tactile_braille.agents.planner import PlannerAgent


def test_pairs_join_frames_of_one_episode_with_the_moves_between_them():
    # Two episodes: transitions 0-2 (frames 0 -> 1 -> 2 -> 3), then 3-4 (frames 4 -> 5 -> 6).
    rows = np.array([[0, 1], [1, 2], [2, 3], [4, 5], [5, 6]])
    deltas = np.array([[0.5, 0.0], [0.0, -0.5], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    firsts = np.array([True, False, False, True, False])
    labels = np.array([0, 1, -1, 1, 2, 0, 0])  # frame 2 has no key: no pair touches it
    first, second, moves = maps.frame_pairs(rows, labels, deltas, firsts, span=3)
    found = {(int(a), int(b)): tuple(m) for a, b, m in zip(first, second, moves, strict=True)}
    assert found == {
        (0, 1): (0.5, 0.0), (0, 3): (0.5, -0.5), (1, 3): (0.0, -0.5),  # frame 3 after a press: no move
        (4, 5): (1.0, 0.0), (4, 6): (1.0, 1.0), (5, 6): (0.0, 1.0),
    }  # fmt: skip
    assert len(maps.frame_pairs(rows, labels, deltas, firsts, span=1)[0]) == 3  # one transition each


def test_press_points_are_placed_by_the_last_placed_frame_and_the_moves_since():
    rows = np.array([[0, 1], [1, 2], [2, 3], [4, 5]])
    deltas = np.array([[0.5, 0.0], [0.0, 0.5], [0.0, 0.0], [0.0, 0.0]])
    firsts = np.array([True, False, False, True])
    pressed = np.array([False, False, True, True])
    outcomes = np.array([-1, -1, 1, -1])
    positions = np.array([[1.0, 1.0], [9, 9], [9, 9], [9, 9], [9, 9], [9, 9]])
    located = np.array([True, False, False, False, False, False])  # frame 0 only: the rest reckoned
    points, kinds = maps.press_points(positions, located, rows, deltas, firsts, pressed, outcomes)
    np.testing.assert_allclose(points, [[1.5, 1.5]])  # frame 0 and two moves; episode 2 never placed
    assert kinds.tolist() == [1]


def test_a_key_s_targets_are_its_presses_each_as_safe_as_its_distance_to_anything_else():
    points = np.array([[0.0, 0.0], [0.3, 0.0], [0.6, 0.0], [1.0, 0.0]])
    outcomes = np.array([0, 0, 0, 1])
    targets, safety = maps.key_targets(points, outcomes, keys=3)
    assert targets.shape == (3, maps.TARGETS, 2) and safety.shape == (3, maps.TARGETS)
    np.testing.assert_allclose(targets[0, :3], [[0.0, 0.0], [0.3, 0.0], [0.6, 0.0]])  # safest first
    np.testing.assert_allclose(safety[0, :3], [1.0, 0.7, 0.4])
    np.testing.assert_allclose(safety[1, 0], 0.4)
    assert np.isnan(targets[2]).all() and np.isneginf(safety[2]).all()  # key 2 was never pressed
    crowded = maps.key_targets(np.array([[0.0, 0.0], [0.01, 0.01], [0.5, 0.5]]), np.array([0, 0, 1]), 2)
    assert np.isfinite(crowded[1][0]).sum() == 1  # two presses in one cell: the safer one kept


def test_the_map_tells_the_keys_apart_where_each_press_s_nearest_press_had_its_outcome():
    points = np.array([[0.0, 0.0], [0.1, 0.0], [1.0, 0.0], [1.1, 0.0], [0.55, 0.0]])
    assert maps.press_separation(points, np.array([0, 0, 1, 1, -1])) == 1.0
    assert maps.press_separation(points, np.array([0, 1, 0, 1, -1])) == 0.0  # each beside the other key
    assert maps.press_separation(points[:1], np.array([0])) == 0.0  # one press tells nothing


def test_the_aim_is_the_fewest_steps_then_the_safest_and_a_step_that_reaches_it_presses():
    assert maps.steps_to(np.array([[0.2, -0.9], [1.5, 0.0], [0.0, 0.0], [-2.0, 2.1]])).tolist() == [
        1,
        2,
        1,
        3,
    ]
    targets = np.array([[0.9, 0.0], [0.5, 0.0], [2.5, 0.0], [np.nan, np.nan]])
    safety = np.array([0.2, 0.5, 0.9, -np.inf])
    move, ends = maps.locate_action(np.zeros(2), targets, safety, margin=0.1)
    np.testing.assert_allclose(move, [0.5, 0.0])  # both one step away: the safer, pressed
    assert ends
    move, ends = maps.locate_action(np.zeros(2), targets, safety, margin=0.6)
    np.testing.assert_allclose(move, [2.5 / 3, 0.0])  # only the third is that safe: a third of the way
    assert not ends
    assert maps.locate_action(np.zeros(2), targets[3:], safety[3:], 0.1) is None  # a key never pressed


def test_the_map_fits_pairs_by_their_moves_up_to_its_origin():
    torch.manual_seed(0)
    locator = maps.KeyLocator(keys=2, hidden=(16,))
    frames = torch.randint(0, 255, (4, 1, 100, 100), dtype=torch.uint8)
    first, second = frames[[0, 1, 2]], frames[[1, 2, 3]]
    keys = torch.tensor([[0, 0], [0, 1], [1, 1]])
    moves = torch.tensor([[0.3, 0.0], [0.0, 0.4], [-0.2, 0.1]])
    optimiser = torch.optim.Adam(locator.parameters(), 2e-2)
    for _ in range(150):
        loss = maps.locator_loss(locator, first, second, keys, moves)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    with torch.no_grad():
        placed = locator(frames, torch.tensor([0, 0, 1, 1]))
    np.testing.assert_allclose((placed[1:] - placed[:-1]).numpy(), moves.numpy(), atol=0.02)


def test_a_locating_planner_fits_its_map_from_a_replay_and_types_with_it(env_datasets):
    config = TrainConfig(task=CONTINUOUS_TASK, algo="planner", dataset=str(env_datasets[CONTINUOUS_TASK]),
                         replay={"relabel": "all", "capacity": 600},
                         agent=PlannerConfig(locate=True, entry_memory=True, sense_depth=-1 / 3,
                                             explore_press=0.5, locate_accept=0.5,
                                             learning_rate=3e-3, locate_ready=0.0))  # fmt: skip
    rng = np.random.default_rng(0)
    env, agent, buffer = random_replay(config, 300, rng)
    assert "locator" in agent.policy_parts and "locator_optimiser" in agent.checkpointed
    for _ in range(50):  # the reader learns the presses' keys; the refit then pairs what it reads
        agent.update(agent.sample(buffer, 32, rng))
    agent.refit(buffer)
    for _ in range(10):
        losses = agent.update(agent.sample(buffer, 16, rng))
    assert len(agent.pairs) > 0 and np.isfinite(losses["losses/locator_loss"])
    assert losses["charts/located_pairs"] == len(agent.pairs)
    agent.end_epoch()
    assert np.isfinite(agent.locator.safety.numpy()).any()  # targets placed from the replay's presses
    assert 0.0 <= float(agent.locator.separation) <= 1.0
    typed, aimed = 0, 0
    for episode in range(8):
        observation, _ = env.reset(seed=episode)
        for _ in range(25):
            action = agent.policy_action(observation, 0, explore=False, rng=rng, deterministic=True)
            assert env.action_space.contains(np.asarray(action, np.float32))
            aimed += isinstance(agent._where.get(False), np.ndarray)  # a step the map aimed
            observation, _, terminated, truncated, _ = env.step(action)
            typed += terminated
            if terminated or truncated:
                break
    assert typed > 0 and aimed > 0
    agent.locator.separation.fill_(0.5)
    agent.config = dataclasses.replace(
        agent.config, locate_ready=0.9
    )  # a map that cannot yet tell keys apart
    observation, _ = env.reset(seed=0)
    assert agent.located_action(observation) is None  # leaves the steps to the graph
    fresh = PlannerAgent(env.observation_space, env.action_space, config.agent)
    fresh.load_policy_state_dict(agent.policy_state_dict())  # the map travels with the policy
    torch.testing.assert_close(fresh.locator.targets, agent.locator.targets, equal_nan=True)


def test_the_map_is_refused_a_discrete_task_and_bad_settings(discrete_env):
    with pytest.raises(ValueError, match="locate maps a continuous task"):
        PlannerAgent(discrete_env.observation_space, discrete_env.action_space, PlannerConfig(locate=True))
    with pytest.raises(ValueError, match="locate_accept"):
        PlannerConfig(locate_accept=0.0)
    with pytest.raises(ValueError, match="locate_margin"):
        PlannerConfig(locate_margin=-0.1)
