"""Do two training runs log the same epochs? Every column of progress.csv but the timings, exactly (a
column one log lacks reads as blank: logs name only the losses their agent returned).

A refactor of the training code must not change what a run learns: run the
same command before and after it (``--threads 1``) and compare. Exits 1 when a
pair differs, printing the first differing cells.

    python tools/compare_progress.py runs/before/fast_DA_0 runs/after/fast_DA_0 [RUN_A RUN_B ...]
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

TIMINGS = ("charts/SPS", "time_s")


def differences(run_a: Path, run_b: Path) -> list[str]:
    """``epoch N column: a != b`` for each differing cell (timings aside), and a differing epoch count."""
    logs = []
    for run in (run_a, run_b):
        with open(run / "progress.csv", newline="") as handle:
            logs.append(list(csv.DictReader(handle)))
    found = [f"epochs: {len(logs[0])} != {len(logs[1])}"] if len(logs[0]) != len(logs[1]) else []
    for row_a, row_b in zip(*logs, strict=False):
        columns = dict.fromkeys([*row_a, *row_b])  # a column one log lacks reads as blank
        found += [
            f"epoch {row_a['epoch']} {column}: {row_a.get(column, '')} != {row_b.get(column, '')}"
            for column in columns
            if column not in TIMINGS and row_a.get(column, "") != row_b.get(column, "")
        ]
    return found


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("runs", nargs="+", type=Path, help="pairs of run folders")
    args = parser.parse_args()
    if len(args.runs) % 2:
        parser.error("give run folders in pairs")
    failed = False
    for run_a, run_b in zip(args.runs[::2], args.runs[1::2], strict=True):
        found = differences(run_a, run_b)
        failed |= bool(found)
        print(f"{run_a} vs {run_b}: " + ("identical" if not found else "; ".join(found[:3])))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
