"""The key-graph planner: its values, its belief, its backtracked labels, and runs on the tactile track."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest
import torch

from agents_helpers import CONTINUOUS_TASK, DISCRETE_TASK, read_progress_csv, touch_config, train_module
from tactile_braille.agents import PlannerConfig, TrainConfig, train
from tactile_braille.agents.planner import (
    MOVES,
    PRESS,
    PlannerAgent,
    backtrack,
    continuous_actions,
    episode_starts,
    graph_moves,
    place,
    place_entry,
    state_classes,
)
from tactile_braille.agents.presets import preset_config
from tactile_braille.envs.tasks import DISCRETE_ACTIONS

_STEPS = np.array([(-1, 0), (1, 0), (0, -1), (0, 1)])  # UP, DOWN, LEFT, RIGHT in (row, column)


def true_graph(env) -> tuple[np.ndarray, np.ndarray]:
    """The arrows' graph over the planner's states (:func:`state_classes`), and each cell's class:
    read from the environment's grid, which only a test may know."""
    core = env.unwrapped._core
    keys = len(core.goal_keys)
    classes = np.array([[core._goal_of_code[c] if c >= 0 else keys for c in row] for row in core.grid_codes])
    rows, columns = classes.shape
    cells = [(r, c) for r in range(rows) for c in range(columns)]

    def step(cell, move):
        r, c = cell[0] + _STEPS[move][0], cell[1] + _STEPS[move][1]
        return (r, c) if 0 <= r < rows and 0 <= c < columns else cell

    def state(cell, came_from, move):  # the state a cell reads, reached from another by a move
        if classes[cell] < keys:
            return classes[cell]
        if came_from is not None and classes[came_from] < keys:
            return keys + 1 + classes[came_from] * MOVES + move
        return keys

    states = keys + 1 + keys * MOVES
    moves = np.zeros((states, MOVES, states))
    for cell in cells:
        arrivals = [(state(cell, None, 0), None)]  # an episode's start
        arrivals += [(state(cell, there, m), there) for there in cells for m in range(MOVES)
                     if step(there, m) == cell and there != cell]  # fmt: skip
        for here, _ in arrivals:
            for move in range(MOVES):
                after = step(cell, move)
                moves[here, move, state(after, cell, move)] += 1
    moves += 1e-9
    return moves / moves.sum(-1, keepdims=True), classes


@pytest.fixture
def planner(discrete_env):
    torch.manual_seed(0)
    return PlannerAgent(discrete_env.observation_space, discrete_env.action_space, PlannerConfig(gamma=0.9))


def given_graph(agent: PlannerAgent, moves: np.ndarray, visits: float = 5.0) -> None:
    agent.graph.moves.copy_(torch.as_tensor(moves))
    agent.graph.visits.fill_(visits)
    agent._plan()


def test_the_values_are_the_discounted_shortest_paths_and_the_agent_walks_them(planner, discrete_env):
    moves, _ = true_graph(discrete_env)
    given_graph(planner, moves)
    up, down, left, right = (
        discrete_env.unwrapped.goal_keys.index(k) for k in ("UP", "DOWN", "LEFT", "RIGHT")
    )
    # From LEFT, RIGHT is two moves away (through DOWN), UP two (DOWN then UP), DOWN one.
    assert planner._values[right, left] == pytest.approx(0.9**2, rel=1e-6)
    assert planner._values[down, left] == pytest.approx(0.9, rel=1e-6)
    assert planner._values[left, left] == 1.0
    sure = np.eye(len(planner.state_class))
    assert DISCRETE_ACTIONS[planner.action_values(sure[left], down).argmax()] == "RIGHT"
    assert DISCRETE_ACTIONS[planner.action_values(sure[down], up).argmax()] == "UP"
    assert DISCRETE_ACTIONS[planner.action_values(sure[up], up).argmax()] == "PRESS"
    # Unsure where it is, it presses only what it believes enough.
    unsure = 0.5 * sure[up] + 0.5 * sure[down]
    assert planner.action_values(unsure, up)[PRESS] == pytest.approx(0.5)


def test_test_episodes_plan_with_their_own_discount(discrete_env):
    """``test_gamma``: test episodes and typing value paths with it, exploring with ``gamma``; an unseen
    move is worth the discount of its stream."""
    moves, _ = true_graph(discrete_env)
    config = PlannerConfig(gamma=0.9, test_gamma=0.5)
    agent = PlannerAgent(discrete_env.observation_space, discrete_env.action_space, config)
    given_graph(agent, moves)
    left, right = (discrete_env.unwrapped.goal_keys.index(k) for k in ("LEFT", "RIGHT"))
    assert agent._values[right, left] == pytest.approx(0.9**2, rel=1e-6)
    assert agent._test_values[right, left] == pytest.approx(0.5**2, rel=1e-6)
    sure = np.eye(len(agent.state_class))[left]
    assert agent.action_values(sure, right)[DISCRETE_ACTIONS.index("RIGHT")] == pytest.approx(0.9**2)
    assert agent.action_values(sure, right, episode=True)[DISCRETE_ACTIONS.index("RIGHT")] == pytest.approx(
        0.5**2
    )
    given_graph(agent, moves, visits=0.0)
    assert np.all(agent.action_values(sure, right, episode=True)[:MOVES] == 0.5)
    assert np.all(agent.action_values(sure, right)[:MOVES] == 0.9)
    with pytest.raises(ValueError, match=r"test_gamma must be in \[0, 1\]"):
        PlannerConfig(test_gamma=1.5)


def test_a_move_the_graph_has_not_seen_is_worth_trying(planner, discrete_env):
    moves, _ = true_graph(discrete_env)
    given_graph(planner, moves, visits=0.0)
    values = planner.action_values(np.eye(len(planner.state_class))[0], 1)
    assert np.all(values[:MOVES] == planner.config.gamma)  # optimism: any move might lead to the goal


def test_the_belief_carries_the_last_one_through_the_graph_and_the_previous_action(planner, discrete_env):
    moves, _ = true_graph(discrete_env)
    given_graph(planner, moves)
    observation, _ = discrete_env.reset(seed=3)
    first = planner.belief(observation, stream=True)
    reading = planner.read(observation["observation"][None])[0]
    np.testing.assert_allclose(first, place(reading, None, PRESS), rtol=1e-5)
    assert first[: planner.keys].sum() == pytest.approx(1 - reading[-1], rel=1e-5)  # nothing: at the start
    observation, *_ = discrete_env.step(DISCRETE_ACTIONS.index("RIGHT"))
    reading = planner.read(observation["observation"][None])[0]
    expected = (reading / planner._prior)[planner.state_class] * (first @ moves[:, 3, :])
    np.testing.assert_allclose(planner.belief(observation, stream=True), expected / expected.sum(), rtol=1e-5)
    # Another stream (the test episodes) keeps its own: a new episode there starts from the reading.
    other = planner.belief({**observation, "previous_action": np.zeros(5, np.float32)}, stream=False)
    np.testing.assert_allclose(other, place(reading, None, PRESS), rtol=1e-5)


def test_a_cell_off_the_keys_is_told_apart_by_the_key_and_the_move_before_it():
    keys = 4
    key_up = np.eye(keys + 1)[0]
    nothing = np.eye(keys + 1)[keys]
    start = place(nothing, None, PRESS)
    assert start.argmax() == keys  # nothing at an episode's start
    after_up = place(nothing, place(key_up, None, PRESS), 2)  # LEFT from key 0
    assert after_up.argmax() == keys + 1 + 0 * MOVES + 2
    assert place(nothing, after_up, PRESS).argmax() == after_up.argmax()  # a press there stays
    assert place(nothing, after_up, 3).argmax() == keys  # nothing after nothing
    assert np.all(state_classes(keys)[keys:] == keys)


def test_an_unseen_state_off_the_keys_backs_off_to_the_pooled_moves_off_the_keys():
    keys = 4
    states = len(state_classes(keys))
    counts = np.zeros((states, MOVES, states))
    counts[keys + 1, 0, 0] = 3.0  # nothing UP of key 0, moved UP: key 0 (an edge stop)
    counts[keys, 2, keys] = 1.0  # the generic nothing, moved LEFT: still nothing
    moves = graph_moves(counts, keys, prior=1e-6, backoff=1.0)
    unseen = keys + 1 + 3 * MOVES + 1  # nothing below key 3, never visited
    assert moves[unseen, 0, 0] == pytest.approx(1.0, abs=1e-4)  # UP: the key the moves off the keys reached
    assert moves[unseen, 2, keys] == pytest.approx(1.0, abs=1e-4)  # LEFT: nothing, as theirs
    np.testing.assert_allclose(moves.sum(-1), 1.0)


def test_the_backtracked_belief_is_read_with_how_often_each_state_is_occupied():
    """Many rarely occupied states off the keys that lead to key 0 by UP, as the key itself does (an
    edge stop): without the occupancy they outvote it, and the frame before is read as nothing."""
    keys = 3
    classes = state_classes(keys)
    states = len(classes)
    moves = np.full((states, MOVES, states), 1e-9)
    moves[:, :, keys] = 1.0  # elsewhere: off the keys
    moves[0, 0] = 0.0
    moves[0, 0, 0] = 1.0
    moves[keys:, 0] = 0.0
    moves[keys:, 0, 0] = 1.0
    moves /= moves.sum(-1, keepdims=True)
    anchors = np.array([-1, 0])  # frame 0 then UP to frame 1, pressed there: key 0
    args = (moves, classes, anchors, np.array([0, 1]), np.array([0, PRESS]), np.array([-1, 0]),
            np.array([0]), np.array([1]), 1.0, 0.9)  # fmt: skip
    assert backtrack(*args)[0] == keys  # nothing, 13 states against one
    occupancy = np.r_[np.full(keys, 1000.0), np.ones(states - keys)]
    assert backtrack(*args, occupancy=occupancy)[0] == 0


def test_a_move_into_the_generic_nothing_is_worth_its_share_of_that_state_s_value(discrete_env):
    """The generic nothing's pooled moves are a lottery drawn again at each step (every cell off the
    keys at once): with ``lost_value`` 0 a plan into it from a key is worth nothing, and its own moves
    keep their value."""
    values = {}
    for lost in (None, 0.0):
        config = PlannerConfig(gamma=0.9, lost_value=lost)
        agent = PlannerAgent(discrete_env.observation_space, discrete_env.action_space, config)
        keys, states = agent.keys, len(agent.state_class)
        moves = np.zeros((states, MOVES, states))
        moves[np.arange(states), :, np.arange(states)] = 1.0  # every move stays, but:
        moves[0, 3] = np.eye(states)[keys]  # key 0, RIGHT: the generic nothing
        moves[keys, 0] = 0.3 * np.eye(states)[2] + 0.7 * np.eye(states)[keys]  # there UP: key 2, 3 in 10
        given_graph(agent, moves)
        values[lost] = agent._values[2]
    generic = 0.9 * 0.3 / (1 - 0.9 * 0.7)
    assert values[None][keys] == pytest.approx(generic) and values[0.0][keys] == pytest.approx(generic)
    assert values[None][0] == pytest.approx(0.9 * generic) and values[0.0][0] == 0.0


def test_a_test_episode_remembers_where_each_move_led_and_plans_again(discrete_env):
    """A move the graph makes a lottery (UP from key 0 reaches key 3 four times in ten, else stays) is
    worth more than a sure path of three moves; once a test episode has seen it stay, ``outcome_memory``
    plans on what it saw and takes the path, where without it (or in training) the lottery is drawn
    again. A new episode forgets."""
    up, right = 0, 3
    observation, _ = discrete_env.reset(seed=0)

    goal = {**observation, "desired_goal": np.eye(4, dtype=np.float32)[3]}

    def two_actions(memory: bool, explore: bool) -> tuple[PlannerAgent, list[int]]:
        config = PlannerConfig(gamma=0.9, repeat_penalty=0.0, outcome_memory=memory, epsilon_start=0.0,
                               epsilon_end=0.0)  # fmt: skip
        agent = PlannerAgent(discrete_env.observation_space, discrete_env.action_space, config)
        states = len(agent.state_class)
        moves = np.zeros((states, MOVES, states))
        moves[np.arange(states), :, np.arange(states)] = 1.0  # every move stays, but:
        moves[[0, 1, 2], right] = np.eye(states)[[1, 2, 3]]  # RIGHT walks keys 0, 1, 2, 3
        moves[0, up] = 0.4 * np.eye(states)[3] + 0.6 * np.eye(states)[0]  # the lottery
        given_graph(agent, moves)
        agent.read = lambda frames, batch_size=512: np.eye(agent.classes)[[0]]  # it stays on key 0
        rng = np.random.default_rng(0)
        first = agent.policy_action(goal, 10**6, explore=explore, rng=rng)
        moved = {**goal, "previous_action": np.eye(5, dtype=np.float32)[first]}
        return agent, [first, agent.policy_action(moved, 10**6, explore=explore, rng=rng)]

    agent, actions = two_actions(memory=True, explore=False)
    assert agent._values[3, 0] == pytest.approx(0.9 * 0.4 / (1 - 0.9 * 0.6))  # above the path's 0.9 ** 3
    assert actions == [up, right] and agent._outcomes == {(0, up): 0}
    assert two_actions(memory=False, explore=False)[1] == [up, up]
    assert two_actions(memory=True, explore=True)[1] == [up, up]  # training draws as before
    assert agent.policy_action(goal, 10**6, explore=False, rng=np.random.default_rng(0)) == up
    assert agent._outcomes == {}  # a new episode: the lottery again


def test_backtracking_labels_the_frames_before_a_press_with_the_keys_they_show(discrete_env):
    """Scripted episodes on the real environment: each frame before a press is labelled, back
    through the true graph, with the key the sensor was on (the grid's edge stops the backtracking
    where a move may have stayed put: RIGHT into RIGHT comes from DOWN or from RIGHT itself)."""
    moves, classes = true_graph(discrete_env)
    core = discrete_env.unwrapped._core
    frame_classes, rows, actions, achieved, remaining = [], [], [], [], []
    for seed, script in ((0, "DUR"), (1, "LRP"), (2, "RRLP"), (3, "UP")):
        discrete_env.reset(seed=seed)
        episode = []
        for name in [{"D": "DOWN", "U": "UP", "L": "LEFT", "R": "RIGHT", "P": "PRESS"}[c] for c in script]:
            frame_classes.append(classes[tuple(core.cell[0])])
            rows.append(len(frame_classes) - 1)
            _, _, terminated, _, info = discrete_env.step(DISCRETE_ACTIONS.index(name))
            episode.append(DISCRETE_ACTIONS.index(name))
            pressed = discrete_env.unwrapped.goal_keys.index(info["pressed_key"]) if terminated else -1
            achieved.append(pressed)
            if terminated:
                break
        actions += episode
        remaining += list(range(len(episode) - 1, -1, -1))
    rows, actions, achieved = np.array(rows), np.array(actions), np.array(achieved)
    anchors = np.full(len(frame_classes), -1)
    pressed = achieved >= 0
    anchors[rows[pressed]] = achieved[pressed]
    ends = np.flatnonzero(pressed)
    starts = episode_starts(np.array(remaining), ends)
    labels = backtrack(moves, state_classes(4), anchors, rows, actions, achieved, starts, ends,
                       sharpen=1.0, accept=0.99)  # fmt: skip
    truth = np.array(frame_classes)
    labelled = labels >= 0
    assert labelled.sum() > pressed.sum()  # frames besides the presses' own were labelled
    np.testing.assert_array_equal(labels[labelled], truth[labelled])
    assert np.all(labels[~labelled] == -1)


def random_replay(config: TrainConfig, steps: int, rng: np.random.Generator):
    """The run's environment, agent and replay, the replay filled with ``steps`` random steps (a
    discrete task's five actions, or the agent's own continuous ones)."""
    env = train_module.make_env(config)
    agent, buffer = train_module.make_agent(config, env), train_module.make_replay(config, env)
    observation, _ = env.reset(seed=0)
    buffer.start_episode(observation)
    for _ in range(steps):
        if agent.continuous is None:
            action = int(rng.integers(len(DISCRETE_ACTIONS)))
        else:
            action = agent.continuous[rng.integers(len(agent.continuous))].copy()
        observation, reward, terminated, truncated, _ = env.step(action)
        buffer.add_step(action, reward, observation, terminated)
        if terminated or truncated:
            buffer.end_episode()
            observation, _ = env.reset(seed=int(rng.integers(1000)))
            buffer.start_episode(observation)
    return env, agent, buffer


def test_a_refit_labels_each_press_frame_with_what_it_pressed(discrete_env, env_datasets):
    config = TrainConfig(task=DISCRETE_TASK, algo="planner", dataset=str(env_datasets[DISCRETE_TASK]),
                         replay={"relabel": "all", "capacity": 500})  # fmt: skip
    rng = np.random.default_rng(0)
    _, agent, buffer = random_replay(config, 120, rng)
    batch = agent.sample(buffer, 16, rng)
    assert agent.refits == 1 and len(agent.label_frames) > 0
    presses = np.flatnonzero((buffer.actions[: buffer.size] == PRESS) & (buffer.achieved[: buffer.size] >= 0))
    frames = buffer.frame_index[presses, 0]
    read = dict(zip(agent.label_frames, agent.label_classes, strict=True))
    assert [read[f] for f in frames] == list(buffer.achieved[presses])
    losses = agent.update(batch)
    assert np.isfinite(losses["losses/reader_loss"])
    np.testing.assert_allclose(agent.graph.moves.sum(-1).numpy(), 1.0, rtol=1e-6)


def test_a_resumed_planner_refits_its_replay_as_before(env_datasets, tmp_path):
    """Its refits read the replay's episodes (each transition's steps remaining): a checkpoint keeps
    them, so a resumed run labels the frames it labelled before."""
    config = TrainConfig(task=DISCRETE_TASK, algo="planner", dataset=str(env_datasets[DISCRETE_TASK]),
                         replay={"relabel": "all", "capacity": 500})  # fmt: skip
    env, agent, buffer = random_replay(config, 200, np.random.default_rng(1))
    agent.refit(buffer)
    before = agent.label_frames.copy(), agent.label_classes.copy(), agent.graph.moves.clone()
    assert len(before[0]) > 0
    buffer.save(tmp_path / "replay.npz")
    restored = train_module.make_replay(config, env)
    restored.load(tmp_path / "replay.npz")
    np.testing.assert_array_equal(restored.remaining[: buffer.size], buffer.remaining[: buffer.size])
    agent.refit(restored)
    np.testing.assert_array_equal(agent.label_frames, before[0])
    np.testing.assert_array_equal(agent.label_classes, before[1])
    torch.testing.assert_close(agent.graph.moves, before[2])


def test_a_planner_run_learns_from_its_observations_alone_and_resumes(env_datasets, tmp_path, monkeypatch):
    from test_tracks import _learnt

    config = touch_config(env_datasets, "planner", track="tactile", touch={"enabled": False}, epochs=2,
                          agent=PlannerConfig(batch_size=8, refit_every=5), start_steps=0)  # fmt: skip
    plain = _learnt(config, tmp_path / "plain", monkeypatch, scrambled=False)
    assert plain == _learnt(config, tmp_path / "scrambled", monkeypatch, scrambled=True)
    assert any(row["losses/reader_loss"] not in ("", None) for row in plain)
    train(dataclasses.replace(config, epochs=3), run_dir=tmp_path / "plain", resume=True, progress=False)
    assert [row["epoch"] for row in read_progress_csv(tmp_path / "plain")] == ["0", "1", "2"]


def test_the_planner_is_refused_what_it_cannot_read():
    with pytest.raises(ValueError, match=r"turn touch\.enabled off"):
        TrainConfig(task=DISCRETE_TASK, algo="planner", touch={"enabled": True}, track="proprio")
    with pytest.raises(ValueError, match="the planner reads the tactile images alone"):
        preset_config("fast", DISCRETE_TASK, "planner")
    with pytest.raises(ValueError, match="the released code has no planner"):
        preset_config("released", DISCRETE_TASK, "planner")
    with pytest.raises(ValueError, match="accept is a probability"):
        PlannerConfig(accept=0.0)
    config = preset_config("fast-tactile", DISCRETE_TASK, "planner")
    assert (config.track, config.replay.relabel, config.start_steps) == ("tactile", "all", 0)
    with pytest.raises(ValueError, match="set final_press=False"):
        TrainConfig(task=CONTINUOUS_TASK, algo="planner", final_press=True)
    with pytest.raises(ValueError, match="move is a share"):
        PlannerConfig(move=1.5)
    with pytest.raises(ValueError, match="explore_press is a probability"):
        PlannerConfig(explore_press=-0.1)
    with pytest.raises(ValueError, match="lost_value is a share"):
        PlannerConfig(lost_value=1.5)
    with pytest.raises(ValueError, match=r"Discrete\(5\) actions or the continuous tasks' Box"):
        PlannerAgent(discrete_observation_space(), gym.spaces.Box(-1.0, 1.0, (2,)))


def discrete_observation_space():
    return gym.make(DISCRETE_TASK).observation_space


def test_a_record_of_a_retired_planner_setting_reads_only_with_the_value_the_code_still_runs():
    stored = TrainConfig(task=DISCRETE_TASK, algo="planner").to_json()
    stored["agent"] = {**stored["agent"], "backtrack_readings": 0.0}  # as the records of 2026-12-01 hold it
    assert TrainConfig.from_json(stored) == TrainConfig(task=DISCRETE_TASK, algo="planner")
    stored["agent"]["backtrack_readings"] = 1.0
    with pytest.raises(ValueError, match=r"agent\.backtrack_readings=1\.0: this setting was removed"):
        TrainConfig.from_json(stored)


def test_on_a_continuous_task_it_acts_with_its_five_actions_and_reads_them_back(env_datasets):
    env = gym.make(CONTINUOUS_TASK, dataset=env_datasets[CONTINUOUS_TASK])
    agent = PlannerAgent(env.observation_space, env.action_space, PlannerConfig(move=0.5, sense_depth=-0.2))
    actions = continuous_actions(0.5, -0.2)
    np.testing.assert_array_equal(actions[PRESS], [0.0, 0.0, 1.0])  # the deepest tap, no move
    np.testing.assert_array_equal(np.abs(actions[:MOVES, :2]).sum(-1), 0.5)  # one axis each, both ways
    assert len({tuple(a) for a in actions[:MOVES, :2]}) == MOVES and np.all(actions[:MOVES, 2] == -0.2)
    np.testing.assert_array_equal(agent.action_indices(actions), np.arange(len(DISCRETE_ACTIONS)))
    with pytest.raises(ValueError, match="run it without final_press"):
        agent.action_indices(np.array([[0.5, 0.0, 1.0]], np.float32))  # a final press: a move, deep
    rng = np.random.default_rng(0)
    observation, _ = env.reset(seed=0)
    for _ in range(6):
        action = agent.policy_action(observation, 0, explore=True, rng=rng)
        assert env.action_space.contains(action) and np.any(np.all(actions == action, axis=-1))
        observation, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            observation, _ = env.reset(seed=1)
    pressing = PlannerAgent(env.observation_space, env.action_space, PlannerConfig(explore_press=1.0))
    assert all(pressing.random_action(env.action_space, rng)[2] == 1.0 for _ in range(5))


def test_a_test_press_waits_for_a_frame_that_shows_the_goal(env_datasets):
    env = gym.make(CONTINUOUS_TASK, dataset=env_datasets[CONTINUOUS_TASK])
    entry = MOVES + 1  # a state is a class and how the sensor came onto it: class * entry + move + 1
    key0, key0_down, key1_down = 0, 0 * entry + 1 + 1, 1 * entry + 1 + 1

    def two_steps(config: PlannerConfig, explore: bool) -> tuple[PlannerAgent, np.ndarray]:
        """From key 0 toward key 1: DOWN, then a frame that shows key 0 (the move did not leave it)."""
        agent = PlannerAgent(env.observation_space, env.action_space, config)
        states = len(agent.state_class)
        moves = np.full((states, MOVES, states), 1.0 / states)
        moves[[key0, key0_down], 1] = np.eye(states)[key1_down]  # the graph: DOWN from key 0 reaches key 1
        given_graph(agent, moves)
        observation, _ = env.reset(seed=0)
        observation = {**observation, "desired_goal": np.eye(agent.keys, dtype=np.float32)[1]}
        rng = np.random.default_rng(0)
        agent.read = lambda frames, batch_size=512: np.eye(agent.classes)[[0]]
        first = agent.policy_action(observation, 10**6, explore=explore, rng=rng)
        np.testing.assert_array_equal(first, agent.continuous[1])  # DOWN
        agent.read = lambda frames, batch_size=512: np.array([[0.98, 0.01, 0.0, 0.0, 0.01]])
        moved = {**observation, "previous_action": first}
        return agent, agent.policy_action(moved, 10**6, explore=explore, rng=rng)

    base = PlannerConfig(entry_memory=True, epsilon_start=0.0, epsilon_end=0.0)
    agent, action = two_steps(base, explore=False)
    assert int(agent._beliefs[False].argmax()) == key1_down  # the filter believes the graph
    np.testing.assert_array_equal(action, agent.continuous[PRESS])  # and presses key 0
    waiting = dataclasses.replace(base, press_reading=0.5)
    agent, action = two_steps(waiting, explore=False)
    np.testing.assert_array_equal(action, agent.continuous[1])  # the frame shows key 0: DOWN again
    assert int(agent._beliefs[False].argmax()) == key0_down  # believed from the frame, reached by DOWN
    agent, action = two_steps(waiting, explore=True)
    np.testing.assert_array_equal(action, agent.continuous[PRESS])  # training presses as before
    with pytest.raises(ValueError, match="press_reading is a probability"):
        PlannerConfig(press_reading=0.0)


def test_a_test_episode_moves_before_it_presses_without_first_press(env_datasets):
    env = gym.make(CONTINUOUS_TASK, dataset=env_datasets[CONTINUOUS_TASK])
    entry = MOVES + 1  # a state is a class and how the sensor came onto it: class * entry + move + 1
    key1_first, key1_down = 1 * entry, 1 * entry + 1 + 1

    def first_step(config: PlannerConfig, explore: bool) -> tuple[PlannerAgent, np.ndarray]:
        """An episode's first frame, read surely as the goal key 1; a move DOWN from it stays on key 1."""
        agent = PlannerAgent(env.observation_space, env.action_space, config)
        states = len(agent.state_class)
        moves = np.full((states, MOVES, states), 1.0 / states)
        moves[key1_first, 1] = np.eye(states)[key1_down]
        given_graph(agent, moves)
        observation, _ = env.reset(seed=0)
        observation = {**observation, "desired_goal": np.eye(agent.keys, dtype=np.float32)[1]}
        agent.read = lambda frames, batch_size=512: np.eye(agent.classes)[[1]]
        return agent, agent.policy_action(observation, 10**6, explore=explore, rng=np.random.default_rng(0))

    base = PlannerConfig(entry_memory=True, epsilon_start=0.0, epsilon_end=0.0)
    agent, action = first_step(base, explore=False)
    np.testing.assert_array_equal(action, agent.continuous[PRESS])  # pressed on the frame alone
    moving = dataclasses.replace(base, first_press=False)
    agent, action = first_step(moving, explore=False)
    np.testing.assert_array_equal(action, agent.continuous[1])  # the move the graph says stays on key 1
    assert int(agent._beliefs[False].argmax()) == key1_first  # believed from the frame, as before
    agent, action = first_step(moving, explore=True)
    np.testing.assert_array_equal(action, agent.continuous[PRESS])  # training presses as before
    # After that move, the frame still read as key 1, the press is allowed again.
    agent, first = first_step(moving, explore=False)
    goal = np.eye(agent.keys, dtype=np.float32)[1]
    moved = {**env.reset(seed=0)[0], "desired_goal": goal, "previous_action": first}
    action = agent.policy_action(moved, 10**6, explore=False, rng=np.random.default_rng(0))
    np.testing.assert_array_equal(action, agent.continuous[PRESS])


def test_entry_states_keep_how_the_sensor_came_onto_each_class(discrete_env):
    agent = PlannerAgent(
        discrete_env.observation_space, discrete_env.action_space, PlannerConfig(entry_memory=True)
    )
    belief = np.random.default_rng(0).dirichlet(np.ones(len(agent.state_class)))
    assert agent.action_values(belief, 2)[PRESS] == pytest.approx(belief[agent.state_class == 2].sum())
    np.testing.assert_array_equal(agent._values[:, agent.state_class == 2][2], 1.0)  # pressing there pays
    keys = 4
    classes = state_classes(keys, entry=True)
    assert len(classes) == (keys + 1) * (MOVES + 1) and np.all(np.bincount(classes) == MOVES + 1)
    reading = np.array([0.0, 0.7, 0.0, 0.1, 0.2])
    start, moved, pressed = place_entry(reading, None), place_entry(reading, 2), place_entry(reading, PRESS)
    np.testing.assert_array_equal(start, pressed)
    for state in (start, moved):  # each class keeps its probability, in one state of its five
        np.testing.assert_allclose(np.bincount(classes, weights=state), reading)
    assert np.flatnonzero(moved).tolist() == [1 * 5 + 3, 3 * 5 + 3, 4 * 5 + 3]  # reached by move 2
    assert np.flatnonzero(start).tolist() == [1 * 5, 3 * 5, 4 * 5]


def test_a_continuous_planner_run_learns_from_its_observations_alone(env_datasets, tmp_path, monkeypatch):
    from test_tracks import _learnt

    preset = preset_config("fast-tactile", CONTINUOUS_TASK, "planner")
    assert (preset.track, preset.final_press, preset.agent.entry_memory, preset.edges) == (
        "tactile",
        False,
        True,
        "stop",
    )
    alphabet = preset_config("fast-tactile", "tactile_braille/ContinuousAlphabet-v0", "planner")
    assert (preset.agent.press_reading, alphabet.agent.press_reading) == (0.8, None)  # the arrows' waits
    assert (preset.agent.first_press, alphabet.agent.first_press) == (False, True)
    config = dataclasses.replace(
        preset, dataset=str(env_datasets[CONTINUOUS_TASK]), epochs=2, steps_per_epoch=30, threads=1,
        agent=dataclasses.replace(preset.agent, batch_size=8, refit_every=5),
        evaluation=dataclasses.replace(preset.evaluation, test_episodes=2, snapshots=1),
        replay=dataclasses.replace(preset.replay, capacity=200),
    )  # fmt: skip
    plain = _learnt(config, tmp_path / "plain", monkeypatch, scrambled=False)
    assert plain == _learnt(config, tmp_path / "scrambled", monkeypatch, scrambled=True)
    assert any(row["losses/reader_loss"] not in ("", None) for row in plain)
    assert float(plain[-1]["charts/labelled_frames"]) > 0
