"""The fewest typing steps each task allows, beside a pose-aware script, the touch-only optimum and the
paper's Table III.

For each task and each typing protocol (the paper's text: no reset between
keys; the released code: a reset per key), on the dataset backend:

* **bound**: :func:`tactile_braille.evaluation.bounds.typing_bound`, the
  fewest steps any policy can type the paper's sequences in, even one that
  knows the sensor's pose and the key layout. With no reset it is for the
  start poses of the typing evaluation's seed (0 unless --seeds); with a reset
  per key too on the continuous tasks, and the expectation over random starts
  on the discrete ones.
* **bound, presses 1 mm inside** (continuous tasks): the same bound when every
  press must land at least :data:`MARGIN_MM` inside its key's press region
  (``typing_bound(..., margin_mm=...)``): the bound above presses on the
  regions' very edges, which no policy that knows its pose only to within a
  millimetre (from touch, or on a rig) can count on.
* **key-by-key typist** (continuous tasks): ``KeyByKeyTypist``, which knows
  the pose and the press regions but not the next key, and presses
  :data:`MARGIN_MM` inside at the place that minimises its steps and the mean
  steps on to another key: what a policy typing key by key with a margin can
  reach (a yardstick, measured by typing).
* **pose script**: ``PoseScript`` (tactile_braille.envs.oracle), which goes
  straight for the goal key's centre and presses on the step that lands there.
* **touch-only optimum** (discrete tasks): the fewest steps expected of a
  policy that knows only what it has felt (``touch_optimum``; a lower bound
  with no reset).

With ``--runs RECORD ...`` (run folders or archived records with a
``typing.json``) it adds their mean steps per task, and ``--figure PNG`` draws
everything as bars, steps relative to the bound.

Run: python benchmarks/typing_bounds.py [--seeds 1] [--runs results/fast/*]
        [--figure docs/images/typing_bounds.png]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import gymnasium as gym
import numpy as np

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.envs.oracle import PoseScript
from tactile_braille.evaluation.bounds import KeyByKeyTypist, typing_bound
from tactile_braille.evaluation.protocol import paper_sequences, type_sequences
from tactile_braille.evaluation.report import PAPER_TABLE
from tactile_braille.evaluation.scoring import touch_optimum

TASKS = ("DiscreteArrows-v0", "DiscreteAlphabet-v0", "ContinuousArrows-v0", "ContinuousAlphabet-v0")
MARGIN_MM = 1.0
"""How far inside its press region each press lands in the bound with a margin."""


def _cell(values: list[float]) -> str:
    low, high = min(values), max(values)
    return f"{low:.0f}" if round(low) == round(high) else f"{np.mean(values):.0f} ({low:.0f}-{high:.0f})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=1, help="typing seeds (start poses) per protocol")
    parser.add_argument("--runs", nargs="*", type=Path, default=[], help="run folders or records to add")
    parser.add_argument("--figure", type=Path, default=None, help="write the bars to this PNG")
    args = parser.parse_args()
    runs: dict[str, dict[str, list[int]]] = {}  # task -> protocol -> steps of the runs
    for run in args.runs:
        typing = json.loads((run / "typing.json").read_text())
        for protocol, typed in (("paper", typing), ("released", typing.get("released_protocol"))):
            if typed is not None:
                runs.setdefault(typing["task"].split("/")[-1], {}).setdefault(protocol, []).append(
                    typed["total_steps"]
                )
    bars: dict[str, dict[str, float]] = {}
    print(f"| task | bound, no reset | bound, presses {MARGIN_MM:g} mm inside, no reset "
          f"| key-by-key typist, {MARGIN_MM:g} mm inside, no reset | pose script, no reset "
          "| touch-only, no reset (>=) "
          "| bound, reset per key (discrete: expected) | pose script, reset per key "
          "| paper's Table III steps |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|")
    for task in TASKS:
        env = gym.make(f"tactile_braille/{task}")
        keys = env.unwrapped.task.keys
        sequences = paper_sequences(keys)
        script = PoseScript(env)
        cells = []
        for protocol in ("paper", "released"):
            seeds = range(args.seeds)
            bounds = [typing_bound(task, sequences, protocol, seed) for seed in seeds]
            steps = [type_sequences(script, env, sequences, seed, protocol).total_steps for seed in seeds]
            cells += [_cell(bounds), _cell(steps)]
            continuous = env.unwrapped.task.continuous
            if protocol == "paper" and not continuous:
                cells[-1:-1] = ["-", "-"]
            elif protocol == "paper":
                margins = [
                    typing_bound(task, sequences, protocol, seed, margin_mm=MARGIN_MM) for seed in seeds
                ]
                typist = KeyByKeyTypist(env, MARGIN_MM)
                typed = [type_sequences(typist, env, sequences, seed, protocol).total_steps for seed in seeds]
                cells[-1:-1] = [_cell(margins), _cell(typed)]
                bars.setdefault(task, {}).update({"bound margin": np.mean(margins), "typist": np.mean(typed)})
            ran = runs.get(task, {}).get(protocol)
            if ran:
                cells[-1] += f"; runs {_cell(ran)}"
            here = bars.setdefault(task, {})
            here.update({f"bound {protocol}": np.mean(bounds), f"script {protocol}": np.mean(steps)})
            if ran:
                here[f"runs {protocol}"] = np.mean(ran)
            if protocol == "paper":
                cells.append("-" if continuous else f"{touch_optimum(keys, sequences, 'paper'):.0f}")
        paper = ", ".join(f"{v[0]} ({algo})" for (platform, t, algo), v in PAPER_TABLE.items()
                          if platform == "sim" and t == task)  # fmt: skip
        print(f"| {task} | " + " | ".join(cells) + f" | {paper} |")
        bars[task]["paper"] = min(
            v[0] for (platform, t, _), v in PAPER_TABLE.items() if platform == "sim" and t == task
        )
    if args.figure:
        print(f"wrote {draw(bars, args.figure)}")


def draw(bars: dict[str, dict[str, float]], path: Path) -> Path:
    """Steps relative to each task's bound (no reset), as grouped bars."""
    from tactile_braille._figures import new_figure, save_figure

    series = [("bound margin", f"bound, presses {MARGIN_MM:g} mm inside, no reset"),
              ("typist", f"key-by-key typist, {MARGIN_MM:g} mm inside, no reset"),
              ("script paper", "pose script, no reset"), ("runs paper", "runs, no reset"),
              ("bound released", "bound, reset per key"),
              ("script released", "pose script, reset per key"), ("runs released", "runs, reset per key"),
              ("paper", "paper's Table III (best)")]  # fmt: skip
    series = [(key, label) for key, label in series if any(key in b for b in bars.values())]
    fig, axes = new_figure(figsize=(9, 3.8))
    ax = axes[0, 0]
    width = 0.8 / len(series)
    for i, (key, label) in enumerate(series):
        ratios = [bars[t].get(key, np.nan) / bars[t]["bound paper"] for t in bars]
        ax.bar(np.arange(len(bars)) + (i - (len(series) - 1) / 2) * width, ratios, width, label=label)
    ax.axhline(1.0, color="black", linewidth=1, label="bound, no reset (= 1)")
    ax.set_xticks(range(len(bars)), [t.removesuffix("-v0") for t in bars])
    ax.set_ylabel("typing steps / bound (no reset)")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    return save_figure(fig, path)


if __name__ == "__main__":
    main()
