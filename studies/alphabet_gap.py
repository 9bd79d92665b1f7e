"""Why the `paper` DQN learns the discrete alphabet more slowly here than in the paper: the runs that
separate the candidate causes, side by side with the preset's own rows and the original release's log.

Each GROUP is ``LABEL=GLOB`` (record or run folders of the DQN on the discrete alphabet). Per group it
prints each seed's first epoch at 95 % of its best test return (the paper's convergence rule) and at a
test return of 0.95, their means with a 95 % bootstrap interval, the mean test return over each ten
epochs and the typing after the last epoch (the paper's protocol); then the release's logged run of the
same agent. With ``--figure`` it draws the groups' mean test return per epoch (a five-epoch running
mean) beside the release's log. Without groups it reads the committed records of the study
(docs/notes/alphabet-gap.md). ``--offsets`` also generates the discrete tasks' dataset (``keys-train``)
again without the switch model's per-key travel offsets and counts the images they change.

    python studies/alphabet_gap.py [LABEL=GLOB ...] [--figure docs/images/alphabet_gap.png] [--offsets]
"""

from __future__ import annotations

import argparse
import glob
from pathlib import Path

import numpy as np

from tactile_braille.agents.report import convergence_epoch
from tactile_braille.evaluation.report import load_records, original_curves
from tactile_braille.evaluation.statistics import bootstrap_interval

ROOT = Path(__file__).resolve().parents[1]
TASK = "DiscreteAlphabet-v0"
COMMITTED = (
    f"`paper` preset=results/table3/paper/{TASK}__dqn__[0-2]",
    f"`released` preset=results/table3-v2/released/{TASK}__dqn__[0-2]",
    "`paper`, Adam epsilon 1e-8 and Huber loss=results/diagnostics/DA_paper_huber-eps8_*",
    "`paper`, one image per key=results/diagnostics/DA_paper_fixed-images_*",
)
"""The study's groups, as its notes read them (relative to the repository): seeds 0-2 of each."""


def parse_groups(items: list[str]) -> dict[str, list[Path]]:
    """``LABEL=GLOB`` items -> label: the folders the pattern matches (each group needs one)."""
    groups = {}
    for item in items:
        label, _, pattern = item.partition("=")
        if not label or not pattern:
            raise SystemExit(f"a group is LABEL=GLOB, got {item!r}")
        folders = sorted(Path(p) for p in glob.glob(pattern))
        if not folders:
            raise SystemExit(f"group {label!r}: no folder matches {pattern}")
        groups[label] = folders
    return groups


def interval_text(values: list[int | None]) -> str:
    reached = [v for v in values if v is not None]
    if not reached:
        return "never"
    low, high = bootstrap_interval(reached)
    text = f"{np.mean(reached):.1f} [{low:.1f}, {high:.1f}]"
    return text if len(reached) == len(values) else f"{text} ({len(reached)} of {len(values)} seeds)"


def describe(label: str, records) -> list[str]:
    paper = [convergence_epoch(list(r.returns)) for r in records]
    absolute = [convergence_epoch(list(r.returns), level=0.95) for r in records]
    seeds = ", ".join(f"{r.seed}: {p} / {a}" for r, p, a in zip(records, paper, absolute, strict=True))
    epochs = min(len(r.returns) for r in records)
    tens = [np.mean([r.returns[i : i + 10].mean() for r in records]) for i in range(0, epochs, 10)]
    lines = [
        f"{label} ({len(records)} seed{'s' if len(records) > 1 else ''}, {epochs} epochs)",
        f"  first 95 % of the best (the paper's rule): {interval_text(paper)}; first 0.95: "
        f"{interval_text(absolute)}",
        f"  per seed (95 % of best / 0.95): {seeds}",
        "  mean test return over each ten epochs: " + ", ".join(f"{v:.2f}" for v in tens),
    ]
    lengths = [len(r.returns) for r in records]
    if len(set(lengths)) > 1:  # a run stopped once its curve answered: its typing is its own
        lines.append("  epochs per seed (a shorter run was stopped): " + ", ".join(map(str, lengths)))
        lines += [f"  typing, seed {r.seed} after {len(r.returns)} epochs: {r.typing['accuracy']:.3f} in "
                  f"{r.typing['total_steps']:,} steps" for r in records if r.typing]  # fmt: skip
        return lines
    typed = [r.typing for r in records if r.typing]  # the paper's protocol: no reset between keys
    if typed:
        accuracy = [t["accuracy"] for t in typed]
        steps = [t["total_steps"] for t in typed]
        lines.append(f"  typing (paper's protocol): {np.mean(accuracy):.3f} in {np.mean(steps):,.0f} steps "
                     f"({len(typed)} seed{'s' if len(typed) > 1 else ''})")  # fmt: skip
    return lines


def release_log() -> tuple[np.ndarray, np.ndarray] | None:
    return original_curves().get(("sim", TASK, "dqn"))


def offsets_effect() -> list[str]:
    """What the per-key travel offsets change in the discrete world: ``keys-train`` collected again
    (same taps, same sensor noise) with a switch model without them, image by image."""
    import tempfile

    from tactile_braille.datasets.cache import _default_collection, default_dataset
    from tactile_braille.datasets.collector import collect
    from tactile_braille.datasets.store import load_dataset
    from tactile_braille.keyboard.switch import SwitchModel
    from tactile_braille.rigs.virtual import VirtualRig

    procedure, seed, _ = _default_collection("keys-train", "braille_331", 0)
    reference = default_dataset("keys-train", progress=False)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "no-offsets.h5"
        collect(
            VirtualRig(switch=SwitchModel(travel_offsets_mm=())), procedure, path, seed=seed, progress=False
        )
        without = load_dataset(path)
        labels = without.label_names()
        ours, theirs = reference.observations, without.observations
        changed = ~(ours == theirs).all(axis=(1, 2))
        lines = [f"without the per-key offsets, {int(changed.sum())} of {len(changed)} images of keys-train "
                 f"change"]  # fmt: skip
        for key in sorted(set(labels[changed])):
            taps = labels == key
            share = (ours[taps] != theirs[taps]).mean(axis=(1, 2))
            lines.append(f"  {key}: {int(changed[taps].sum())} of {int(taps.sum())} images, in at most "
                         f"{share.max():.2%} of their pixels")  # fmt: skip
    return lines


def plot(groups: dict[str, list], path: Path) -> Path:
    from tactile_braille._figures import new_figure, save_figure

    fig, axes = new_figure(1, 1, figsize=(7.5, 4.0))
    ax = axes[0, 0]
    for label, records in groups.items():
        epochs = min(len(r.returns) for r in records)
        mean = np.mean([r.returns[:epochs] for r in records], axis=0)
        smooth = np.convolve(mean, np.ones(5) / 5, mode="valid")
        ax.plot(
            np.arange(3, 3 + len(smooth)),
            smooth,
            lw=1.5,
            label=f"{label} ({len(records)} seed{'s' if len(records) > 1 else ''})",
        )
    log = release_log()
    if log is not None:
        epochs, returns = log
        smooth = np.convolve(returns, np.ones(5) / 5, mode="valid")
        ax.plot(epochs[2 : 2 + len(smooth)], smooth, color="black", ls=":", lw=1.5, label="the release's log")
    ax.axhline(0.95, color="grey", lw=0.6, ls="--")
    ax.set_xlabel("epoch (250 environment steps)")
    ax.set_ylabel("test return (five-epoch mean)")
    ax.set_title(f"{TASK}, the paper's DQN: mean over seeds", fontsize=9)
    ax.set_ylim(0, 1.02)
    ax.legend(fontsize=7, loc="lower right", frameon=False)
    fig.tight_layout()
    return save_figure(fig, path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("groups", nargs="*", metavar="LABEL=GLOB")
    parser.add_argument("--figure", type=Path, help="draw the groups' mean test return into this PNG")
    parser.add_argument("--offsets", action="store_true", help="count the images the per-key offsets change")
    args = parser.parse_args(argv)
    items = args.groups or [f"{label}={ROOT / pattern}" for label, _, pattern in
                            (item.partition("=") for item in COMMITTED)]  # fmt: skip
    groups = {label: load_records(folders, evaluate_missing=False) for label, folders in
              parse_groups(items).items()}  # fmt: skip
    for label, records in groups.items():
        print("\n".join(describe(label, records)))
    log = release_log()
    if log is not None:
        returns = list(log[1])
        tens = ", ".join(f"{np.mean(returns[i : i + 10]):.2f}" for i in range(0, len(returns), 10))
        print(
            f"the release's logged run: first 95 % of its best at epoch {convergence_epoch(returns)}, "
            f"first 0.95 at {convergence_epoch(returns, level=0.95)}; mean over each ten epochs: {tens}"
        )
    if args.figure is not None:
        print(f"wrote {plot(groups, args.figure)}")
    if args.offsets:
        print("\n".join(offsets_effect()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
