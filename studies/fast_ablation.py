"""Ablation of the ``fast`` preset: each of its parts taken away, on the same seeds and budget.

Trains (or continues, if its folder exists) one run per variant and seed under
``runs/ablation/`` and prints, per variant, the convergence epoch under the
paper's rule and the first epoch at 0.95, with the wall clock per run. The
report command turns the same runs into the table and curves of
docs/results.md.

    python studies/fast_ablation.py --task DiscreteAlphabet-v0 --algo dqn --seeds 0
    python studies/fast_ablation.py --variants fast no-refits --seeds 0 1 2
    python studies/fast_ablation.py --task ContinuousAlphabet-v0 --algo sac --variants latent
    python studies/fast_ablation.py --task DiscreteArrows-v0 --variants tactile-no-goal-offsets \
        tactile-features tactile-paper-relabel paper+all --seeds 0 1 2 --archive results/ablation-tactile

``--archive DIR`` copies each run's record (with its typing evaluation) to DIR, where ``make results``
finds it.

Variants (``fast`` with one change each; ``paper+all`` is the paper's preset
with only the relabelling of every transition added, on images):
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from tactile_braille.agents.presets import preset_config
from tactile_braille.agents.report import convergence_epoch
from tactile_braille.agents.run import read_progress, setting_differences
from tactile_braille.agents.training import train
from tactile_braille.sweep import archive_run

VARIANTS = {
    "fast": ("fast", {}),
    "no-refits": ("fast", {"touch": {"refits": 0}}),
    "refit-500": ("fast", {"touch": {"refit_every": 500, "refits": 8}}),
    "paper-relabel": ("fast", {"replay": {"relabel": "paper"}}),
    "paper+all": ("paper", {"replay": {"relabel": "all"}}),
    # The continuous alphabet's additions, taken away one after another: the readout, the placed
    # goals, the asymmetric critics (what is left is the first fast preset, of 2026-11-22).
    "latent": ("fast", {"touch": {"inputs": "features"}}),
    "latent-no-goal-positions": ("fast", {"touch": {"inputs": "features", "goal_positions": False}}),
    "session-3-fast": (
        "fast",
        {"agent": {"critic_pose": False}, "touch": {"inputs": "features", "goal_positions": False}},
    ),
    # The same additions on the continuous arrows, which the preset leaves without them.
    "alphabet-additions": (
        "fast",
        {"agent": {"critic_pose": True}, "touch": {"inputs": "readout", "goal_positions": True}},
    ),
    # fast-tactile's parts taken away: the goal's offset (the learner sees the readout and the goal
    # one-hot), then the readout (the encoder's features), or the relabelling of every transition.
    "tactile-no-goal-offsets": ("fast-tactile", {"touch": {"goal_positions": False}}),
    "tactile-features": ("fast-tactile", {"touch": {"inputs": "features", "goal_positions": False}}),
    "tactile-paper-relabel": ("fast-tactile", {"replay": {"relabel": "paper"}}),
    # The key-graph planner's parts (``--algo planner``), taken away one at a time: its belief filter,
    # its optimism for moves the graph has not seen, its repeat penalty; on the discrete tasks the
    # memory of the key a cell off the keys was left from and the final press of a training episode;
    # on the continuous ones the entry states and the exploration that presses 8 times in 10; on the
    # discrete ones the occupancy its backtracking reads with and the worthless generic nothing of
    # its value iteration; on the continuous ones the test press that waits for a frame showing the
    # goal (at 0.8 since commit 519e9cf, 0.5 before), and the first frame's press; on the continuous
    # alphabet the test episodes' memory of where each move led.
    "planner-no-filter": ("fast-tactile", {"agent": {"filter": False}}),
    "planner-no-optimism": ("fast-tactile", {"agent": {"optimism": False}}),
    "planner-no-repeat-penalty": ("fast-tactile", {"agent": {"repeat_penalty": 0.0}}),
    "planner-no-nothing-memory": ("fast-tactile", {"agent": {"nothing_memory": False}}),
    "planner-no-final-press": ("fast-tactile", {"final_press": False}),
    "planner-no-entry-memory": ("fast-tactile", {"agent": {"entry_memory": False}}),
    "planner-uniform-exploration": ("fast-tactile", {"agent": {"explore_press": None}}),
    "planner-no-occupancy": ("fast-tactile", {"agent": {"backtrack_prior": False}}),
    "planner-no-lost-value": ("fast-tactile", {"agent": {"lost_value": None}}),
    "planner-no-press-reading": ("fast-tactile", {"agent": {"press_reading": None}}),
    "planner-no-outcome-memory": ("fast-tactile", {"agent": {"outcome_memory": False}}),
    "planner-press-reading-0.5": ("fast-tactile", {"agent": {"press_reading": 0.5}}),
    "planner-first-press": ("fast-tactile", {"agent": {"first_press": True}}),
}
__doc__ += "".join(f"\n* ``{name}``: preset {preset}, {changes or 'as it is'}" for name, (preset, changes) in
                   VARIANTS.items())  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--task", default="DiscreteAlphabet-v0")
    parser.add_argument("--algo", default="dqn")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    parser.add_argument("--epochs", type=int, default=None, help="default: each variant's preset's")
    parser.add_argument("--root", type=Path, default=Path("runs/ablation"))
    parser.add_argument("--archive", type=Path, default=None, help="copy each run's record here")
    parser.add_argument("--precision", choices=("bf16", "fp32"), default=None,
                        help="default: the preset's")  # fmt: skip
    args = parser.parse_args()
    task = f"tactile_braille/{args.task}"
    print(f"{args.task}, {args.algo}, seeds {args.seeds}")
    print("| variant | seeds | convergence epoch (paper's rule) | first epoch >= 0.95 | minutes per run |")
    print("|---|---|---|---|---|")
    for name in args.variants:
        preset, changes = VARIANTS[name]
        epochs = args.epochs or preset_config("fast" if preset == "paper" else preset, task, args.algo).epochs
        paper_rule, absolute, minutes = [], [], []
        for seed in args.seeds:
            run = args.root / f"{args.task.split('-')[0]}__{args.algo}__{name}__{seed}"
            precision = {} if args.precision is None else {"precision": args.precision}
            config = preset_config(preset, task, args.algo, seed=seed, epochs=epochs, threads=1, **precision,
                                   **changes)  # fmt: skip
            if (run / "checkpoint.pt").exists():
                differing = setting_differences(run, config)
                if differing:
                    raise SystemExit(f"{run} holds a run with other settings ({', '.join(differing)}): "
                                     "remove it, or pass another --root")  # fmt: skip
                train(run_dir=run, resume=True, progress=False)
            else:
                train(config, run_dir=run, progress=False)
            if args.archive is not None:
                archive_run(run, args.archive)
            returns = [row["test/episodic_return"] for row in read_progress(run)]
            paper_rule.append(convergence_epoch(returns))
            absolute.append(convergence_epoch(returns, level=0.95))
            minutes.append(sum(row["time_s"] for row in read_progress(run)) / 60)

        def mean(values):
            reached = [v for v in values if v is not None]
            text = f"{np.mean(reached):.1f}" if reached else "-"
            return text + ("" if len(reached) == len(values) else f" ({len(reached)}/{len(values)} reached)")

        print(
            f"| {name} | {len(args.seeds)} | {mean(paper_rule)} | {mean(absolute)} | {np.mean(minutes):.1f} |"
        )


if __name__ == "__main__":
    main()
