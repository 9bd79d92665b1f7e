"""The touch wrapper (agents/touch.py): a learner acting on the touch encoder's features (or readout) of
the image, its checkpoints and snapshots, the poses it standardises for asymmetric critics, and goals
placed on the layout."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

from agents_helpers import same_weights, through_file
from feature_agents import ACTION_SPACE, FEATURES, GOALS, PREVIOUS, batch, feature_observation_space, make
from tactile_braille.agents import DQNAgent, DQNConfig, SACAgent, SACConfig
from tactile_braille.agents.common import observation_features
from tactile_braille.agents.touch import TouchAgent, feature_space, touch_input_size
from tactile_braille.supervised.touch import TouchEncoder

pytestmark = pytest.mark.usefixtures("one_torch_thread")


# ---------------------------------------------------------------- a learner on the encoder's features
def touch_agent(env: gym.Env, seed: int) -> TouchAgent:
    torch.manual_seed(seed)
    encoder = TouchEncoder(GOALS, features=8, hidden=16)
    space = feature_space(env.observation_space, encoder.features_size)
    return TouchAgent(DQNAgent(space, env.action_space, DQNConfig(hidden=(16,))), encoder)


def test_feature_space_replaces_only_the_image(discrete_env):
    space = feature_space(discrete_env.observation_space, 8)
    assert space["observation"].shape == (8,) and space["observation"].dtype == np.float32
    assert observation_features(space) == 8
    for name in ("desired_goal", "achieved_goal", "previous_action"):
        assert space[name] == discrete_env.observation_space[name]
    assert discrete_env.observation_space["observation"].shape == (100, 100, 1)  # not changed in place


def test_touch_agent_acts_on_the_encoders_features_of_the_image(discrete_env):
    agent = touch_agent(discrete_env, 0)
    rng = np.random.default_rng(0)
    for seed in range(4):
        observation, _ = discrete_env.reset(seed=seed)
        features = agent.touch.encode(observation["observation"][None])[0]
        assert features.shape == (8,)
        expected = agent.agent.policy_action({**observation, "observation": features}, 0, False, rng, True)
        assert agent.policy_action(observation, 0, explore=False, rng=rng, deterministic=True) == expected


@pytest.mark.parametrize("fitted", [True, False])
def test_touch_agent_state_round_trip(discrete_env, fitted):
    agent, fresh = touch_agent(discrete_env, 0), touch_agent(discrete_env, 1)
    if fitted:
        agent.fit(touch_agent(discrete_env, 2).touch)
    assert agent.fitted is fitted and fresh.fitted is False
    assert not same_weights(agent.touch, fresh.touch) and not same_weights(agent.agent.q, fresh.agent.q)
    fresh.fitted = not fitted  # the flag must come from the checkpoint
    fresh.load_state_dict(through_file(agent.state_dict()))
    assert fresh.fitted is fitted
    assert same_weights(agent.touch, fresh.touch) and same_weights(agent.agent.q, fresh.agent.q)
    assert not fresh.touch.training and not any(p.requires_grad for p in fresh.touch.parameters())
    with pytest.raises(ValueError, match="touch encoder"):
        fresh.load_state_dict(through_file(agent.agent.state_dict()))  # a plain agent's checkpoint


def test_touch_agent_policy_snapshot_holds_the_encoder(discrete_env):
    agent, fresh = touch_agent(discrete_env, 0), touch_agent(discrete_env, 1)
    snapshot = agent.policy_state_dict()
    assert set(snapshot) == {"q", "touch"}
    fresh.load_policy_state_dict(through_file(snapshot))
    assert same_weights(agent.touch, fresh.touch) and same_weights(agent.agent.q, fresh.agent.q)
    with pytest.raises(ValueError, match="touch encoder"):
        fresh.load_policy_state_dict({"q": snapshot["q"]})


# ---------------------------------------------------------------- poses for asymmetric critics
def test_the_touch_wrapper_standardises_poses_as_the_encoders_targets():
    encoder = TouchEncoder(GOALS, features=FEATURES, hidden=8)
    encoder.pose_mean.copy_(torch.tensor([10.0, -20.0, 5.0]))
    encoder.pose_scale.copy_(torch.tensor([2.0, 4.0, 0.5]))
    inner = make("sac", True)
    seen = []
    inner.update = lambda data: seen.append(data) or {}
    agent = TouchAgent(inner, encoder)
    data = batch(np.random.default_rng(0))
    agent.update(data)
    (received,) = seen
    for name in ("poses", "next_poses"):
        np.testing.assert_allclose(
            received[name] * [2.0, 4.0, 0.5] + [10.0, -20.0, 5.0], data[name], atol=1e-5
        )
    np.testing.assert_array_equal(received["images"], data["images"])  # the rest passes through


# ---------------------------------------------------------------- goals placed on the layout
def test_a_placed_goal_is_the_one_hot_followed_by_the_keys_standardised_position():
    encoder = TouchEncoder(GOALS, features=FEATURES, hidden=8)
    encoder.pose_mean.copy_(torch.tensor([10.0, -20.0, 5.0]))
    encoder.pose_scale.copy_(torch.tensor([2.0, 4.0, 0.5]))
    positions = np.array([[0.0, 0.0], [10.0, -20.0], [12.0, -16.0], [20.0, -40.0]])
    space = feature_space(feature_observation_space(), FEATURES, goal_positions=True)
    inner = SACAgent(space, ACTION_SPACE, SACConfig(hidden=(8,)))
    agent = TouchAgent(inner, encoder, key_positions_mm=positions)
    eye = np.eye(GOALS, dtype=np.float32)
    placed = agent.goals(np.vstack([eye, np.zeros(GOALS, np.float32)]))
    np.testing.assert_array_equal(placed[:, :GOALS], np.vstack([eye, np.zeros(GOALS)]))
    np.testing.assert_allclose(placed[:GOALS, GOALS:], [[-5.0, 5.0], [0.0, 0.0], [1.0, 1.0], [5.0, -5.0]])
    np.testing.assert_array_equal(placed[GOALS, GOALS:], [0.0, 0.0])  # no goal: nowhere
    assert space["desired_goal"].shape == (GOALS + 2,) and inner.actor.trunk.dense[0].in_features == (
        FEATURES + GOALS + 2 + PREVIOUS
    )
    seen = []
    inner.update = lambda data: seen.append(data) or {}
    data = batch(np.random.default_rng(0), poses=False)
    agent.update(data)
    np.testing.assert_array_equal(seen[0]["goals"], agent.goals(data["goals"]))
    with pytest.raises(ValueError, match="one \\(x, y\\) per goal key"):
        TouchAgent(inner, encoder, key_positions_mm=positions[:3])
    with pytest.raises(ValueError, match="must be finite"):
        TouchAgent(inner, encoder, key_positions_mm=np.full((GOALS, 2), np.nan))


# ---------------------------------------------------------------- learning on the encoder's readout
def test_a_touch_agent_on_the_readout_encodes_with_the_heads():
    encoder = TouchEncoder(GOALS, features=FEATURES, hidden=8)
    space = feature_space(feature_observation_space(), encoder.readout_size)
    agent = TouchAgent(SACAgent(space, ACTION_SPACE, SACConfig(hidden=(8,))), encoder, inputs="readout")
    images = np.zeros((2, 100, 100, 1), np.uint8)
    assert agent.input_size == encoder.readout_size
    np.testing.assert_array_equal(agent.encode(images), encoder.read(images))
    with pytest.raises(ValueError, match="inputs must be one of"):
        TouchAgent(agent.agent, encoder, inputs="pixels")


# ---------------------------------------------------------------- the arm's pose as an input
def test_a_touch_agent_with_pose_inputs_appends_the_standardised_pose_of_each_frame():
    encoder = TouchEncoder(GOALS, features=FEATURES, hidden=8)
    encoder.pose_mean.copy_(torch.tensor([10.0, -20.0, 5.0]))
    encoder.pose_scale.copy_(torch.tensor([2.0, 4.0, 0.5]))
    space = feature_space(feature_observation_space(), encoder.readout_size + 3)
    inner = SACAgent(space, ACTION_SPACE, SACConfig(hidden=(8,)))
    agent = TouchAgent(inner, encoder, inputs="readout", pose_inputs=True)
    assert agent.input_size == encoder.readout_size + 3
    images = np.random.default_rng(0).integers(0, 2, (2, 100, 100, 1), dtype=np.uint8) * 255
    labels = np.array([[12.0, -24.0, 5.5, 1, 2], [10.0, -20.0, 5.0, -1, -1]], dtype=np.float32)
    vectors = agent.encode(images, labels)
    np.testing.assert_array_equal(vectors[:, :-3], encoder.read(images))
    np.testing.assert_allclose(vectors[:, -3:], [[1.0, -1.0, 1.0], [0.0, 0.0, 0.0]], atol=1e-6)
    with pytest.raises(ValueError, match="needs the arm's pose of every frame"):
        agent.encode(images, np.full_like(labels, np.nan))  # frames stored without labels
    observation = {
        "observation": images[0], "previous_action": np.zeros(PREVIOUS, np.float32),
        "achieved_goal": np.zeros(GOALS, np.float32), "desired_goal": np.eye(GOALS, dtype=np.float32)[1],
        "sensor_pose": labels[0, :3],
    }  # fmt: skip
    features = agent.features(observation)
    assert "sensor_pose" not in features  # it went into the vector
    np.testing.assert_allclose(features["observation"], vectors[0], atol=1e-6)


# ---------------------------------------------------------------- goals on the layout learnt from touch
def test_goal_offsets_show_the_learner_only_its_goals_offset_from_the_sensor(discrete_env):
    torch.manual_seed(0)
    encoder = TouchEncoder(GOALS, features=FEATURES, hidden=8, labels="observation")
    size = touch_input_size(encoder, "readout", goal_offsets=True)
    assert size == encoder.readout_size - 2 * GOALS + 2 and encoder.readout_size == 3 + 4 * GOALS + 2
    space = feature_space(discrete_env.observation_space, size)
    agent = TouchAgent(DQNAgent(space, discrete_env.action_space, DQNConfig(hidden=(16,))), encoder,
                       inputs="readout", goal_offsets=True)  # fmt: skip
    assert agent.input_size == encoder.readout_size  # the replay caches the whole readout
    observation, _ = discrete_env.reset(seed=0)
    readout = agent.touch.read(observation["observation"][None])[0]
    goal = int(observation["desired_goal"].argmax())
    seen = agent.features(observation)["observation"]
    np.testing.assert_allclose(seen[:-2], readout[: -2 * GOALS], rtol=1e-6)
    np.testing.assert_allclose(seen[-2:], readout[-2 * GOALS :].reshape(GOALS, 2)[goal], rtol=1e-6)
    # In updates, each transition's (relabelled) goal picks its offset, in both frames.
    vectors = np.random.default_rng(0).normal(size=(3, encoder.readout_size)).astype(np.float32)
    goals = np.eye(GOALS, dtype=np.float32)[[2, 0, 3]]
    viewed = agent.view(vectors, goals)
    np.testing.assert_array_equal(viewed[1, -2:], vectors[1, -2 * GOALS : -2 * GOALS + 2])
    np.testing.assert_array_equal(agent.view(vectors, np.zeros_like(goals))[:, -2:], 0.0)  # no goal
    assert viewed.shape == (3, size)


def test_goal_offsets_need_an_encoder_fitted_on_observations_and_its_readout(discrete_env):
    robot = TouchEncoder(GOALS, features=FEATURES, hidden=8)
    observation = TouchEncoder(GOALS, features=FEATURES, hidden=8, labels="observation")
    for encoder, inputs, pose in ((robot, "readout", False), (observation, "features", False),
                                  (observation, "readout", True)):  # fmt: skip
        space = feature_space(discrete_env.observation_space, 8)
        learner = DQNAgent(space, discrete_env.action_space, DQNConfig(hidden=(16,)))
        with pytest.raises(ValueError, match="goal_offsets"):
            TouchAgent(learner, encoder, inputs=inputs, pose_inputs=pose, goal_offsets=True)
