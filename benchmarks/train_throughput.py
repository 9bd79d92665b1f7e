"""Training throughput: ours against Stable-Baselines3, same network, same update ratio, same env.

For each agent this prints the time of one update (batch 32) and the
environment steps per second of a short training run (``--start`` random
steps, then policy steps with ``updates_per_step`` updates each: 2, TD3 1),
side by side with Stable-Baselines3's DQN, SAC and TD3 given the paper's network
(encoder conv 32/64/64, goal and previous action joined after it, dense 512)
through a features extractor. Both use hindsight replay (SB3: its
HerReplayBuffer, 'future' goals; ours: the paper's rule) and Polyak targets
(tau 0.005). One difference favours SB3's SAC: its twin critics share one
encoder (as do TD3's), ours have one each as in the paper. Target: ours at least 2x SB3's
throughput.

    python benchmarks/train_throughput.py [--steps 150] [--updates 20]
"""

from __future__ import annotations

import argparse
import tempfile
import time

import gymnasium as gym
import numpy as np
import torch

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.agents import preset_config, read_progress, train
from tactile_braille.agents.replay import EpisodeReplayBuffer
from tactile_braille.agents.training import make_agent, make_env
from tactile_braille.supervised.networks import Encoder

TASKS = {
    "dqn": "tactile_braille/DiscreteArrows-v0",
    "sac_discrete": "tactile_braille/DiscreteArrows-v0",
    "sac": "tactile_braille/ContinuousArrows-v0",
    "td3": "tactile_braille/ContinuousArrows-v0",
}


def ours_update_ms(algo: str, precision: str, updates: int) -> float:
    config = preset_config("paper", TASKS[algo], algo, precision=precision)
    env = make_env(config)
    agent = make_agent(config, env)
    rng = np.random.default_rng(0)
    buffer = random_replay(env)
    for _ in range(3):
        agent.update(buffer.sample(32, rng))
    start = time.perf_counter()
    for _ in range(updates):
        agent.update(buffer.sample(32, rng))
    return (time.perf_counter() - start) / updates * 1e3


def random_replay(env: gym.Env, steps: int = 400, **options) -> EpisodeReplayBuffer:
    """A replay of ``steps`` random environment steps (``options``: the buffer's, e.g. ``extras``)."""
    action_shape = env.action_space.shape if isinstance(env.action_space, gym.spaces.Box) else ()
    buffer = EpisodeReplayBuffer(2_000, config_goal(env), action_shape, config_previous(env), **options)
    observation, _ = env.reset(seed=0)
    buffer.start_episode(observation)
    for _ in range(steps):
        action = env.action_space.sample()
        observation, reward, terminated, truncated, _ = env.step(action)
        buffer.add_step(action, reward, observation, terminated)
        if terminated or truncated:
            buffer.end_episode()
            observation, _ = env.reset()
            buffer.start_episode(observation)
    return buffer


def config_goal(env: gym.Env) -> int:
    return env.observation_space["desired_goal"].shape[0]


def config_previous(env: gym.Env) -> int:
    return env.observation_space["previous_action"].shape[0]


def ours_steps_per_second(algo: str, precision: str, start: int, steps: int) -> float:
    config = preset_config(
        "paper",
        TASKS[algo],
        algo,
        precision=precision,
        epochs=1,
        steps_per_epoch=start + steps,
        start_steps=start,
        evaluation={"test_episodes": 1},
    )
    with tempfile.TemporaryDirectory() as folder:
        run = train(config, run_dir=folder, progress=False)
        return read_progress(run)[0]["charts/SPS"]


class PaperExtractor:
    """SB3 features extractor: the paper's encoder with the goal and previous action joined after it."""

    @staticmethod
    def build():
        from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

        class Extractor(BaseFeaturesExtractor):
            def __init__(self, observation_space: gym.spaces.Dict):
                vectors = (
                    observation_space["desired_goal"].shape[0] + observation_space["previous_action"].shape[0]
                )
                super().__init__(observation_space, features_dim=64 * 9 * 9 + vectors)
                self.encoder = Encoder()

            def forward(self, observations: dict[str, torch.Tensor]) -> torch.Tensor:
                images = observations["observation"]  # SB3 hands images channel-first in [0, 1]
                vectors = [observations["desired_goal"], observations["previous_action"]]
                return torch.cat([self.encoder(images), *vectors], dim=-1)

        return Extractor


def sb3_model(algo: str, start: int):
    from stable_baselines3 import DQN, SAC, TD3, HerReplayBuffer

    env = gym.make(TASKS[algo])
    policy_kwargs = {"features_extractor_class": PaperExtractor.build(), "net_arch": [512]}
    common = dict(
        learning_starts=start, batch_size=32, buffer_size=10_000, train_freq=1, gradient_steps=2,
        policy_kwargs=policy_kwargs, device="cpu", seed=0, verbose=0, learning_rate=5e-4, gamma=0.95,
        tau=0.005, replay_buffer_class=HerReplayBuffer, replay_buffer_kwargs={"n_sampled_goal": 4},
    )  # fmt: skip
    if algo == "dqn":
        return DQN("MultiInputPolicy", env, exploration_fraction=0.1, target_update_interval=1, **common)
    if algo == "td3":
        common.update(gradient_steps=1, learning_rate=5e-5, target_policy_noise=0.05, target_noise_clip=0.2)
        return TD3("MultiInputPolicy", env, policy_delay=2, **common)
    return SAC("MultiInputPolicy", env, target_entropy=-6.0, **common)


def sb3_steps_per_second(algo: str, start: int, steps: int) -> float:
    model = sb3_model(algo, start)
    began = time.perf_counter()
    model.learn(start + steps)
    return (start + steps) / (time.perf_counter() - began)


def sb3_update_ms(algo: str, updates: int) -> float:
    model = sb3_model(algo, 400)
    model.learn(400)
    model.train(gradient_steps=3, batch_size=32)
    began = time.perf_counter()
    model.train(gradient_steps=updates, batch_size=32)
    return (time.perf_counter() - began) / updates * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--start", type=int, default=50, help="random steps before learning")
    parser.add_argument("--steps", type=int, default=150, help="learning steps timed")
    parser.add_argument("--updates", type=int, default=20, help="updates timed per agent")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--algos", nargs="+", default=list(TASKS), choices=list(TASKS))
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {args.threads} threads; batch 32; updates/step 2 (TD3 1)")
    print(f"{'agent':<34}{'ms/update':>10}{'steps/s':>10}{'vs SB3':>9}")
    counterparts = {"dqn": "dqn", "sac": "sac", "td3": "td3"}  # SB3 has no discrete SAC
    for algo in args.algos:
        reference = None
        if algo in counterparts:
            reference = sb3_steps_per_second(algo, args.start, args.steps)
            update = sb3_update_ms(algo, args.updates)
            name = f"SB3 {algo.upper()} (same network)"
            print(f"{name:<34}{update:>10.1f}{reference:>10.1f}{1.0:>8.2f}x")
        for precision in ("fp32", "bf16"):
            update = ours_update_ms(algo, precision, args.updates)
            rate = ours_steps_per_second(algo, precision, args.start, args.steps)
            ratio = f"{rate / reference:>8.2f}x" if reference else f"{'-':>9}"
            print(f"{f'ours {algo} {precision}':<34}{update:>10.1f}{rate:>10.1f}{ratio}")
    print("(updates per step: 2, TD3 1; ratios are steps/s against SB3's same algorithm in this run)")


if __name__ == "__main__":
    main()
