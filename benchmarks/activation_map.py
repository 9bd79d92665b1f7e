"""How well the switch model reproduces the real robot's activation maps.

For each map of the original release (alphabet grid, arrows grid) prints the
overall agreement (fraction of taps with the same outcome, NONE included) and
the agreement on the taps where the robot or the model actuated a key, beside
the never-press baseline; writes a PNG with the real and the modelled maps
side by side at each depth. Targets: >= 97 % overall and >= 85 % on actuated
taps for each map.

    python benchmarks/activation_map.py [--output outputs/activation_maps.png]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from tactile_braille.keyboard.calibration import (
    MAP_NAMES,
    agreement,
    load_activation_map,
    predict_activation_map,
)
from tactile_braille.keyboard.layout import NONE_KEY, key_set


def plot_maps(name: str, observed: np.ndarray, predicted: np.ndarray, activation_map, axes_row_pairs) -> None:
    keys = [NONE_KEY, *key_set(name)]
    code = {key: i for i, key in enumerate(keys)}
    xs, ys = np.unique(activation_map.x_mm), np.unique(activation_map.y_mm)
    depths = np.unique(activation_map.depth_mm)
    cmap = plt.get_cmap("tab20", len(keys))
    for column, depth in enumerate(depths):
        at_depth = activation_map.depth_mm == depth
        for row, (labels, what) in enumerate(((observed, "robot"), (predicted, "model"))):
            grid = np.full((len(xs), len(ys)), np.nan)
            rows = np.searchsorted(xs, activation_map.x_mm[at_depth])
            cols = np.searchsorted(ys, activation_map.y_mm[at_depth])
            grid[rows, cols] = [code[k] for k in labels[at_depth]]
            grid[grid == 0] = np.nan
            ax = axes_row_pairs[row][column]
            ax.axis("on")
            ax.imshow(grid, cmap=cmap, vmin=0, vmax=len(keys) - 1, interpolation="nearest", aspect="auto")
            ax.set_xticks([])
            ax.set_yticks([])
            if row == 0:
                ax.set_title(f"tap {depth - 2:g} mm", fontsize=7)
            if column == 0:
                ax.set_ylabel(f"{name}\n{what}", fontsize=7)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output", default="outputs/activation_maps.png")
    args = parser.parse_args()
    maps = {name: load_activation_map(name) for name in MAP_NAMES}
    depth_counts = [len(np.unique(m.depth_mm)) for m in maps.values()]
    fig, axes = plt.subplots(4, max(depth_counts), figsize=(1.3 * max(depth_counts), 6.5), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for index, (name, activation_map) in enumerate(maps.items()):
        predicted = predict_activation_map(activation_map)
        result = agreement(activation_map.pressed, predicted)
        never = agreement(activation_map.pressed, np.full(len(activation_map), NONE_KEY))
        print(
            f"{name:8s} overall agreement {result.overall:6.1%} "
            f"(never-press {never.overall:5.1%}, target 97%)"
        )
        print(
            f"{name:8s} actuated-tap agreement {result.actuated:6.1%} "
            f"(never-press {never.actuated:5.1%}, target 85%)  [{result.taps} taps]"
        )
        plot_maps(name, activation_map.pressed, predicted, activation_map, axes[2 * index : 2 * index + 2])
    fig.suptitle("Activation maps: real robot (rows 1, 3) vs switch model (rows 2, 4); colour = key")
    fig.tight_layout()
    output = Path(args.output)
    output.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(output, dpi=110)
    print(f"wrote {output}")


if __name__ == "__main__":
    main()
