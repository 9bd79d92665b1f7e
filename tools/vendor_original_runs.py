"""Vendor the learning curves of the original release's runs into the package (run once).

Reads the ``progress.txt`` logs of ``braille_rl`` (Church et al., MIT licence)
under ``reference/braille_rl_2020/algos/saved_models/{sim,robot}/...`` and
writes ``src/tactile_braille/evaluation/reference/original_runs.csv`` with one
row per logged epoch: platform, task, algo, epoch, env_steps, train and test
returns. The reports overlay these curves on ours.

    python tools/vendor_original_runs.py ../shared/reference/braille_rl_2020
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

TASKS = {
    ("discrete", "arrows"): "DiscreteArrows-v0",
    ("discrete", "alphabet"): "DiscreteAlphabet-v0",
    ("continuous", "arrows"): "ContinuousArrows-v0",
    ("continuous", "alphabet"): "ContinuousAlphabet-v0",
}
ALGOS = {"dd_dqn": "dqn", "disc_sac": "sac_discrete", "cont_sac": "sac", "td3": "td3"}
OUTPUT = Path(__file__).resolve().parents[1] / "src/tactile_braille/evaluation/reference/original_runs.csv"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("release", type=Path, help="the braille_rl_2020 reference folder")
    args = parser.parse_args()
    rows = []
    for log in sorted((args.release / "algos/saved_models").glob("*/*/*/*/*/progress.txt")):
        platform, kind, keys, algo = log.relative_to(args.release / "algos/saved_models").parts[:4]
        with open(log, newline="") as handle:
            for record in csv.DictReader(handle, delimiter="\t"):
                rows.append({
                    "platform": platform, "task": TASKS[(kind, keys)], "algo": ALGOS[algo],
                    "epoch": int(record["Epoch"]) - 1,  # the original counts from 1; ours from 0
                    "env_steps": int(float(record["TotalEnvInteracts"])),
                    "train_return": float(record["AverageEpRet"]),
                    "test_return": float(record["AverageTestEpRet"]),
                })  # fmt: skip
    OUTPUT.parent.mkdir(parents=True, exist_ok=True)
    with open(OUTPUT, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    runs = len({(r["platform"], r["task"], r["algo"]) for r in rows})
    print(f"wrote {len(rows)} epochs of {runs} runs to {OUTPUT}")


if __name__ == "__main__":
    main()
