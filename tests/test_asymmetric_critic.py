"""Asymmetric critics: SAC's and TD3's critics may also see the sensor pose, the actor never does.

The pose is privileged: the arm's kinematics report it (and the simulator
knows it), but a policy that must type from touch alone cannot use it. Only
the critics, which exist for training, take it: batches carry ``poses`` and
``next_poses`` from the replay's frame labels, standardised by the touch
encoder's pose statistics.
"""

from __future__ import annotations

import importlib
import json

import gymnasium as gym
import numpy as np
import pytest
import torch

import toys
from tactile_braille.agents import EpisodeReplayBuffer, SACAgent, SACConfig, TD3Agent, TD3Config, TrainConfig
from tactile_braille.agents.common import POSE_SIZE
from tactile_braille.agents.networks import ContinuousQNetwork
from tactile_braille.agents.presets import preset_config
from tactile_braille.agents.report import load_run
from tactile_braille.agents.run import read_progress, setting_differences
from tactile_braille.agents.touch import TouchAgent, feature_space
from tactile_braille.supervised.touch import TouchEncoder

train_module = importlib.import_module("tactile_braille.agents.training")
toys.register()

TASK = "tactile_braille/ContinuousArrows-v0"
FEATURES, GOALS, PREVIOUS, ACTIONS = 6, 4, 3, 3


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def feature_observation_space() -> gym.spaces.Dict:
    return gym.spaces.Dict(
        {
            "observation": gym.spaces.Box(-np.inf, np.inf, (FEATURES,), np.float32),
            "previous_action": gym.spaces.Box(-1.0, 1.0, (PREVIOUS,), np.float32),
            "achieved_goal": gym.spaces.Box(0.0, 1.0, (GOALS,), np.float32),
            "desired_goal": gym.spaces.Box(0.0, 1.0, (GOALS,), np.float32),
        }
    )


ACTION_SPACE = gym.spaces.Box(-1.0, 1.0, (ACTIONS,), np.float32)
AGENT_KINDS = {"sac": (SACAgent, SACConfig), "td3": (TD3Agent, TD3Config)}


def make(algo: str, critic_pose: bool, seed: int = 0, **config):
    agent_class, config_class = AGENT_KINDS[algo]
    torch.manual_seed(seed)
    settings = {"hidden": (32, 32), "batch_size": 64, "learning_rate": 3e-3, "critic_pose": critic_pose}
    return agent_class(feature_observation_space(), ACTION_SPACE, config_class(**{**settings, **config}))


def batch(rng: np.random.Generator, size: int = 64, poses: bool = True) -> dict[str, np.ndarray]:
    """One-step episodes whose reward is hidden from the observation: 1 when pose x + action x > 0."""
    pose = rng.uniform(-1, 1, (size, POSE_SIZE)).astype(np.float32)
    actions = rng.uniform(-1, 1, (size, ACTIONS)).astype(np.float32)
    goals = np.eye(GOALS, dtype=np.float32)[rng.integers(GOALS, size=size)]
    result = {
        "images": rng.standard_normal((size, FEATURES)).astype(np.float32),
        "previous_actions": np.zeros((size, PREVIOUS), np.float32),
        "goals": goals,
        "actions": actions,
        "rewards": (pose[:, 0] + actions[:, 0] > 0).astype(np.float32),
        "next_images": rng.standard_normal((size, FEATURES)).astype(np.float32),
        "next_previous_actions": actions,
        "dones": np.ones(size, np.float32),
    }
    if poses:
        result["poses"], result["next_poses"] = pose, rng.uniform(-1, 1, (size, POSE_SIZE)).astype(np.float32)
    return result


def critic_error(agent, data: dict[str, np.ndarray]) -> float:
    t = agent.tensors(data)
    with torch.no_grad():
        poses = (t["poses"],) if agent.config.critic_pose else ()
        q = agent.critics[0](t["images"], t["goals"], t["previous_actions"], t["actions"], *poses)
    return float(((q - t["rewards"]) ** 2).mean())


# ---------------------------------------------------------------- networks and agents
def test_an_asymmetric_critic_takes_poses_and_a_plain_one_refuses_them():
    torch.manual_seed(0)
    sizes = (ACTIONS, GOALS, PREVIOUS, (16,))
    asymmetric = ContinuousQNetwork(*sizes, pose_size=POSE_SIZE, features=FEATURES)
    plain = ContinuousQNetwork(*sizes, features=FEATURES)
    inputs = (torch.randn(5, FEATURES), torch.eye(GOALS)[:1].repeat(5, 1), torch.zeros(5, PREVIOUS),
              torch.zeros(5, ACTIONS))  # fmt: skip
    poses = torch.randn(5, POSE_SIZE)
    assert asymmetric(*inputs, poses).shape == (5,) and plain(*inputs).shape == (5,)
    torch.nn.init.normal_(asymmetric.q.weight)  # away from the near-zero start, so the pose shows
    assert not torch.allclose(asymmetric(*inputs, poses), asymmetric(*inputs, poses + 1.0))
    with pytest.raises(ValueError, match="needs poses of size 3, got none"):
        asymmetric(*inputs)
    with pytest.raises(ValueError, match="takes no poses"):
        plain(*inputs, poses)
    with pytest.raises(ValueError, match="pose_size must be at least 0"):
        ContinuousQNetwork(*sizes, pose_size=-1, features=FEATURES)


@pytest.mark.parametrize("algo", ["sac", "td3"])
def test_only_the_critics_see_the_pose(algo):
    agent, plain = make(algo, True), make(algo, False)
    first_layer = [critic.trunk.dense[0].in_features for critic in agent.critics]
    assert first_layer == [plain.critics[0].trunk.dense[0].in_features + POSE_SIZE] * 2
    assert agent.actor.trunk.dense[0].in_features == plain.actor.trunk.dense[0].in_features
    observation = {
        "observation": np.zeros(FEATURES, np.float32),
        "previous_action": np.zeros(PREVIOUS, np.float32),
        "desired_goal": np.eye(GOALS, dtype=np.float32)[0],
    }
    action = agent.policy_action(observation, 0, explore=False, rng=np.random.default_rng(0))
    assert action.shape == (ACTIONS,)  # acting needs no pose


@pytest.mark.parametrize("algo", ["sac", "td3"])
def test_an_asymmetric_update_without_poses_says_what_is_missing(algo):
    agent = make(algo, True)
    with pytest.raises(ValueError, match="'poses' and 'next_poses'"):
        agent.update(batch(np.random.default_rng(0), poses=False))


@pytest.mark.parametrize("algo", ["sac", "td3"])
def test_the_asymmetric_critic_learns_a_value_that_only_the_pose_explains(algo):
    """The reward depends on the pose, hidden from the observation: only the pose-aware critic fits it."""
    rng = np.random.default_rng(0)
    agents = {pose: make(algo, pose, seed=1) for pose in (True, False)}
    for _ in range(400):
        data = batch(rng)
        for agent in agents.values():
            agent.update(data)
    held_out = batch(np.random.default_rng(99), size=2000)
    with_pose, without = critic_error(agents[True], held_out), critic_error(agents[False], held_out)
    # A critic blind to the pose can do no better than the reward's variance given the action
    # (about 0.17 for this reward); the pose-aware one approaches the noise-free target.
    assert without > 0.12, without
    assert with_pose < 0.5 * without, (with_pose, without)


# ---------------------------------------------------------------- replay and the touch wrapper
def one_step_episodes(buffer: EpisodeReplayBuffer, count: int, labelled: bool = True) -> list[np.ndarray]:
    """``count`` one-step episodes; returns the (first, next) labels of each, in order."""
    eye = np.eye(GOALS, dtype=np.float32)
    labels = []
    for episode in range(count):
        observation = {
            "observation": np.full(FEATURES, episode, np.float32),
            "previous_action": np.zeros(PREVIOUS, np.float32),
            "desired_goal": eye[episode % GOALS],
            "achieved_goal": np.zeros(GOALS, np.float32),
        }
        first = np.array([episode, -episode, 4.0, -1, episode % GOALS], np.float32)
        following = np.array([episode + 0.5, -episode - 0.5, 8.0, episode % GOALS, -1], np.float32)
        buffer.start_episode(observation, first if labelled else None)
        pressed = {**observation, "achieved_goal": eye[episode % GOALS]}
        buffer.add_step(np.full(ACTIONS, episode, np.float32), 1.0, pressed, True,
                        following if labelled else None)  # fmt: skip
        buffer.end_episode()
        labels.append(np.stack([first, following]))
    return labels


def test_a_replay_with_poses_gives_each_transition_the_poses_of_its_two_frames():
    buffer = EpisodeReplayBuffer(50, GOALS, (ACTIONS,), PREVIOUS, observation_shape=(FEATURES,), poses=True)
    labels = one_step_episodes(buffer, 10)
    data = buffer.sample(32, np.random.default_rng(0))
    episodes = data["actions"][:, 0].astype(int)  # each transition's action holds its episode
    expected = np.stack([labels[e] for e in episodes])
    np.testing.assert_array_equal(data["poses"], expected[:, 0, :3])
    np.testing.assert_array_equal(data["next_poses"], expected[:, 1, :3])
    plain = EpisodeReplayBuffer(50, GOALS, (ACTIONS,), PREVIOUS, observation_shape=(FEATURES,))
    one_step_episodes(plain, 3)
    assert "poses" not in plain.sample(4, np.random.default_rng(0))


def test_a_replay_with_poses_refuses_to_sample_unlabelled_frames():
    buffer = EpisodeReplayBuffer(50, GOALS, (ACTIONS,), PREVIOUS, observation_shape=(FEATURES,), poses=True)
    one_step_episodes(buffer, 3, labelled=False)
    with pytest.raises(RuntimeError, match="needs labelled frames"):
        buffer.sample(4, np.random.default_rng(0))


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


# ---------------------------------------------------------------- training runs and the preset
def test_critic_pose_needs_the_touch_encoders_labelled_frames(env_datasets):
    with pytest.raises(ValueError, match=r"critic_pose learns from a touch encoder.*set touch.enabled too"):
        TrainConfig(task=TASK, algo="sac", dataset=str(env_datasets[TASK]), agent=SACConfig(critic_pose=True))


def test_a_touch_run_trains_asymmetric_critics_on_the_labelled_poses(env_datasets, tmp_path):
    seen = []
    original = TouchAgent.update

    def recording_update(self, data):
        seen.append(data)
        return original(self, data)

    config = TrainConfig(
        task=TASK,
        algo="sac",
        epochs=1,
        steps_per_epoch=30,
        start_steps=12,
        threads=1,
        dataset=str(env_datasets[TASK]),
        agent=SACConfig(hidden=(16,), batch_size=8, critic_pose=True),
        evaluation={"test_episodes": 1, "snapshots": 1},
        replay={"capacity": 200},
        touch={"enabled": True, "epochs": 2},
    )
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(TouchAgent, "update", recording_update)
        run = train_module.train(config, run_dir=tmp_path / "run", progress=False)
    (row,) = read_progress(run)
    assert len(seen) == row["updates"] > 0
    for data in seen:
        assert data["poses"].shape == data["next_poses"].shape == (8, POSE_SIZE)
        # Work-frame poses of the arrow task, in mm: x in [-20, 0] around the block, depths 2..8 mm.
        assert (
            np.isfinite(data["poses"]).all()
            and ((data["poses"][:, 2] >= 2) & (data["poses"][:, 2] <= 8)).all()
        )
    _, _, agent = load_run(run)
    assert agent.agent.config.critic_pose and agent.agent.critics[0].pose_size == POSE_SIZE


def test_the_fast_preset_gives_its_continuous_alphabet_additions_to_that_task_only():
    for algo in ("sac", "td3"):
        config = preset_config("fast", "tactile_braille/ContinuousAlphabet-v0", algo)
        assert config.agent.critic_pose and config.touch.goal_positions and config.touch.inputs == "readout"
    for preset, task in (("fast", TASK), ("paper", "tactile_braille/ContinuousAlphabet-v0")):
        config = preset_config(preset, task, "sac")
        assert not config.agent.critic_pose and not config.touch.goal_positions
        assert config.touch.inputs == "features"


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


def test_goal_positions_need_a_touch_encoder_and_a_keyboard(env_datasets):
    with pytest.raises(
        ValueError, match=r"touch.goal_positions learns from a touch encoder.* set touch.enabled too"
    ):
        TrainConfig(task=TASK, algo="sac", dataset=str(env_datasets[TASK]), touch={"goal_positions": True})
    with pytest.raises(ValueError, match=r"touch.inputs='readout' learns from a touch encoder"):
        TrainConfig(task=TASK, algo="sac", dataset=str(env_datasets[TASK]), touch={"inputs": "readout"})
    with pytest.raises(ValueError, match="a keyboard layout"):
        TrainConfig(task="toys/BitFlipPress-v0", algo="dqn", touch={"enabled": True, "goal_positions": True})


def test_a_run_with_placed_goals_acts_on_env_observations_and_learns_on_placed_goals(env_datasets, tmp_path):
    config = TrainConfig(
        task=TASK,
        algo="sac",
        epochs=1,
        steps_per_epoch=30,
        start_steps=12,
        threads=1,
        dataset=str(env_datasets[TASK]),
        agent=SACConfig(hidden=(16,), batch_size=8, critic_pose=True),
        evaluation={"test_episodes": 2, "snapshots": 1},
        replay={"capacity": 200},
        touch={"enabled": True, "epochs": 2, "goal_positions": True},
    )
    run = train_module.train(config, run_dir=tmp_path / "run", progress=False)
    _, env, agent = load_run(run)
    layout = env.unwrapped.layout
    expected = np.array([layout.centre_mm(key) for key in env.unwrapped.goal_keys], np.float32)
    np.testing.assert_array_equal(agent.key_positions_mm, expected)
    observation, _ = env.reset(seed=0)
    assert observation["desired_goal"].shape == (GOALS,)  # the environment is unchanged
    placed = agent.features(observation)["desired_goal"]
    goal = int(observation["desired_goal"].argmax())
    mean, scale = agent.touch.pose_mean.numpy()[:2], agent.touch.pose_scale.numpy()[:2]
    np.testing.assert_allclose(placed[GOALS:] * scale + mean, expected[goal], rtol=1e-5)
    assert agent.policy_action(observation, 0, explore=False, rng=np.random.default_rng(0)).shape == (
        ACTIONS,
    )


# ---------------------------------------------------------------- learning on the encoder's readout
def test_the_readout_is_the_standardised_pose_and_two_key_distributions():
    torch.manual_seed(0)
    encoder = TouchEncoder(GOALS, features=FEATURES, hidden=8).eval()
    images = np.random.default_rng(0).integers(0, 2, (5, 100, 100, 1), dtype=np.uint8) * 255
    readout = encoder.read(images)
    assert readout.shape == (5, encoder.readout_size) and encoder.readout_size == 3 + 2 * (GOALS + 1)
    with torch.no_grad():
        pose, pressed, under = encoder.heads(torch.as_tensor(np.moveaxis(images, -1, 1)))
    np.testing.assert_allclose(readout[:, :3], pose.numpy(), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(
        readout[:, 3 : 3 + GOALS + 1], pressed.softmax(-1).numpy(), rtol=1e-5, atol=1e-6
    )
    np.testing.assert_allclose(readout[:, 3 + GOALS + 1 :], under.softmax(-1).numpy(), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(readout[:, 3:].reshape(5, 2, GOALS + 1).sum(-1), 1.0, rtol=1e-5)


def test_a_touch_agent_on_the_readout_encodes_with_the_heads():
    encoder = TouchEncoder(GOALS, features=FEATURES, hidden=8)
    space = feature_space(feature_observation_space(), encoder.readout_size)
    agent = TouchAgent(SACAgent(space, ACTION_SPACE, SACConfig(hidden=(8,))), encoder, inputs="readout")
    images = np.zeros((2, 100, 100, 1), np.uint8)
    assert agent.input_size == encoder.readout_size
    np.testing.assert_array_equal(agent.encode(images), encoder.read(images))
    with pytest.raises(ValueError, match="inputs must be one of"):
        TouchAgent(agent.agent, encoder, inputs="pixels")


def test_a_run_on_the_readout_learns_and_acts_on_it(env_datasets, tmp_path):
    config = TrainConfig(
        task=TASK,
        algo="sac",
        epochs=1,
        steps_per_epoch=30,
        start_steps=12,
        threads=1,
        dataset=str(env_datasets[TASK]),
        agent=SACConfig(hidden=(16,), batch_size=8),
        evaluation={"test_episodes": 2, "snapshots": 1},
        replay={"capacity": 200},
        touch={"enabled": True, "epochs": 2, "inputs": "readout"},
    )
    run = train_module.train(config, run_dir=tmp_path / "run", progress=False)
    _, env, agent = load_run(run)
    assert agent.inputs == "readout" and agent.agent.actor.trunk.dense[0].in_features == (
        agent.touch.readout_size + GOALS + PREVIOUS
    )
    observation, _ = env.reset(seed=0)
    np.testing.assert_array_equal(
        agent.features(observation)["observation"], agent.touch.read(observation["observation"][None])[0]
    )
    assert agent.policy_action(observation, 0, explore=False, rng=np.random.default_rng(0)).shape == (
        ACTIONS,
    )
    with pytest.raises(ValueError, match=r"TouchConfig.inputs must be one of"):
        config.with_changes(touch={"inputs": "pixels"})


@pytest.mark.parametrize("algo", ["sac", "td3"])
def test_targets_see_the_next_poses_and_the_critics_and_the_actors_loss_the_poses(algo):
    agent = make(algo, True, policy_delay=1) if algo == "td3" else make(algo, True)
    targets = agent.critic_targets if algo == "td3" else agent.targets
    seen: dict[str, list[torch.Tensor]] = {"online": [], "target": []}

    def hook(kind):
        return lambda module, inputs: seen[kind].append(inputs[-1].detach().clone())

    for critic in agent.critics:
        critic.register_forward_pre_hook(hook("online"))
    for target in targets:
        target.register_forward_pre_hook(hook("target"))
    data = batch(np.random.default_rng(0))
    data["dones"] = np.zeros_like(data["dones"])  # the targets' values count
    agent.update(data)
    poses, next_poses = torch.as_tensor(data["poses"]), torch.as_tensor(data["next_poses"])
    assert seen["target"] and all(torch.equal(p, next_poses) for p in seen["target"])
    # Both critics' losses and the actor's loss (the first critic, or both for SAC's minimum).
    assert len(seen["online"]) >= 3 and all(torch.equal(p, poses) for p in seen["online"])


def test_a_run_with_every_addition_resumes_on_its_readout(env_datasets, tmp_path):
    sizes = []
    original = EpisodeReplayBuffer.set_encoder

    def recording_set_encoder(self, encode, size, *args, **kwargs):
        sizes.append(size)
        return original(self, encode, size, *args, **kwargs)

    config = TrainConfig(
        task=TASK,
        algo="sac",
        epochs=2,
        steps_per_epoch=20,
        start_steps=12,
        threads=1,
        dataset=str(env_datasets[TASK]),
        agent=SACConfig(hidden=(16,), batch_size=8, critic_pose=True),
        evaluation={"test_episodes": 1, "snapshots": 1},
        replay={"capacity": 200},
        touch={
            "enabled": True,
            "epochs": 2,
            "refits": 1,
            "refit_every": 20,
            "goal_positions": True,
            "inputs": "readout",
        },
    )
    run = tmp_path / "run"
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(EpisodeReplayBuffer, "set_encoder", recording_set_encoder)
        train_module.train(config, run_dir=run, progress=False)
        before = torch.load(run / "checkpoint.pt", weights_only=False)["agent"]
        stored = json.loads((run / "config.json").read_text())
        stored["epochs"] = 3
        (run / "config.json").write_text(json.dumps(stored))
        train_module.train(run_dir=run, resume=True, progress=False)
    readout = TouchEncoder(GOALS).readout_size
    assert sizes == [readout] * len(sizes) and len(sizes) == 3  # the first fit, the refit, the resume
    assert [row["epoch"] for row in read_progress(run)] == [0, 1, 2]
    assert setting_differences(run, config) == []
    _, _, agent = load_run(run)
    after = agent.state_dict()
    assert not torch.equal(before["critics"]["0.q.weight"], after["critics"]["0.q.weight"])  # it learnt on
    assert agent.inputs == "readout" and agent.key_positions_mm is not None and agent.agent.config.critic_pose


def test_a_run_from_before_these_settings_compares_with_their_defaults(env_datasets, tmp_path):
    config = TrainConfig(task=TASK, algo="sac", dataset=str(env_datasets[TASK]), touch={"enabled": True})
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
