"""MR.Q (agents/mrq.py) and what it reads from the replay: sub-trajectories, batches at chosen slots, its
settings, the reward model's two-hot encoding, prioritised sampling, and short real runs of the loop on
both kinds of task (tiny networks: the tests are of the algorithm's parts and the loop, not of learning;
``test_mrq_learns_to_type_the_discrete_arrows`` is the slow learning check)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

from agents_helpers import through_file
from replay_helpers import (
    FEATURES,
    GOALS,
    PREVIOUS,
    Frames,
    feature_episode,
    goal_indices,
    n_step_buffer,
    replay_observation,
)
from tactile_braille.agents import TrainConfig, train
from tactile_braille.agents.config import MRQConfig
from tactile_braille.agents.mrq import MRQAgent, TwoHot
from tactile_braille.agents.presets import preset_config
from tactile_braille.agents.replay import EpisodeReplayBuffer, SubTrajectories
from tactile_braille.agents.report import load_run
from tactile_braille.agents.run import read_progress

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TINY = {"batch_size": 8, "target_every": 4, "hidden_units": 16, "state_size": 16, "state_action_size": 16,
        "action_size": 8}  # fmt: skip


# ---------------------------------------------------------------- the replay's side
def three_episodes(relabel: str = "paper", horizon: int = 4, capacity: int = 100):
    buffer = n_step_buffer(1, relabel, capacity, extras=(SubTrajectories(horizon),))
    feature_episode(buffer, goal=1, pressed=1, steps=5, first_frame=0)  # right press: frames 0-5
    feature_episode(buffer, goal=0, pressed=2, steps=4, first_frame=10)  # wrong press: frames 10-14
    feature_episode(buffer, goal=3, pressed=None, steps=2, first_frame=20)  # time-out: frames 20-22
    return buffer


@pytest.mark.parametrize("relabel", ["paper", "all"])
def test_a_sub_trajectory_follows_its_episode_under_the_batch_goal_and_is_masked_past_its_end(relabel):
    batch = three_episodes(relabel).sample(3000, np.random.default_rng(0))
    lengths, pressed = {0: 5, 10: 4, 20: 2}, {0: 1, 10: 2, 20: None}
    for t, first, goal, reward, actions, rewards, dones, valid, frames in zip(
        batch["actions"], batch["images"][:, 0], goal_indices(batch["goals"]), batch["rewards"],
        batch["horizon_actions"], batch["horizon_rewards"], batch["horizon_dones"], batch["horizon_valid"],
        batch["horizon_next_images"][:, :, 0], strict=True,
    ):  # fmt: skip
        start = int(first) - t
        inside = np.arange(4) <= lengths[start] - 1 - t  # the steps left in the episode
        np.testing.assert_array_equal(valid, inside)
        np.testing.assert_array_equal(actions[inside], t + np.arange(4)[inside])
        np.testing.assert_array_equal(frames[inside], first + 1 + np.arange(4)[inside])
        last = inside & (t + np.arange(4) == lengths[start] - 1)
        np.testing.assert_array_equal(dones, last & (pressed[start] is not None))
        np.testing.assert_array_equal(rewards, last & (pressed[start] == goal))
        assert rewards[0] == reward  # the batch's own reward, relabelled alike
    assert batch["horizon_valid"][:, 3].any() and not batch["horizon_valid"].all()


def test_a_sub_trajectory_keeps_its_episode_where_the_ring_wraps():
    buffer = n_step_buffer(1, "all", capacity=7, extras=(SubTrajectories(3),))
    for episode in range(5):  # 3 steps each: the ring wraps
        feature_episode(buffer, goal=0, pressed=0, steps=3, first_frame=10 * episode)
    batch = buffer.sample(300, np.random.default_rng(0))
    frames, valid = batch["horizon_next_images"][:, :, 0], batch["horizon_valid"].astype(bool)
    expected = batch["images"][:, :1] + 1 + np.arange(3)
    assert (frames[valid] == expected[valid]).all() and (~valid).any()


def test_a_batch_can_be_sampled_at_chosen_slots_and_bad_slots_are_refused():
    buffer = three_episodes()
    slots = np.array([0, 4, 9, 10])
    batch = buffer.sample(4, np.random.default_rng(0), index=slots)
    # slots 0-4: the first episode; 5-8 the second, 9-12 its relabelled copy; 13-14 the third
    np.testing.assert_array_equal(batch["images"][:, 0], [0, 4, 10, 11])
    np.testing.assert_array_equal(goal_indices(batch["goals"]), [1, 1, 2, 2])
    with pytest.raises(ValueError, match=r"index must hold 4 slots in \[0, 15\)"):
        buffer.sample(4, np.random.default_rng(0), index=np.array([0, 1, 2, 15]))
    with pytest.raises(ValueError, match="index must hold 4 slots"):
        buffer.sample(4, np.random.default_rng(0), index=np.array([0, 1]))


def test_sub_trajectories_refuse_a_replay_that_shifts_images():
    buffer = three_episodes()
    buffer.shift = 2
    with pytest.raises(ValueError, match="not shifted by the replay"):
        buffer.sample(4, np.random.default_rng(0))


def test_mrq_shifts_every_image_of_its_batches_by_up_to_image_shift_pixels():
    box = lambda size: gym.spaces.Box(0.0, 1.0, (size,), np.float32)  # noqa: E731
    observation_space = gym.spaces.Dict({
        "observation": gym.spaces.Box(0, 255, (100, 100, 1), np.uint8), "desired_goal": box(GOALS),
        "achieved_goal": box(GOALS), "previous_action": box(PREVIOUS),
    })  # fmt: skip
    action_space = gym.spaces.Discrete(5)
    buffer = EpisodeReplayBuffer(100, GOALS, (), PREVIOUS, extras=(SubTrajectories(5),))
    frames = Frames()
    for _ in range(3):
        buffer.start_episode(replay_observation(frames(), 0))
        for step in range(4):
            buffer.add_step(step, 0.0, replay_observation(frames(), 0), False)
        buffer.end_episode()
    for pixels in (0, 2):
        agent = MRQAgent(observation_space, action_space, MRQConfig(**TINY, image_shift=pixels))
        agent._mark_new(buffer)
        batch = agent._draw(buffer, 16, np.random.default_rng(pixels))
        originals = buffer.store.observations(buffer.frame_index[batch["slots"], 0])
        shifted = [any((_shift(o, dr, dc) == b).all() for dr in range(-2, 3) for dc in range(-2, 3))
                   for o, b in zip(originals, batch["images"], strict=True)]  # fmt: skip
        assert all(shifted) and "next_images" not in batch
        assert (batch["images"] == originals).all() == (pixels == 0)
        assert batch["horizon_next_images"].shape == (16, 5, 1, 100, 100)


def _shift(image: np.ndarray, rows: int, columns: int) -> np.ndarray:
    padded = np.pad(image, ((0, 0), (2, 2), (2, 2)), mode="edge")
    return padded[:, 2 + rows : 102 + rows, 2 + columns : 102 + columns]


@pytest.mark.parametrize("horizon", [0, 1.5, True])
def test_a_sub_trajectory_needs_a_whole_horizon(horizon):
    with pytest.raises(ValueError, match="horizon must be a whole number >= 1"):
        SubTrajectories(horizon)


# ---------------------------------------------------------------- settings and the reward model
@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"target_every": 0}, "target_every must be at least 1"),
        ({"encoder_horizon": 0}, "encoder_horizon must be at least 1"),
        ({"reward_bins": 1}, "reward_bins must be at least 2"),
        ({"priority_alpha": 1.5}, r"priority_alpha must be in \[0, 1\]"),
        ({"min_priority": 0.0}, "min_priority must be positive"),
        ({"value_learning_rate": -1e-4}, "value_learning_rate must be positive"),
        ({"exploration_noise": -0.1}, "exploration_noise must not be negative"),
        ({"gamma": 1.5}, r"gamma must be in \[0, 1\]"),
    ],
)
def test_bad_mrq_settings_are_refused_by_name(change, message):
    with pytest.raises(ValueError, match=message):
        MRQConfig(**change)


def test_mrq_refuses_the_replays_n_step_returns_and_shifts_it_makes_itself():
    with pytest.raises(ValueError, match=r"replay.n_step must be 1, got 3"):
        TrainConfig(algo="mrq", replay={"n_step": 3})
    with pytest.raises(ValueError, match=r"agent.image_shift\): replay.shift must be 0, got 2"):
        TrainConfig(algo="mrq", replay={"shift": 2})
    assert TrainConfig(algo="mrq").updates_per_step == 1


def test_the_fast_presets_refuse_mrq_by_name():
    for preset in ("fast", "fast-tactile"):
        with pytest.raises(
            ValueError, match=rf"--preset {preset} holds settings for .* not mrq: use --preset paper"
        ):
            preset_config(preset, "tactile_braille/DiscreteArrows-v0", "mrq")
    assert preset_config("paper", "tactile_braille/DiscreteArrows-v0", "mrq").agent == MRQConfig()


def test_the_two_hot_encoding_puts_each_reward_between_its_two_bins():
    two_hot = TwoHot(65, 10.0, torch.device("cpu"))
    rewards = torch.tensor([0.0, 1.0, 0.37, -2.5, 1e6])
    encoded = two_hot.encode(rewards)
    torch.testing.assert_close(encoded.sum(-1), torch.ones(5))
    assert ((encoded > 0).sum(-1) <= 2).all()
    decoded = (encoded * two_hot.values).sum(-1)
    torch.testing.assert_close(decoded[:4], rewards[:4])
    assert decoded[4] == two_hot.values[-1]  # beyond the range: the last bin
    sharp = torch.full((1, 65), -1e4)
    sharp[0, 32] = 1e4  # the bin of 0
    assert two_hot.cross_entropy(sharp, torch.tensor([0.0])).item() == pytest.approx(0.0, abs=1e-4)


def test_the_discrete_policy_learns_the_values_best_action_under_the_batch_goal():
    box = lambda size: gym.spaces.Box(-np.inf, np.inf, (size,), np.float32)  # noqa: E731
    observation_space = gym.spaces.Dict({
        "observation": box(FEATURES), "desired_goal": box(GOALS), "achieved_goal": box(GOALS),
        "previous_action": box(PREVIOUS),
    })  # fmt: skip
    torch.manual_seed(0)
    agent = MRQAgent(observation_space, gym.spaces.Discrete(PREVIOUS),
                     MRQConfig(**TINY, image_shift=0, policy_learning_rate=3e-3))  # fmt: skip
    for optimiser in (agent.encoder_optimiser, agent.value_optimiser):  # the value stays as it is
        optimiser.param_groups[0]["lr"] = 0.0
    buffer, rng = three_episodes(horizon=5), np.random.default_rng(0)
    for _ in range(200):
        agent.update(agent.sample(buffer, 8, rng))
    t = agent.tensors(agent._draw(buffer, 256, rng))
    with torch.no_grad():
        zs = agent.encoder.zs(t["images"], t["goals"], t["previous_actions"])
        greedy, best = agent.policy(zs, t["goals"]).argmax(-1), agent._best_actions(zs, t["goals"])
    assert len(best.unique()) > 1  # the value ranks the actions differently across states and goals
    assert (greedy == best).float().mean() > 0.95


# ---------------------------------------------------------------- the agent in the loop
def _run(env_datasets, tmp_path, task: str, epochs: int = 1, name: str = "run"):
    config = TrainConfig(
        task=task, algo="mrq", epochs=epochs, steps_per_epoch=40, start_steps=20,
        dataset=str(env_datasets[task]), threads=1, agent=TINY, evaluation={"test_episodes": 1},
        replay={"capacity": 500},
    )  # fmt: skip
    return train(config, run_dir=tmp_path / name, progress=False)


@pytest.mark.parametrize("task", ["tactile_braille/DiscreteArrows-v0", "tactile_braille/ContinuousArrows-v0"])
def test_mrq_trains_in_the_loop_checkpoints_and_resumes_as_if_never_stopped(env_datasets, tmp_path, task):
    run = _run(env_datasets, tmp_path, task)
    (row,) = read_progress(run)
    assert int(row["updates"]) == 21  # one update per step, from the last start step on
    for name in ("q_loss", "policy_loss", "encoder_dynamics", "encoder_reward", "encoder_done"):
        assert np.isfinite(float(row[f"losses/{name}"])), name

    _, env, agent = load_run(run)
    assert isinstance(agent, MRQAgent)
    assert len(agent.priorities) == 500 and agent.priorities.max() >= 1.0  # LAP's floor, set by updates
    assert agent.counters[0] == 21 and agent.counters[1] > 0  # updates done, the replay's reward scale
    fresh = MRQAgent(env.observation_space, env.action_space, MRQConfig(**TINY))
    fresh.load_state_dict(through_file(agent.state_dict()))
    torch.testing.assert_close(fresh.priorities, agent.priorities)
    torch.testing.assert_close(fresh.counters, agent.counters)
    observation, _ = env.reset(seed=3)
    mine, theirs = (
        np.asarray(a.policy_action(observation, 0, False, np.random.default_rng(0))) for a in (agent, fresh)
    )
    np.testing.assert_array_equal(mine, theirs)

    config_file = run / "config.json"  # resumed to two epochs, it logs the rows of a run of two
    config_file.write_text(config_file.read_text().replace('"epochs": 1,', '"epochs": 2,'))
    train(run_dir=run, resume=True, progress=False)
    straight = _run(env_datasets, tmp_path, task, epochs=2, name="straight")
    assert _rows_but_time(run) == _rows_but_time(straight) and len(_rows_but_time(run)) == 2


def _rows_but_time(run) -> list[dict]:
    return [{k: v for k, v in row.items() if k not in ("charts/SPS", "time_s")} for row in read_progress(run)]
