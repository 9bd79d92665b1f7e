"""How well the switch model reproduces the real robot's activation maps.

For each map of the original release (alphabet grid, arrows grid) prints the
overall agreement (fraction of taps with the same outcome, NONE included) and
the agreement on the taps where the robot or the model actuated a key, beside
the never-press baseline. For a map whose keys carry fitted travel offsets,
it also prints the same figures with offsets fitted on half the map's taps
and scored on the other half (two-fold cross-validation), and how much of the
offsets a plane over the key positions explains (little: they are per-switch
scatter, not a tilted work frame). Writes a PNG with the real and the
modelled maps side by side at each depth, and one of the offsets on the
keyboard. Targets: >= 97 % overall and >= 85 % on actuated taps for each map.

    python benchmarks/activation_map.py [--output outputs/activation_maps.png]
        [--offsets-output outputs/travel_offsets.png]
"""

from __future__ import annotations

import argparse

import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.patches import Rectangle

from tactile_braille._figures import colormap, new_figure, save_figure
from tactile_braille.gallery import draw_activation_map
from tactile_braille.keyboard.calibration import (
    MAP_NAMES,
    RIG_TAP_OFFSET_MM,
    agreement,
    held_out_agreement,
    load_activation_map,
    predict_activation_map,
)
from tactile_braille.keyboard.layout import NONE_KEY, KeyboardLayout, key_set
from tactile_braille.keyboard.switch import SWITCH_TOLERANCE_MM, SwitchModel


def plot_offsets(switch: SwitchModel, path: str) -> None:
    """The alphabet keys on the keyboard, coloured by their travel offset."""
    layout = KeyboardLayout()
    offsets = dict(switch.travel_offsets_mm)
    fig, axes = new_figure(figsize=(7.5, 2.9))
    ax = axes[0, 0]
    cmap = colormap("coolwarm")
    for name in key_set("alphabet"):
        key = layout.key(name)
        width = key.width_u * layout.pitch_mm
        value = offsets.get(name, 0.0)
        # The keyboard frame's y grows to the typist's left: draw -y to the right.
        ax.add_patch(Rectangle(
            (-key.centre_y_mm - width / 2 + 0.5, -key.centre_x_mm - layout.pitch_mm / 2 + 0.5),
            width - 1, layout.pitch_mm - 1,
            color=cmap(0.5 + value / (2 * SWITCH_TOLERANCE_MM)), ec="black",
        ))  # fmt: skip
        ax.text(-key.centre_y_mm, -key.centre_x_mm + 3, name, ha="center", va="center", fontsize=8)
        ax.text(-key.centre_y_mm, -key.centre_x_mm - 4, f"{value:+.2f}", ha="center", va="center", fontsize=7)
    ax.set_xlim(-20, 200)
    ax.set_ylim(-70, 12)
    ax.set_aspect("equal")
    ax.axis("off")
    mappable = ScalarMappable(cmap=cmap, norm=Normalize(-SWITCH_TOLERANCE_MM, SWITCH_TOLERANCE_MM))
    fig.colorbar(mappable, ax=ax, fraction=0.03, label="mm earlier")
    ax.set_title(
        "Fitted switch travel offsets (mm; + registers earlier). Tolerance of an MX switch: +/- 0.6 mm",
        fontsize=9,
    )
    fig.tight_layout()
    print(f"wrote {save_figure(fig, path)}")


def offset_trend_r2(switch: SwitchModel, keys: tuple[str, ...]) -> float:
    """Share of the offsets' variance that a plane over the key centres explains."""
    layout = KeyboardLayout()
    offsets = dict(switch.travel_offsets_mm)
    keys = tuple(k for k in keys if layout.key(k).width_u == 1)  # SPACE's centre says little of its switch
    values = np.array([offsets.get(k, 0.0) for k in keys])
    design = np.c_[np.ones(len(keys)), [layout.centre_mm(k) for k in keys]]
    fitted = design @ np.linalg.lstsq(design, values, rcond=None)[0]
    return float(1 - ((values - fitted) ** 2).sum() / ((values - values.mean()) ** 2).sum())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output", default="outputs/activation_maps.png")
    parser.add_argument("--offsets-output", default="outputs/travel_offsets.png")
    args = parser.parse_args()
    maps = {name: load_activation_map(name) for name in MAP_NAMES}
    switch = SwitchModel()
    offset_keys = {key for key, _ in switch.travel_offsets_mm}
    depth_counts = [len(np.unique(m.depth_mm)) for m in maps.values()]
    fig, axes = new_figure(4, max(depth_counts), figsize=(1.3 * max(depth_counts), 6.5))
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
        if offset_keys & set(key_set(name)):
            held_out = held_out_agreement(activation_map)
            print(
                f"{name:8s} held-out agreement, per-key offsets fitted on the other half: "
                f"{held_out.overall:6.1%} overall, {held_out.actuated:6.1%} actuated"
            )
            print(
                f"{name:8s} travel offsets: a plane over the key centres explains "
                f"R^2 = {offset_trend_r2(switch, key_set(name)):.3f} of them"
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
    plot_offsets(switch, args.offsets_output)


if __name__ == "__main__":
    main()
