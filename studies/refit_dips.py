"""What a touch encoder's refits do to the test return of a run.

For each run, compares the change of the test return over the epochs in which
the encoder was refitted with the change over the other epochs (after the
start steps). A learner on the encoder's latent features loses ground at a
refit, whose new weights give the features new meanings; a learner on its
readout (``touch_inputs="readout"``) does not.

    python studies/refit_dips.py runs/fast/ContinuousAlphabet__sac__* runs/ablation/ContinuousAlphabet__*
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from tactile_braille.agents.config import TrainConfig
from tactile_braille.agents.extensions import touch_fit_steps
from tactile_braille.agents.run import read_progress


def refit_changes(run: Path, config: TrainConfig) -> tuple[list[float], list[float]] | None:
    """Test-return changes over the refit epochs and over the other epochs, or None without refits."""
    if not config.touch.enabled:
        return None
    returns = [row["test/episodic_return"] for row in read_progress(run)]
    # The test after epoch i (0-based) follows step (i + 1) * steps_per_epoch; a fit after step s
    # (1-based) falls in epoch (s - 1) // steps_per_epoch, before its test. The changes start from the
    # epoch after the first fit's.
    first, *refits = touch_fit_steps(config)
    refit_epochs = {(s - 1) // config.steps_per_epoch for s in refits}
    start = (first - 1) // config.steps_per_epoch + 2
    at_refits = [returns[i] - returns[i - 1] for i in range(start, len(returns)) if i in refit_epochs]
    others = [returns[i] - returns[i - 1] for i in range(start, len(returns)) if i not in refit_epochs]
    return (at_refits, others) if at_refits and others else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    args = parser.parse_args()
    print("| run | inputs | refits | mean change at a refit | drops | mean change otherwise |")
    print("|---|---|---|---|---|---|")
    for run in args.runs:
        config = TrainConfig.from_json(json.loads((run / "config.json").read_text()))
        changes = refit_changes(run, config)
        if changes is None:
            continue
        at_refits, others = changes
        print(
            f"| {run.name} | {config.touch.inputs} | {len(at_refits)} | {np.mean(at_refits):+.3f} | "
            f"{sum(change < 0 for change in at_refits)} | {np.mean(others):+.3f} |"
        )


if __name__ == "__main__":
    main()
