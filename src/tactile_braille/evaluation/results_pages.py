"""The repository's results pages: ``make results`` writes them from the records committed under results/.

:func:`write_results_pages` reads the runs' records (:func:`~tactile_braille.evaluation.report.load_records`),
splits their groups into a preset's own rows (:func:`split_groups`) and the rest, and writes four pages
side by side, each linking the others near its top:

- the headline (``docs/results.md``): the curves by task over the original release's logs, typing steps
  per key against the typing bound, the presets' curves seed by seed, then one row per preset, task and
  agent in a table per track and preset beside the paper's Table III, its coverage, the notes (a reading
  of the tables), and the sections on transfer and warm starts;
- ``results-ablations.md``: the rows whose settings depart from a preset, or that were run as ablations,
  grouped by the preset they depart from, each naming what differs, beside the preset's own row;
- ``results-runs.md``: each group's runs and typing confusion, and the transfer and warm-start runs;
- ``results-tuning.md``: the records of a tuning folder (the seeds settings were chosen on) and of a
  diagnostics folder (runs that tested a cause), a row each, with the diagnostics' READMEs.

A user's own runs get one page of every row from :func:`~tactile_braille.evaluation.report.write_report`
(``tactile-braille report RUN... --output DIR``). Run as ``python -m
tactile_braille.evaluation.results_pages`` (the Makefile's ``results`` target).
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from tactile_braille._io import atomic_path
from tactile_braille.agents.presets import PRESET_TRACKS, PRESETS, preset_config
from tactile_braille.agents.registry import agent_label, agent_names
from tactile_braille.evaluation.report import (
    PAPER_COLUMNS,
    PAPER_TABLE,
    TASK_NAMES,
    TRACK_TITLES,
    TYPING_COLUMNS,
    RunRecord,
    by_task_section,
    coverage_section,
    first_095_text,
    group,
    group_sections,
    linked_figures,
    load_records,
    markdown_table,
    original_curves,
    panels_with_legends,
    paper_cells,
    profiles_section,
    run_bound,
    run_list,
    seed_curves,
    transfer_section,
    typing_cells,
    warm_start_section,
)
from tactile_braille.evaluation.statistics import bootstrap_interval

Groups = dict[tuple[str, str, str], list[RunRecord]]

PRESET_ORDER = tuple(
    sorted(PRESETS, key=lambda p: (list(TRACK_TITLES).index(PRESET_TRACKS[p]), PRESETS.index(p)))
)
"""The presets in the order of the headline's tables: the ``tactile`` track's, then ``proprio``'s."""
PRESET_TITLES = {
    "paper": "`paper`: the paper's settings (its Table II; the released code's values where it is silent)",
    "released": "`released`: the released code's settings",
    "fast-tactile": "`fast-tactile`: ours, from touch alone",
    "fast": "`fast`: ours, with the arm's pose and the key layout",
}
"""Each preset's heading on the headline page."""
PRESET_COLOURS = {preset: f"C{index}" for index, preset in enumerate(PRESET_ORDER)}
"""Each preset's colour in the figures, in the order of the tables."""
PAGES = {
    "ablations": "Variants and ablations: rows that depart from a preset",
    "runs": "Run by run: each row's runs and typing",
    "tuning": "Tuning and diagnostics: records outside the results tables",
}
"""The companion pages (``{stem}-{name}.md`` beside the headline page ``{stem}.md``) and their titles."""
SEE_ALSO = (("the research account", "notes/results-account.md"), ("the notes", "notes/index.md"))
"""Hand-written pages beside the results pages that their links name, where they exist."""


def _preset_index(preset: str) -> tuple[int, str]:
    """A preset's place in :data:`PRESET_ORDER` (others after, by name): a sort key."""
    return (PRESET_ORDER.index(preset) if preset in PRESET_ORDER else len(PRESET_ORDER), preset)


def preset_of(variant: str) -> str:
    """The preset (or ``custom``) a group's variant starts with: ``paper`` for ``paper, bf16, ...``."""
    return variant.partition(", ")[0]


def departure_text(variant: str) -> str:
    """What a group's variant names beyond its preset and precision (``replay.relabel=all``), else ``""``."""
    parts = variant.split(", ", 2)
    return parts[2] if len(parts) > 2 else ""


AS_ABLATION = "run as an ablation"
"""What an ablation's group names where its settings are its preset's own (it is not that preset's row)."""


def is_presets_own(variant: str) -> bool:
    """Whether a group's variant names a preset and its precision alone (``paper, bf16``): no departure,
    no other world, backend, grid or warm start."""
    return preset_of(variant) in PRESETS and ", " in variant and not departure_text(variant)


def split_groups(records: list[RunRecord], ablations: list[RunRecord] = ()) -> tuple[Groups, Groups]:
    """(The groups of ``records`` run with a preset's own settings, the others with ``ablations``'s), each
    in the paper's order (:func:`~tactile_braille.evaluation.report.group`). A departing group is named
    after its epochs too where those are not its preset's (``fast-tactile, fp32, agent.x=1, 100
    epochs``), so that the same settings trained for other lengths are two groups. An ablation's runs
    are never a preset's own row: where their settings are the preset's, their group is named
    :data:`AS_ABLATION` (``fast-tactile, fp32, 60 epochs, run as an ablation``: the ablation is then
    the training's length)."""
    own = group([r for r in records if is_presets_own(r.variant)])

    def named(record: RunRecord) -> str:
        own_settings = f", {AS_ABLATION}" if is_presets_own(record.variant) else ""
        return f"{record.variant}{_other_epochs(record)}{own_settings}"

    departed = group([r for r in records if not is_presets_own(r.variant)] + list(ablations), variant=named)
    return own, dict(sorted(departed.items(), key=lambda item: (_task_index(item[0][0]), *item[0][1:])))


def _other_epochs(record: RunRecord) -> str:
    """``", 60 epochs"`` where a preset's run was set to train other epochs than its preset's, else ``""``
    (also for a run of no preset)."""
    config = record.config
    if config is None or config.preset not in PRESETS:
        return ""
    preset = preset_config(config.preset, config.task, config.algo)
    return "" if config.epochs == preset.epochs else f", {config.epochs} epochs"


def merged(own: Groups, departed: Groups) -> Groups:
    """Both kinds of groups in one, in the paper's order of tasks (then agents and variants)."""
    return dict(sorted({**own, **departed}.items(), key=lambda item: (_task_index(item[0][0]), *item[0][1:])))


def _folders(records: list[RunRecord]) -> str:
    """The folders that hold a group's records, in code: `` `results/table3/paper/` ``."""
    return ", ".join(f"`{folder}/`" for folder in sorted({Path(r.path).parent.as_posix() for r in records}))


def _precisions(groups: Groups) -> list[str]:
    return sorted({key[2].split(", ")[1] for key in groups if ", " in key[2]})


def headline_tables(groups: Groups) -> list[str]:
    """Lines: a heading per track, and under it a heading, its records' folders and a table per preset
    (a row per task and agent, the paper's Table III beside it)."""
    tracks: dict[str, dict[str, Groups]] = {}
    for key, records in groups.items():
        tracks.setdefault(records[0].track, {}).setdefault(preset_of(key[2]), {})[key] = records
    lines = []
    for track in sorted(tracks, key=lambda t: (list(TRACK_TITLES).index(t) if t in TRACK_TITLES else 99, t)):
        lines += [f"## {TRACK_TITLES.get(track, track)}", ""]
        for preset in sorted(tracks[track], key=_preset_index):
            members = tracks[track][preset]
            precisions = _precisions(members)
            rows = [
                [TASK_NAMES.get(task, task), agent_label(algo) + (f" ({variant.split(', ')[1]})"
                 if len(precisions) > 1 else ""), str(len(records)), *typing_cells(records),
                 *paper_cells(task, algo)]
                for (task, algo, variant), records in members.items()
            ]  # fmt: skip
            folders = _folders([r for records in members.values() for r in records])
            lines += [
                f"### {PRESET_TITLES.get(preset, f'`{preset}`')}", "",
                f"Precision {' and '.join(precisions)}; records in {folders}.", "",
                markdown_table(("task", "agent", "seeds", *TYPING_COLUMNS, *PAPER_COLUMNS), rows), "",
            ]  # fmt: skip
    return lines


def ablation_tables(departed: Groups, own: Groups) -> list[str]:
    """Lines: a heading and a table per preset departed from; each task and agent's rows follow the
    preset's own row (from ``own``), each naming what differs, with its records' folders."""
    presets: dict[str, Groups] = {}
    for key, records in departed.items():
        presets.setdefault(preset_of(key[2]), {})[key] = records
    header = ("task", "agent", "what differs", "seeds", *TYPING_COLUMNS, *PAPER_COLUMNS, "records")
    lines = []
    for preset in sorted(presets, key=_preset_index):
        rows, shown = [], set()
        for (task, algo, variant), records in presets[preset].items():
            for key, reference in own.items():
                if (key[0], key[1], preset_of(key[2])) == (task, algo, preset) and key not in shown:
                    shown.add(key)
                    rows.append(_ablation_row(key, reference, "none: the preset's own row"))
            rows.append(_ablation_row((task, algo, variant), records, departure_text(variant) or "-"))
        tracks = sorted({r.track for records in presets[preset].values() for r in records})
        title = "Runs of no preset" if preset not in PRESETS else f"Departures from `{preset}`"
        lines += [
            f"## {title} (track {', '.join(f'`{t}`' for t in tracks)})",
            "",
            markdown_table(header, rows),
            "",
        ]
    return lines


def _ablation_row(key: tuple[str, str, str], records: list[RunRecord], differs: str) -> list[str]:
    task, algo, variant = key
    precision = variant.split(", ")[1] if ", " in variant else ""
    return [TASK_NAMES.get(task, task), agent_label(algo) + (f" ({precision})" if precision else ""), differs,
            str(len(records)), *typing_cells(records), *paper_cells(task, algo),
            _folders(records)]  # fmt: skip


def record_table(records: list[RunRecord], root: Path) -> str:
    """A row per record: its folder (under ``root``), task, agent, settings, seed, epochs, first epoch at
    0.95, best test return, typing under both protocols and the device it ran on."""
    rows = []
    for r in records:
        typing = r.typing or {}
        reset = typing.get("released_protocol")
        rows.append([
            f"`{Path(r.path).relative_to(root).as_posix()}`", TASK_NAMES.get(r.task, r.task),
            agent_label(r.algo), r.variant or "-", r.track, str(r.seed), str(len(r.returns)),
            "-" if r.reached_095 is None else str(r.reached_095),
            f"{np.max(r.returns):.2f}" if len(r.returns) else "-",
            f"{typing['accuracy']:.3f} in {typing['total_steps']}" if typing else "-",
            f"{reset['accuracy']:.3f} in {reset['total_steps']}" if reset else "-",
            r.config.device if r.config is not None else "?",
        ])  # fmt: skip
    header = ("record", "task", "agent", "settings", "track", "seed", "epochs", "first epoch >= 0.95",
              "best test return", "typing (steps)", "reset per key (steps)", "device")  # fmt: skip
    return markdown_table(header, rows)


def _records_in(folder: Path) -> list[Path]:
    """The run records (folders with a ``config.json``) in ``folder`` and one level below, sorted."""
    return sorted({p.parent for p in [*folder.glob("*/config.json"), *folder.glob("*/*/config.json")]})


def _readme_title(readme: Path) -> str:
    for line in readme.read_text().splitlines():
        if line.startswith("# "):
            return line[2:].strip()
    return readme.parent.name


def _relative_link(target: Path, page: Path) -> str:
    return Path(os.path.relpath(target, page.parent)).as_posix()


def tuning_lines(tuning: Path | None, diagnostics: Path | None, page: Path, account: str | None) -> list[str]:
    """The tuning and diagnostics page's sections: a table of the tuning folder's records; the
    diagnostics folder's single records in a table, then each study folder (one with its own README or
    records) under its README's title, with a link to the README, its other files and its records."""
    lines: list[str] = []
    reading = f" [The research account]({account}) reads them." if account else ""
    if tuning is not None:
        records = load_records(_records_in(tuning), evaluate_missing=False)
        seeds = ", ".join(map(str, sorted({r.seed for r in records}))) or "none yet"
        lines += [
            f"## Tuning: the seeds settings were chosen on (`{tuning.as_posix()}/`)", "",
            f"The presets' settings and the recipes on the other pages were chosen on these runs (seeds "
            f"{seeds}); no results table reports them: its rows are fresh seeds. A row per record: its "
            "settings as they depart from the preset as it is today (a run made before a preset changed "
            "departs from it in what the change added), the first epoch whose test return reached 0.95 "
            "(none: '-'), and its typing (accuracy in steps) without and with a reset per key." + reading,
            "", record_table(records, tuning), "",
        ]  # fmt: skip
    if diagnostics is None:
        return lines
    single = sorted(diagnostics.glob("*/config.json"))
    lines += [
        f"## Diagnostics: runs that tested a cause (`{diagnostics.as_posix()}/`)", "",
        "Runs made to test one explanation, some stopped once their curve answered, and the GPU nodes' "
        "records; no results table reports them. Columns as for tuning." + reading, "",
    ]  # fmt: skip
    if single:
        records = load_records([p.parent for p in single], evaluate_missing=False)
        lines += ["### Single runs", "", record_table(records, diagnostics), ""]
    for study in sorted(p for p in diagnostics.iterdir() if p.is_dir() and not (p / "config.json").exists()):
        readme = study / "README.md"
        records = load_records(_records_in(study), evaluate_missing=False)
        others = sorted(p.name for p in study.iterdir() if p.is_file() and p.name != "README.md")
        title = _readme_title(readme) if readme.exists() else study.name
        lines += [f"### `{study.name}/`: {title}", ""]
        if readme.exists():
            lines += [
                f"[Its README]({_relative_link(readme, page)}) says what ran and what it showed."
                + (f" Its other files: {', '.join(f'`{name}`' for name in others)}." if others else ""),
                "",
            ]
        lines += [record_table(records, study), ""] if records else ["No run records.", ""]
    return lines


# ------------------------------------------------------------------ figures
def _typed(record: RunRecord, protocol: str) -> dict | None:
    """A record's typing under ``protocol`` (``paper``: no reset; ``released``: a reset per key), or None."""
    if not record.typing or not record.typing.get("keys_asked"):
        return None
    return record.typing if protocol == "paper" else record.typing.get("released_protocol")


def _steps_per_key_bars(ax, x: float, records: list[RunRecord], colour: str) -> None:
    """Two bars at ``x``: steps per key without (solid) and with a reset per key (hatched), each with its
    seeds' 95 % interval, the runs' mean typing bound per key (a black bar) and the accuracy above."""
    for offset, protocol, shade in ((-0.2, "paper", 1.0), (0.2, "released", 0.45)):
        typed = [(r, t) for r in records if (t := _typed(r, protocol)) is not None]
        if not typed:
            continue
        per_key = [t["total_steps"] / t["keys_asked"] for _, t in typed]
        mean, (low, high) = float(np.mean(per_key)), bootstrap_interval(per_key)
        ax.bar(x + offset, mean, width=0.38, color=colour, alpha=shade, edgecolor=colour,
               hatch=None if protocol == "paper" else "//")  # fmt: skip
        if len(per_key) > 1:
            ax.errorbar(
                x + offset, mean, yerr=[[mean - low], [high - mean]], color="black", lw=0.7, capsize=2
            )
        bounds = [b / t["keys_asked"] for r, t in typed if (b := run_bound(r, protocol)) is not None]
        if bounds:
            ax.hlines(np.mean(bounds), x + offset - 0.19, x + offset + 0.19, color="black", lw=2)
        accuracy = np.mean([t["accuracy"] for _, t in typed])
        ax.text(x + offset, max(mean, high if len(per_key) > 1 else mean), f"{accuracy:.2f}", ha="center",
                va="bottom", fontsize=5.5)  # fmt: skip


def plot_steps_per_key(groups: Groups, path: str | Path) -> Path | None:
    """A panel per task: each group's typing steps per key (mean over seeds, its 95 % interval) without
    and with a reset per key, beside the runs' typing bound per key (the fewest steps possible) and the
    paper's Table III, the typing accuracy over each bar. None (nothing written) without typed runs."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from tactile_braille._figures import new_figure, save_figure

    tasks: dict[str, list[tuple[str, str, list[RunRecord]]]] = {}
    for (task, algo, variant), records in groups.items():
        if any(_typed(r, "paper") for r in records):
            tasks.setdefault(task, []).append((algo, variant, records))
    if not tasks:
        return None
    for members in tasks.values():  # by preset, as the headline's tables, then by agent
        members.sort(key=lambda m: (_preset_index(preset_of(m[1])), m[0]))
    columns = min(len(tasks), 2)
    fig, axes = new_figure(int(np.ceil(len(tasks) / columns)), columns, figsize=(7.0 * columns,
                           3.3 * int(np.ceil(len(tasks) / columns)) + 0.5))  # fmt: skip
    for ax, (task, members) in zip(axes.ravel(), tasks.items(), strict=False):
        for x, (algo, variant, records) in enumerate(members):
            _steps_per_key_bars(ax, x, records, PRESET_COLOURS.get(preset_of(variant), "grey"))
            paper = PAPER_TABLE.get(("sim", task, algo))
            keys = next(t["keys_asked"] for r in records if (t := _typed(r, "paper")))
            if paper is not None:
                ax.plot(x, paper[0] / keys, marker="D", color="red", ls="none", ms=4, zorder=3)
        ax.set_xticks(range(len(members)), [f"{agent_label(a)}\n{preset_of(v)}" for a, v, _ in members],
                      fontsize=6.5)  # fmt: skip
        ax.set_title(f"{task}: typing steps per key", fontsize=9)
        ax.set_ylabel("steps per key")
        ax.set_ylim(0, ax.get_ylim()[1] * 1.08)  # room for the accuracies
    for ax in axes.ravel()[len(tasks) :]:
        ax.axis("off")
    presets = sorted({preset_of(v) for members in tasks.values() for _, v, _ in members},
                     key=_preset_index)  # fmt: skip
    handles = [
        Patch(color=PRESET_COLOURS.get(p, "grey"), label=f"{p}, no reset between keys") for p in presets
    ]
    handles += [
        Patch(facecolor="white", edgecolor="grey", hatch="//", label="lighter, hatched: a reset per key"),
        Line2D([], [], color="black", lw=2, label="typing bound: the fewest steps possible"),
        Line2D([], [], color="red", marker="D", ls="none", label="the paper's Table III"),
    ]  # fmt: skip
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 4), fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0.5 / fig.get_figheight() + 0.02, 1, 1))
    return save_figure(fig, path)


def plot_preset_curves(groups: Groups, path: str | Path) -> Path | None:
    """A panel per preset (rows) and task (columns): each agent's test return per epoch, seed by seed
    and the mean, over the original release's logged run of the same agent (dotted) and the paper's
    convergence epoch (dashed, where the panel reaches it). None (nothing written) without groups."""
    from tactile_braille._figures import new_figure, save_figure

    cells: dict[tuple[str, str], list[tuple[str, list[RunRecord]]]] = {}
    for (task, algo, variant), records in groups.items():
        cells.setdefault((preset_of(variant), task), []).append((algo, records))
    if not cells:
        return None
    presets = sorted({p for p, _ in cells}, key=_preset_index)
    tasks = list(dict.fromkeys(task for _, task in sorted(cells, key=lambda k: _task_index(k[1]))))
    originals = original_curves()
    fig, axes = new_figure(len(presets), len(tasks), figsize=(4.0 * len(tasks), 2.8 * len(presets)))
    for (row, preset), (column, task) in ((r, c) for r in enumerate(presets) for c in enumerate(tasks)):
        ax, members = axes[row, column], cells.get((preset, task))
        if not members:
            ax.axis("off")
            continue
        longest = max(len(r.returns) for _, records in members for r in records)
        for algo, records in members:
            colour = f"C{agent_names().index(algo)}" if algo in agent_names() else "grey"
            for record in records:
                ax.plot(
                    np.arange(1, len(record.returns) + 1), record.returns, color=colour, lw=0.5, alpha=0.3
                )
            epochs, curves = seed_curves(records)
            ax.plot(
                epochs,
                curves.mean(0),
                color=colour,
                lw=1.8,
                label=f"{agent_label(algo)}, {len(records)} seeds",
            )
            original = originals.get(("sim", task, algo))
            if original is not None:
                shown = original[0] < longest * 1.2
                ax.plot(original[0][shown] + 1, original[1][shown], color=colour, lw=1, ls=":",
                        label=f"{agent_label(algo)}, the release's log")  # fmt: skip
            paper = PAPER_TABLE.get(("sim", task, algo))
            if paper is not None and paper[2] <= longest:
                ax.axvline(paper[2], color=colour, lw=0.8, ls="--")
        ax.axhline(0.95, color="grey", lw=0.5)
        ax.set_title(f"{task}, {preset}", fontsize=8)
        ax.set_ylim(-0.05, 1.05)
        ax.tick_params(labelsize=7)
        ax.set_xlabel("epoch (250 steps)", fontsize=7)
        ax.legend(fontsize=5.5, loc="lower right")
    fig.tight_layout()
    return save_figure(fig, path)


def _task_index(task: str) -> int:
    return list(TASK_NAMES).index(task) if task in TASK_NAMES else 99


def plot_departures(departed: Groups, own: Groups, path: str | Path) -> Path | None:
    """A panel per preset and task with departures: the mean test return (seed range shaded) of each
    group that departs, beside the preset's own rows (black). None (nothing written) without departures."""
    from tactile_braille._figures import save_figure

    panels: dict[tuple[str, str], list[tuple[str, str, list[RunRecord]]]] = {}
    for (task, algo, variant), records in departed.items():
        panels.setdefault((preset_of(variant), task), []).append((algo, variant, records))
    if not panels:
        return None
    keys = sorted(panels, key=lambda k: (*_preset_index(k[0]), _task_index(k[1])))
    references = {key: [(k, r) for k, r in own.items() if (k[0], preset_of(k[2])) == (key[1], key[0])
                        and any(a == k[1] for a, _, _ in panels[key])] for key in keys}  # fmt: skip
    fig, axes, legends = panels_with_legends([len(panels[k]) + len(references[k]) for k in keys])
    for ax, legend, key in zip(axes, legends, keys, strict=True):
        for dashes, ((_, algo, _), records) in zip(("-", "--", ":"), references[key], strict=False):
            epochs, curves = seed_curves(records)
            ax.plot(epochs, curves.mean(0), color="black", ls=dashes, lw=2,
                    label=f"{agent_label(algo)}, the preset's own ({len(records)} seeds): "
                          f"{first_095_text(records)}")  # fmt: skip
        for index, (algo, variant, records) in enumerate(panels[key]):
            epochs, curves = seed_curves(records)
            ax.fill_between(epochs, curves.min(0), curves.max(0), color=f"C{index % 10}", alpha=0.1)
            ax.plot(epochs, curves.mean(0), color=f"C{index % 10}", lw=1.4,
                    label=f"{agent_label(algo)}, {departure_text(variant) or variant} "
                          f"({len(records)} seeds): "
                          f"{first_095_text(records)}")  # fmt: skip
        ax.axhline(0.95, color="grey", lw=0.6)
        ax.set_title(f"{key[1]}: departures from {key[0]}", fontsize=9)
        ax.set_xlabel("epoch (250 steps)")
        ax.set_ylabel("test return, mean over seeds")
        ax.set_ylim(-0.05, 1.05)
        legend.legend(*ax.get_legend_handles_labels(), fontsize=6.5, loc="upper left", frameon=False)
    fig.tight_layout()
    return save_figure(fig, path)


# ------------------------------------------------------------------ pages
def _see_also(headline: Path) -> str:
    """The line near each page's top that links the results pages (and the hand-written ones beside them)."""
    pages = [("Table III and the presets", headline.name)]
    pages += [(title.split(":")[0].lower(), f"{headline.stem}-{name}.md") for name, title in PAGES.items()]
    pages += [(label, target) for label, target in SEE_ALSO if (headline.parent / target).exists()]
    return "**The results pages:** " + " · ".join(f"[{label}]({target})" for label, target in pages)


def _figure_lines(groups: Groups, figures: Path, link: str, written: set[str]) -> list[str]:
    """The headline's figures, each under a caption: curves by task, steps per key, the presets' curves."""
    lines = by_task_section(groups, figures, link, written) + profiles_section(groups, figures, link, written)
    if plot_steps_per_key(groups, figures / "steps_per_key.png") is not None:
        written.add("steps_per_key.png")
        lines += [
            "Typing steps per key, each row's mean over seeds (whiskers: its 95 % interval), without a reset "
            "between keys (the paper's text) and with one (hatched, the released code's), the typing "
            "accuracy above each bar, beside the typing bound of the same start poses (black: the fewest "
            "steps any policy, even one that knows the sensor's pose, can type every key right in) and the "
            "paper's Table III (red; it does not say which protocol it used):", "",
            f"![steps per key against the typing bound]({link}steps_per_key.png)", "",
        ]  # fmt: skip
    if plot_preset_curves(groups, figures / "curves.png") is not None:
        written.add("curves.png")
        lines += [
            "Each preset's runs seed by seed (thin) and their mean (thick), a row per preset, beside the "
            "original release's logged run of the same agent (dotted) and the paper's convergence epoch "
            "(dashed, where the runs reach it):", "",
            f"![the presets' training curves, seed by seed]({link}curves.png)", "",
        ]  # fmt: skip
    return lines


def _headline_page(title: str, own: Groups, notes: str | None, sections: list[str],
                   figures: list[str], headline: Path) -> list[str]:  # fmt: skip
    ablations = f"{headline.stem}-ablations.md"
    return [
        f"# {title}", "",
        "`make results` generates this page and the three beside it from the run records committed under "
        "`results/` (each run's settings, world, progress and typing; no checkpoints), on any machine. This "
        f"page holds one row per preset, task and agent: the runs made with a preset's own settings. Rows "
        f"that depart from a preset are on [their own page]({ablations}). Each cell: the mean over seeds "
        "[95 % bootstrap confidence interval] (and the interquartile mean from 4 seeds up); typing is the "
        "paper's evaluation of each run's last checkpoint, without a reset between keys (the paper's text) "
        "and with one ('reset per key', the released code's). [Reading the tables](#reading-the-table), "
        "below them, says more.", "",
        _see_also(headline), "", *figures, *headline_tables(own),
        *coverage_section(own, elsewhere=f"on [the variants and ablations page]({ablations})", level=2),
        *([notes.strip(), ""] if notes else []), *sections,
    ]  # fmt: skip


def _ablations_page(departed: Groups, own: Groups, figures: Path, link: str, written: set[str],
                    headline: Path) -> list[str]:  # fmt: skip
    lines = [
        f"# {PAGES['ablations']}", "", _see_also(headline), "",
        "`make results` generates this page from the same records as [the results page]"
        f"({headline.name}). Each row is a group of runs whose settings depart from a preset's: the "
        "settings in which its runs differ from the preset as it is today ('what differs'; a run made "
        "before a preset changed differs in what the change added, such as the earlier `released` "
        "preset's rows), or runs made as an ablation (`results/ablation-*/`). The rows are grouped by the "
        "preset they depart from, and each task and agent's rows follow the preset's own row, as on the "
        "results page. Cells as there.", "",
    ]  # fmt: skip
    if plot_departures(departed, own, figures / "ablations.png") is not None:
        written.add("ablations.png")
        lines += [
            "Each departure's mean test return over its seeds (its seed range shaded) beside the preset's "
            "own rows (black), a panel per preset and task:", "",
            f"![departures beside their preset]({link}ablations.png)", "",
        ]  # fmt: skip
    return lines + ablation_tables(departed, own)


def _runs_page(groups: Groups, moved: list[RunRecord], warm: list[RunRecord], figures: Path, link: str,
               written: set[str], headline: Path) -> list[str]:  # fmt: skip
    lines = [
        f"# {PAGES['runs']}", "", _see_also(headline), "",
        "Every row of [the results page](" + headline.name + ") and of [the variants and ablations page]("
        f"{headline.stem}-ablations.md), in the paper's order of tasks: its runs (folder, seed, epochs, "
        "minutes and machine, convergence by the paper's rule, typing without and with a reset per key) "
        "and the typing confusion over its seeds (rows: the goal key; columns: the key pressed, a press "
        "off the keys, or none before the time limit).", "",
    ]  # fmt: skip
    lines += group_sections(groups, figures, link, written)
    if moved:
        lines += ["## Transfer runs", "", "Typed in other worlds (the results page's transfer section):", ""]
        lines += [*run_list(moved), ""]
    if warm:
        lines += ["## Warm-start runs", "", "Warm starts and their sources (the results page's warm-start "
                  "section):", "", *run_list(warm), ""]  # fmt: skip
    return lines


def write_results_pages(
    run_dirs,
    output: str | Path = "docs/results.md",
    *,
    title: str = "Results",
    notes: str | None = None,
    ablation_dirs=(),
    transfer_dirs=(),
    warm_dirs=(),
    tuning: str | Path | None = None,
    diagnostics: str | Path | None = None,
) -> list[Path]:
    """Write the results pages from run records; returns their paths, the headline page's first.

    Args:
        run_dirs: the runs' records (folders): a preset's own are the headline's rows, the others
            the variants and ablations page's.
        output: the headline page (``docs/results.md``); the others go beside it (``results-runs.md``...)
            and the figures in a folder of its name (``docs/results/``). Figures that the pages there
            linked and these do not are removed.
        title: the headline page's title.
        notes: Markdown placed after the headline's tables (a reading of them).
        ablation_dirs: runs of ablations: rows of the variants and ablations page even where their
            settings are a preset's.
        transfer_dirs: runs typed in other worlds (``transfer.json``): a section of the headline page.
        warm_dirs: warm-started runs (``init.json``) and their sources: a section of the headline page.
        tuning: a folder of tuning records (the seeds settings were chosen on): a table on the tuning page.
        diagnostics: a folder of diagnostic records and studies (a README each): on the tuning page too.
    """
    headline = Path(output)
    figures, link = headline.with_suffix(""), headline.with_suffix("").name + "/"
    own, departed = split_groups(load_records(run_dirs, evaluate_missing=False),
                                 load_records(ablation_dirs, evaluate_missing=False))  # fmt: skip
    groups = merged(own, departed)
    if not groups:
        raise ValueError("no runs to report")
    pages = [headline, *(headline.with_name(f"{headline.stem}-{name}.md") for name in PAGES)]
    previous = set().union(*(linked_figures(page, link) for page in pages))
    figures.mkdir(parents=True, exist_ok=True)
    written: set[str] = set()
    runs_page = pages[2].name
    sections = transfer_section(transfer_dirs, runs_page=runs_page)
    sections += warm_start_section(warm_dirs, groups, figures, link, written, runs_page=runs_page)
    moved = [r for r in load_records(transfer_dirs, evaluate_missing=False) if r.transfer]
    warm = load_records(warm_dirs, evaluate_missing=False)
    account = next((target for label, target in SEE_ALSO if "account" in label
                    and (headline.parent / target).exists()), None)  # fmt: skip
    texts = [
        _headline_page(title, own, notes, sections, _figure_lines(own, figures, link, written), headline),
        _ablations_page(departed, own, figures, link, written, headline),
        _runs_page(groups, moved, warm, figures, link, written, headline),
        [f"# {PAGES['tuning']}", "", _see_also(headline), "",
         *tuning_lines(_path(tuning), _path(diagnostics), pages[3], account)],
    ]  # fmt: skip
    for page, lines in zip(pages, texts, strict=True):
        with atomic_path(page) as temporary:
            temporary.write_text("\n".join(lines).rstrip("\n") + "\n")
    for stale in previous - written:
        (figures / stale).unlink(missing_ok=True)
    return pages


def _path(value: str | Path | None) -> Path | None:
    return None if value is None else Path(value)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m tactile_braille.evaluation.results_pages RUN_DIR... [options]``: the results pages."""
    parser = argparse.ArgumentParser(
        prog="python -m tactile_braille.evaluation.results_pages",
        description="Write the results pages (make results): the headline page at --output, its companions "
        "beside it and their figures in a folder of its name.",
    )
    parser.add_argument("runs", nargs="+", type=Path, metavar="RUN_DIR", help="run records")
    parser.add_argument("--output", type=Path, default=Path("docs/results.md"), help="the headline page")
    parser.add_argument("--title", default="Results", help="the headline page's title")
    parser.add_argument("--notes", type=Path, help="Markdown placed after the headline's tables")
    for flag, what in (("--ablations", "runs of ablations"), ("--transfer", "runs typed in other worlds"),
                       ("--warm-start", "warm-started runs and their sources")):  # fmt: skip
        parser.add_argument(flag, nargs="*", type=Path, default=(), metavar="RUN_DIR", help=what)
    parser.add_argument("--tuning", type=Path, metavar="DIR", help="the tuning records' folder")
    parser.add_argument("--diagnostics", type=Path, metavar="DIR", help="the diagnostic records' folder")
    args = parser.parse_args(argv)
    pages = write_results_pages(
        args.runs, args.output, title=args.title, notes=args.notes.read_text() if args.notes else None,
        ablation_dirs=args.ablations, transfer_dirs=args.transfer, warm_dirs=args.warm_start,
        tuning=args.tuning, diagnostics=args.diagnostics,
    )  # fmt: skip
    for page in pages:
        print(f"wrote {page} ({page.stat().st_size:,} bytes)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
