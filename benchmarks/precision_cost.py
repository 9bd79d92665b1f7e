"""What bf16 autocast buys on this machine: one update of each agent in fp32 and in bf16, side by side.

bf16 pays only where the processor computes it natively (AVX512-BF16 or AMX
on x86, CUDA from compute capability 8): the committed Table III rows ran on
such CPUs, where bf16 took about half fp32's time (``train_throughput.py``).
On a CPU with AVX2 alone torch emulates it, and the same update runs several
times slower than in fp32; agents made with bf16 there warn
(:func:`tactile_braille.agents.common.native_bf16`). The agents are the
``paper`` and ``released`` presets' (batch 32, one thread), on a replay of
random environment steps; the two precisions are timed in alternating
rounds, so that a shared, noisy machine slows both alike, and the ratio is
the figure to read.

    python benchmarks/precision_cost.py [--updates 5] [--rounds 3]
"""

from __future__ import annotations

import warnings

import numpy as np
import torch

import tactile_braille  # noqa: F401 - registers the environments
from all_goals_cost import alternating_ms, timing_arguments  # this folder's
from tactile_braille.agents import preset_config
from tactile_braille.agents.common import native_bf16
from tactile_braille.agents.training import make_agent, make_env
from train_throughput import random_replay  # this folder's

CASES = (
    ("paper", "dqn", "tactile_braille/DiscreteAlphabet-v0"),
    ("paper", "sac_discrete", "tactile_braille/DiscreteArrows-v0"),
    ("paper", "sac", "tactile_braille/ContinuousArrows-v0"),
    ("released", "sac", "tactile_braille/ContinuousAlphabet-v0"),
    ("paper", "td3", "tactile_braille/ContinuousArrows-v0"),
)


def main() -> None:
    args = timing_arguments(__doc__, updates=5, rounds=3)
    print(f"CPU: {torch.backends.cpu.get_cpu_capability()} kernels; native bf16: {native_bf16('cpu')}")
    print(f"{'preset':<10}{'agent':<14}{'task':<22}{'fp32':>10}{'bf16':>11}{'bf16/fp32':>11}")
    for preset, algo, task in CASES:
        env = make_env(preset_config(preset, task, algo))
        buffer, rng = random_replay(env), np.random.default_rng(0)
        batches = [buffer.sample(32, rng) for _ in range(args.updates)]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # the emulated-bf16 warning: measured here
            agents = {
                precision: make_agent(preset_config(preset, task, algo, precision=precision), env)
                for precision in ("fp32", "bf16")
            }
        medians = alternating_ms(agents, batches, args.rounds, warm_up=1)
        fp32, bf16 = medians["fp32"], medians["bf16"]
        name = task.split("/")[1]
        print(f"{preset:<10}{algo:<14}{name:<22}{fp32:>7.0f} ms{bf16:>8.0f} ms{bf16 / fp32:>11.2f}")
        env.close()


if __name__ == "__main__":
    main()
