"""Short runs of every preset, task and agent: the check that a refactor left training unchanged.

Each run is a few hundred steps of the preset's own settings, one torch thread,
fp32, written under ``ROOT/{preset}__{task}__{algo}``. Run it before and after
a change into two roots, then compare the logs:

    python tools/preset_runs.py runs/before
    python tools/preset_runs.py runs/after
    python tools/compare_progress.py runs/before/X runs/after/X ...   (or --compare ROOT_A ROOT_B)

Runs whose folder exists in ROOT are left to whoever made them, so that two sweeps
(``--only``) can share a root; delete the folder of a run that was killed.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from tactile_braille._registration import ENV_IDS as TASKS
from tactile_braille.agents.presets import PRESETS, preset_config
from tactile_braille.agents.registry import agent_names

SHORT = ["--epochs", "2", "--steps-per-epoch", "150", "--test-episodes", "3",
         "--threads", "1", "--precision", "fp32", "--quiet"]  # fmt: skip
"""What every run shares: two short epochs on one thread."""


def combinations() -> list[tuple[str, str, str]]:
    """Every (preset, task, algo) a preset makes settings for."""
    found = []
    for preset in PRESETS:
        for task in TASKS:
            for algo in agent_names():
                try:
                    preset_config(preset, task, algo)
                except ValueError:
                    continue
                found.append((preset, task, algo))
    return found


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("root", type=Path, help="folder of the runs")
    parser.add_argument("--compare", type=Path, help="a second root: compare its runs with ROOT's")
    parser.add_argument("--only", help="run only the combinations whose folder name contains this")
    args = parser.parse_args()
    names = []
    for preset, task, algo in combinations():
        name = f"{preset}__{task.split('/')[-1]}__{algo}"
        if args.only and args.only not in name:
            continue
        names.append(name)
        run = args.root / name
        if args.compare is None and not run.exists():  # another sweep on ROOT may be running it
            # Touch encoders and the replay fill from the random start steps: keep them short but present.
            start = [] if algo == "planner" else ["--start-steps", "100"]
            command = [sys.executable, "-m", "tactile_braille.cli", "train", task, algo, "--preset", preset,
                       *SHORT, *start, "--run-dir", str(run)]  # fmt: skip
            print(name, flush=True)
            subprocess.run(command, check=True)
    if args.compare is None:
        return 0
    pairs = [str(root / name) for name in names for root in (args.root, args.compare)]
    return subprocess.run(
        [sys.executable, str(Path(__file__).with_name("compare_progress.py")), *pairs]
    ).returncode


if __name__ == "__main__":
    sys.exit(main())
