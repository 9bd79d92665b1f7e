"""Stable-Baselines3 with Hindsight Experience Replay on a braille task, scored by the benchmark.

A baseline from the library most users already have: SB3's DQN (discrete
tasks), SAC or TD3 (continuous tasks) with its ``HerReplayBuffer``, on the
environment exactly as registered (no wrapper, no extra information: the
``tactile`` track), with the untuned settings of
``tactile_braille.baselines.sb3.DEFAULTS``. After training, the model types
the paper's sequences through ``tactile_braille.evaluation.evaluate_policy``
and the results file is written for the leaderboard.

    python examples/sb3_her.py DiscreteArrows-v0 dqn --steps 6000 --seed 0 \\
        --output results/leaderboard/sb3/DiscreteArrows-v0__dqn__0.json

The same agents tuned by the benchmark's protocol (a search on tuning seeds,
then fresh seeds): ``python -m tactile_braille.baselines.sb3`` (docs/benchmark.md).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.baselines.sb3 import ALGORITHMS, DEFAULTS, score, train
from tactile_braille.evaluation.results import make_result, write_result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("task", help="e.g. DiscreteArrows-v0")
    parser.add_argument("algo", choices=sorted(DEFAULTS))
    parser.add_argument("--steps", type=int, required=True, help="environment steps to train")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--output", type=Path, required=True, help="the results file to write")
    parser.add_argument("--dataset", type=Path, help="the dataset backend's file (default: the cached one)")
    parser.add_argument("--learning-starts", type=int, default=DEFAULTS["dqn"]["learning_starts"])
    parser.add_argument("--save", type=Path, help="also save the model (an SB3 zip)")
    args = parser.parse_args(argv)
    if args.output.exists():
        parser.error(f"{args.output} exists; choose another name")
    if args.learning_starts <= 25:  # HER samples from finished episodes only
        parser.error("--learning-starts must exceed an episode's 25 steps")

    settings = {"learning_starts": args.learning_starts}
    model, seconds = train(args.task, args.algo, settings, args.steps, args.seed, args.dataset)
    if args.save is not None:
        model.save(args.save)
    report = score(model, args.task, args.dataset)
    result = make_result(
        report, method=ALGORITHMS[args.algo].label, seed=args.seed, env_steps=args.steps,
        notes=f"examples/sb3_her.py; {seconds / 60:.0f} min on 1 CPU thread(s)",
    )  # fmt: skip
    write_result(result, args.output)
    print(f"{args.task} {args.algo} seed {args.seed}: accuracy {report.accuracy:.3f}, "
          f"{report.total_steps} steps ({args.steps} env steps trained in {seconds / 60:.1f} min); "
          f"wrote {args.output}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
