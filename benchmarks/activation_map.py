"""How well the switch model reproduces the real robot's activation maps.

For each map of the original release (alphabet grid, arrows grid) prints the
overall agreement (fraction of taps with the same outcome, NONE included) and
the agreement on the taps where the robot or the model actuated a key, beside
the never-press baseline; for a map whose keys carry fitted travel offsets,
also the same figures with offsets fitted on half the map's taps and scored
on the other half (two-fold cross-validation); writes a PNG with the real and the modelled maps
side by side at each depth. Targets: >= 97 % overall and >= 85 % on actuated
taps for each map.

    python benchmarks/activation_map.py [--output outputs/activation_maps.png]
"""

from __future__ import annotations

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from tactile_braille.gallery import draw_activation_map, save_figure
from tactile_braille.keyboard.calibration import (
    MAP_NAMES,
    RIG_TAP_OFFSET_MM,
    agreement,
    held_out_agreement,
    load_activation_map,
    predict_activation_map,
)
from tactile_braille.keyboard.layout import NONE_KEY, key_set
from tactile_braille.keyboard.switch import SwitchModel


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
        offset_keys = {key for key, _ in SwitchModel().travel_offsets_mm}
        if offset_keys & set(key_set(name)):
            held_out = held_out_agreement(activation_map)
            print(
                f"{name:8s} held-out agreement, per-key offsets fitted on the other half: "
                f"{held_out.overall:6.1%} overall, {held_out.actuated:6.1%} actuated"
            )
        for row, (labels, what) in enumerate(((activation_map.pressed, "robot"), (predicted, "model"))):
            draw_activation_map(
                axes[2 * index + row],
                activation_map.x_mm,
                activation_map.y_mm,
                activation_map.depth_mm - RIG_TAP_OFFSET_MM,
                labels,
                key_set(name),
                f"{name}\n{what}",
            )
    fig.suptitle(
        "Activation maps: real robot (rows 1, 3) vs switch model (rows 2, 4); colour = key; "
        "depth = recorded tap depth"
    )
    fig.tight_layout()
    print(f"wrote {save_figure(fig, args.output)}")


if __name__ == "__main__":
    main()
