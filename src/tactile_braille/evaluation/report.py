"""Reports over runs and seeds: the paper's Table III with confidence intervals, curves, trajectories.

``tactile-braille report RUN_DIR... --output DIR`` groups runs by (task,
algorithm), reads each one's typing evaluation (:func:`write_report` runs it
where missing; the command, which writes only under ``DIR``, refuses such
runs instead) and writes ``DIR/results.md``: a table in the shape of the paper's Table III, the
paper's numbers alongside, with the mean over seeds, its 95 % bootstrap
confidence interval and the interquartile mean (IQM, the mean of the middle
half, as rliable recommends for few seeds); training curves with the seed
range, the convergence marker and the original release's logged run overlaid;
typing confusion matrices; and the paper's Figure 4 (the sensor's path to the
goal at the start, middle and end of training). The repository's own results
pages (``make results``) are written from the same pieces by
:mod:`~tactile_braille.evaluation.results_pages`.
"""

from __future__ import annotations

import csv
import json
import math
import re
import textwrap
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from tactile_braille._io import atomic_path
from tactile_braille._tasks import REGISTERED_TASKS
from tactile_braille.agents.config import TrainConfig, flatten
from tactile_braille.agents.registry import PAPER_AGENTS, agent_label
from tactile_braille.agents.report import convergence_epoch
from tactile_braille.agents.run import read_config, read_progress, run_world
from tactile_braille.datasets.collector import GENERATOR_VERSION
from tactile_braille.envs.registry import task_name, task_of
from tactile_braille.evaluation.statistics import bootstrap_interval, iqm

TASK_NAMES = {task.name: task.label for task in REGISTERED_TASKS}
"""Each registered task's short name in the reports (the paper's Table III rows), in the paper's order."""
PAPER_TABLE: dict[tuple[str, str, str], tuple[int, float, int]] = {
    ("sim", "DiscreteArrows-v0", "dqn"): (230, 1.0, 8),
    ("sim", "DiscreteArrows-v0", "sac_discrete"): (234, 1.0, 8),
    ("sim", "DiscreteAlphabet-v0", "dqn"): (1722, 0.981, 45),
    ("sim", "DiscreteAlphabet-v0", "sac_discrete"): (1649, 0.940, 39),
    ("sim", "ContinuousArrows-v0", "td3"): (140, 0.906, 60),
    ("sim", "ContinuousArrows-v0", "sac"): (133, 1.0, 25),
    ("sim", "ContinuousAlphabet-v0", "td3"): (1169, 0.811, 1246),
    ("sim", "ContinuousAlphabet-v0", "sac"): (1193, 0.933, 872),
    ("robot", "DiscreteArrows-v0", "dqn"): (246, 1.0, 8),
    ("robot", "DiscreteArrows-v0", "sac_discrete"): (246, 1.0, 6),
    ("robot", "DiscreteAlphabet-v0", "dqn"): (1722, 0.992, 24),
    ("robot", "DiscreteAlphabet-v0", "sac_discrete"): (1649, 0.985, 32),
    ("robot", "ContinuousArrows-v0", "sac"): (364, 0.938, 76),
}
"""The paper's Table III: (platform, task, algo) -> (typing steps, typing accuracy, convergence epoch)."""


# ------------------------------------------------------------------ runs
@dataclass
class RunRecord:
    """One training run as the report sees it."""

    path: Path
    task: str
    algo: str
    seed: int
    returns: np.ndarray
    typing: dict | None = None
    seconds: float = float("nan")
    """Wall-clock of the run's epochs (training and tests, from ``progress.csv``)."""
    config: TrainConfig | None = field(default=None, repr=False)
    world: str | None = GENERATOR_VERSION
    """The generator version (or the real rig) of the world the run learned in; ``None`` where
    the run predates ``world.json`` (a world before ``0.1.0+samples3``)."""
    transfer: dict | None = None
    """``transfer.json``: typing of the last checkpoint in other worlds (None if never, or stale)."""
    grid: str | None = None
    """The grid a continuous-task run learnt on where it is not its task's (``6 mm grid``), else None."""
    init: dict | None = None
    """``init.json``: what a warm-started run (``init_from``) took from its source run."""

    @property
    def variant(self) -> str:
        """The settings that set this run apart from others of its task and algorithm."""
        if self.init is None:
            return self.cold_variant
        warm = f"warm start: {self.init['epochs']} epochs on the {source_world(self.init.get('world'))}"
        return f"{self.cold_variant}, {warm}" if self.cold_variant else warm

    @property
    def cold_variant(self) -> str:
        """:attr:`variant` but for a warm start: that of the same run started from scratch."""
        if self.config is None:
            return ""
        from tactile_braille.agents.presets import PRESETS

        parts = [self.config.preset or "custom", self.config.precision]
        if self.config.preset not in PRESETS:  # a preset's run names its track by departing from it
            parts.append(f"{self.config.track} track")
        if not self.config.replay.her:
            parts.append("no HER")
        if self.config.backend != "dataset":
            parts.append(f"{self.config.backend} backend")
        if self.config.frame_noise is not None:
            parts.append("frame noise {:g} mm, {:g} deg".format(*self.config.frame_noise))
        if self.grid is not None:
            parts.append(self.grid)
        if self.world != GENERATOR_VERSION:
            parts.append("earlier world" if self.world is None else f"world {self.world}")
        return ", ".join(parts + departures(self.config))

    @property
    def track(self) -> str:
        """The benchmark track the run competes in (docs/benchmark.md)."""
        return self.config.track if self.config is not None else "tactile"

    @property
    def convergence(self) -> int | None:
        return convergence_epoch(list(self.returns))

    @property
    def reached_095(self) -> int | None:
        return convergence_epoch(list(self.returns), level=0.95)


def dataset_label(world: dict | None) -> str | None:
    """What sets a run's dataset apart from its task's default, in a few words: ``6 mm grid`` for a grid
    other than the paper's (3 mm alphabet and 1 mm arrows grids), with its depth step where that
    differs too; ``1 unperturbed tap per key`` (or the bounds) for perturbed taps drawn within other
    bounds than the paper's; else None."""
    from tactile_braille.datasets.procedures import GridTaps

    procedure = (world or {}).get("procedure") or {}
    if procedure.get("procedure") == "perturbed":
        return _perturbed_label(procedure)
    if procedure.get("procedure") != "grid":
        return None
    default = GridTaps(keys=procedure["keys"])
    spacing, depth = procedure["spacing_mm"], procedure["depth_step_mm"]
    if (spacing, depth) == (default.spacing_mm, default.depth_step_mm):
        return None
    return f"{spacing:g} mm grid" + (f" ({depth:g} mm depth steps)" if depth != default.depth_step_mm else "")


def _perturbed_label(procedure: dict) -> str | None:
    from tactile_braille.datasets.procedures import PerturbedTaps

    paper = PerturbedTaps()
    per_key = procedure.get("per_key", paper.per_key)
    position = procedure.get("position_range_mm", paper.position_range_mm)
    low, high = procedure.get("depth_range_mm", paper.depth_range_mm)
    yaw = procedure.get("yaw_range_deg", paper.yaw_range_deg)
    if (position, (low, high), yaw) == (paper.position_range_mm, paper.depth_range_mm, paper.yaw_range_deg):
        return None
    taps = f"{per_key} {'tap' if per_key == 1 else 'taps'} per key"
    if position == 0 and low == high and yaw == 0:
        return taps.replace(" tap", " unperturbed tap", 1)
    return f"{taps} within +-{position:g} mm, +-{yaw:g} deg, depth {low:+g} to {high:+g} mm"


def source_world(world: dict | None) -> str:
    """Where a warm start's source learnt, in a few words: ``6 mm grid``, ``render backend``..."""
    world = world or {}
    if world.get("backend", "dataset") != "dataset":
        return f"{world['backend']} backend"
    return dataset_label(world) or "default dataset"


def _read_json(path: Path) -> dict | None:
    return json.loads(path.read_text()) if path.exists() else None


def _current_typing(run_dir: Path, rows: list[dict[str, float]]) -> dict | None:
    """The run's typing evaluation (``typing.json``), or None where it has none of its last epoch."""
    typing_file = run_dir / "typing.json"
    typing = json.loads(typing_file.read_text()) if typing_file.exists() else None
    last_epoch = int(rows[-1]["epoch"]) if rows else -1
    if typing is not None and typing.get("checkpoint_epoch") != last_epoch:
        return None  # evaluated before the run went on: stale
    return typing


def unevaluated(run_dirs) -> list[Path]:
    """The runs with a checkpoint but no typing evaluation of their last epoch: those that
    :func:`load_records` evaluates, writing ``typing.json`` and ``result.json`` into their folders."""
    return [
        run_dir
        for run_dir in map(Path, run_dirs)
        if (run_dir / "checkpoint.pt").exists() and _current_typing(run_dir, read_progress(run_dir)) is None
    ]


def load_records(run_dirs, evaluate_missing: bool = True) -> list[RunRecord]:
    """Read runs (and their typing evaluations, running them where missing)."""
    from tactile_braille.evaluation.runs import evaluate_typing

    records = []
    for run_dir in map(Path, run_dirs):
        if not (run_dir / "config.json").exists():
            raise FileNotFoundError(f"{run_dir} is not a training run (no config.json)")
        config = read_config(run_dir)
        rows = read_progress(run_dir)
        typing = _current_typing(run_dir, rows)
        last_epoch = int(rows[-1]["epoch"]) if rows else -1
        if typing is not None and "released_protocol" not in typing and evaluate_missing \
                and (run_dir / "checkpoint.pt").exists():  # fmt: skip
            typing = None  # evaluated before the released protocol was: evaluate again
        if typing is None and evaluate_missing and (run_dir / "checkpoint.pt").exists():
            typing = evaluate_typing(run_dir)
        world = run_world(run_dir)
        transfer_file = run_dir / "transfer.json"
        transfer = json.loads(transfer_file.read_text()) if transfer_file.exists() else None
        if transfer is not None and transfer.get("checkpoint_epoch") != last_epoch:
            transfer = None  # typed before the run went on: stale
        records.append(RunRecord(
            path=run_dir, task=task_name(config.task), algo=config.algo, seed=config.seed,
            returns=np.array([row["test/episodic_return"] for row in rows]), typing=typing, config=config,
            seconds=float(np.nansum([row.get("time_s", np.nan) for row in rows])), transfer=transfer,
            grid=dataset_label(world), init=_read_json(run_dir / "init.json"),
            world=(GENERATOR_VERSION if task_of(config.task) is None else None)
            if world is None else world.get("generator_version", world.get("rig")),
        ))  # fmt: skip
    return records


def group(
    records: list[RunRecord], variant: Callable[[RunRecord], str] | None = None
) -> dict[tuple[str, str, str], list[RunRecord]]:
    """Records by (task, algo, variant), in the paper's order; runs of one group need distinct seeds.
    ``variant``: a record's variant as the groups name it (default: :attr:`RunRecord.variant`)."""
    order = list(TASK_NAMES)
    named = variant or (lambda record: record.variant)
    groups: dict[tuple[str, str, str], list[RunRecord]] = {}
    for record in sorted(
        records, key=lambda r: (order.index(r.task) if r.task in order else 99, r.algo, named(r), r.seed)
    ):
        members = groups.setdefault((record.task, record.algo, named(record)), [])
        if any(other.seed == record.seed for other in members):
            raise ValueError(f"{record.path} repeats seed {record.seed} of {members[0].path}")
        members.append(record)
    return groups


def original_curves() -> dict[tuple[str, str, str], tuple[np.ndarray, np.ndarray]]:
    """The original release's logged test returns: (platform, task, algo) -> (epochs, returns)."""
    table = resources.files("tactile_braille.evaluation") / "reference" / "original_runs.csv"
    curves: dict[tuple[str, str, str], list[tuple[int, float]]] = {}
    with table.open(newline="") as handle:
        for row in csv.DictReader(handle):
            key = (row["platform"], row["task"], row["algo"])
            curves.setdefault(key, []).append((int(row["epoch"]), float(row["test_return"])))
    return {key: (np.array([e for e, _ in v]), np.array([r for _, r in v])) for key, v in curves.items()}


# ------------------------------------------------------------------ table
def _stat(values, digits: int = 1) -> str:
    values = [v for v in values if v is not None and np.isfinite(v)]
    if not values:
        return "-"
    if len(values) == 1:
        return f"{values[0]:.{digits}f} (one run)"
    low, high = bootstrap_interval(values)
    text = f"{np.mean(values):.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]"
    return text + (f"; IQM {iqm(values):.{digits}f}" if len(values) >= 4 else "")


_RUN_SETTINGS = {"task", "algo", "preset", "seed", "epochs", "threads", "device", "dataset", "precision",
                 "init_from", "frame_noise",
                 "replay.her", "backend", "checkpoint_every", "evaluation.snapshots",
                 "evaluation.test_episodes"}  # fmt: skip
"""Settings that do not make a variant (or are named by it already)."""


def departures(config: TrainConfig) -> list[str]:
    """``name=value`` for each setting in which a run departs from its preset (an ablation)."""
    from tactile_braille.agents.presets import PRESETS, preset_config

    if config.preset not in PRESETS:
        return []
    ran, preset = flatten(config), flatten(preset_config(config.preset, config.task, config.algo))
    departed = [name for name in sorted(ran) if name not in _RUN_SETTINGS and ran[name] != preset[name]]
    return [f"{name}={ran[name]}" for name in departed]


def _label(algo: str, variant: str) -> str:
    return agent_label(algo) + (f" ({variant})" if variant else "")


TRACK_TITLES = {
    "tactile": "Track `tactile`: the paper's rules (touch, previous action, goals and reward only)",
    "proprio": "Track `proprio`: also the arm's pose and the calibrated key layout",
}
"""A heading per track where a report holds more than one (docs/benchmark.md)."""


def results_table(groups: dict[tuple[str, str, str], list[RunRecord]]) -> str:
    """Markdown in the shape of the paper's Table III, ours (mean [95 % CI]) beside the paper's, with a
    ``track`` column; runs of different tracks go in separate tables, each under its track's heading."""
    tracks: dict[str, dict] = {}
    for key, records in groups.items():
        kinds = {r.track for r in records}
        if len(kinds) > 1:
            raise ValueError(f"{records[0].path} and others of one group compete in tracks {sorted(kinds)}")
        tracks.setdefault(records[0].track, {})[key] = records
    if len(tracks) == 1:
        return _track_table(next(iter(tracks.values())))
    ordered = sorted(tracks, key=lambda t: (list(TRACK_TITLES).index(t) if t in TRACK_TITLES else 99, t))
    return "\n\n".join(f"### {TRACK_TITLES.get(t, t)}\n\n" + _track_table(tracks[t]) for t in ordered)


TYPING_COLUMNS = (
    "steps", "typing bound", "accuracy", "steps, reset per key", "typing bound, reset per key",
    "accuracy, reset per key", "convergence epoch", "first epoch >= 0.95",
)  # fmt: skip
"""The columns of :func:`typing_cells`: typing under the paper's text protocol (no reset between keys) and
the released code's (a reset per key), each beside its typing bound, then the two convergence epochs."""
PAPER_COLUMNS = ("paper: steps", "paper: accuracy", "paper: convergence")
"""The columns of :func:`paper_cells`: the paper's Table III (simulation)."""


def typing_cells(records: list[RunRecord]) -> list[str]:
    """A group's cells under :data:`TYPING_COLUMNS`: mean over seeds [95 % CI] (IQM from 4 seeds)."""
    typed = [r.typing for r in records if r.typing]
    reset = [t["released_protocol"] for t in typed if "released_protocol" in t]
    return [
        _stat([t["total_steps"] for t in typed], 0),
        _bound_cell([run_bound(r, "paper") for r in records if r.typing]),
        _stat([t["accuracy"] for t in typed], 3),
        _stat([t["total_steps"] for t in reset], 0),
        _bound_cell(
            [run_bound(r, "released") for r in records if r.typing and "released_protocol" in r.typing]
        ),
        _stat([t["accuracy"] for t in reset], 3),
        _stat([r.convergence for r in records], 1),
        _reached_cell([r.reached_095 for r in records], [len(r.returns) for r in records]),
    ]


def paper_cells(task: str, algo: str) -> list[str]:
    """The paper's Table III row of ``task`` and ``algo`` (simulation) under :data:`PAPER_COLUMNS`."""
    paper = PAPER_TABLE.get(("sim", task, algo))
    return [str(paper[0]), f"{paper[1]:.3f}", str(paper[2])] if paper else ["-", "-", "-"]


def markdown_table(header: list[str] | tuple[str, ...], rows: list[list[str]]) -> str:
    """A Markdown table of ``rows`` under ``header``."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join([*lines, *("| " + " | ".join(row) + " |" for row in rows)])


def _track_table(groups: dict[tuple[str, str, str], list[RunRecord]]) -> str:
    rows = [
        ["sim", TASK_NAMES.get(task, task), _label(algo, variant), records[0].track, str(len(records)),
         *typing_cells(records), *paper_cells(task, algo)]
        for (task, algo, variant), records in groups.items()
    ]  # fmt: skip
    return markdown_table(("env", "task", "algo", "track", "seeds", *TYPING_COLUMNS, *PAPER_COLUMNS), rows)


TABLE3_SEEDS = 5
"""Seeds per row of Table III and preset, as the paper ran them."""
TABLE3_SHORT_ROWS = {"ContinuousAlphabet-v0": (3, 100)}
"""Rows too long for a CPU (2,000 epochs), asked as far as compute allows: (seeds, epochs) at least."""
TABLE3_PRESETS = ("paper", "released")


def coverage_table(groups: dict[tuple[str, str, str], list[RunRecord]]) -> str:
    """How complete Table III is: for each simulated row and each of the paper's presets, the seeds
    whose runs ran the preset's full epochs (the continuous alphabet: at least 100 epochs) with the
    preset's own settings, against the seeds asked for. Runs that depart from their preset, or ran an
    earlier version of it, are other rows of the results table and do not count here."""
    from tactile_braille.agents.presets import PRESET_TRACKS, TASK_PRESETS

    lines = [
        "| Table III row | preset | track | seeds run | epochs each | asked | status |",
        "|---|---|---|---|---|---|---|",
    ]
    for platform, task, algo in PAPER_TABLE:
        if platform != "sim":
            continue
        full = TASK_PRESETS[f"tactile_braille/{task}"].paper_epochs
        seeds_asked, epochs_asked = TABLE3_SHORT_ROWS.get(task, (TABLE3_SEEDS, full))
        for preset in TABLE3_PRESETS:
            runs = [
                r for (t, a, variant), records in groups.items() if (t, a) == (task, algo)
                and variant in (f"{preset}, bf16", f"{preset}, fp32") for r in records
            ]  # fmt: skip
            finished = [r for r in runs if len(r.returns) >= epochs_asked]
            done, epochs = sorted({r.seed for r in finished}), sorted({len(r.returns) for r in finished})
            short = sorted(len(r.returns) for r in runs if len(r.returns) < epochs_asked)
            epochs_text = "-" if not epochs else (
                str(epochs[0]) if len(epochs) == 1 else f"{epochs[0]}-{epochs[-1]}"
            )  # fmt: skip
            asked = f"{seeds_asked} x {epochs_asked}" + ("" if epochs_asked == full else f" (of {full:,})")
            if len(done) >= seeds_asked:
                status = "complete"
            elif done:
                status = f"{seeds_asked - len(done)} more seed{'s' if seeds_asked - len(done) > 1 else ''}"
            else:
                status = "not run"
            if short:
                status += f"; {len(short)} stopped at epoch {', '.join(map(str, short))}"
            lines.append(
                f"| {TASK_NAMES[task]}, {agent_label(algo)} | {preset} | {PRESET_TRACKS[preset]} "
                f"| {len(done)} | {epochs_text} | {asked} | {status} |"
            )
    return "\n".join(lines)


def coverage_section(
    groups: dict[tuple[str, str, str], list[RunRecord]],
    elsewhere: str = "in the tables above",
    level: int = 3,
) -> list[str]:
    """The report's lines on how complete Table III is (:func:`coverage_table` under a heading of
    ``level``); none for a report without a run of the paper's presets (the table would only say "not
    run"). ``elsewhere`` says where the rows of runs that depart from a preset are."""
    if not any(variant.split(",")[0] in TABLE3_PRESETS for _, _, variant in groups):
        return []
    return [
        "#" * level + " Table III coverage: seeds per row with the paper's and the released code's "
        "settings", "",
        "Runs with the preset's own settings to its full epochs (the continuous alphabet's 2,000 are "
        "asked only as far as compute allows); rows of an earlier `released` preset, or of runs that "
        f"change a setting, are {elsewhere} but not counted here.", "",
        coverage_table(groups), "",
    ]  # fmt: skip


def _reached_cell(reached: list[int | None], epochs: list[int] | None = None) -> str:
    """First epochs at 0.95 over seeds; how many reached it where some did not, and, given the epochs
    each run ran (``epochs``), within how many the others did not (``not by epoch 100``)."""
    if all(e is not None for e in reached):
        return _stat(reached, 1)
    some = any(e is not None for e in reached)
    budget = ""
    if epochs is not None:
        short = sorted({n for e, n in zip(reached, epochs, strict=True) if e is None})
        budget = (
            f", not by epoch {short[0]}" if len(short) == 1 else f", not by epochs {short[0]}-{short[-1]}"
        )
    return f"{sum(e is not None for e in reached)}/{len(reached)} reached{budget}" + (
        f"; {_stat(reached, 1)}" if some else ""
    )


def transfer_table(groups: dict[tuple[str, str, str], list[RunRecord]]) -> str:
    """Typing accuracy (mean [95 % CI] over seeds) in the world each run learnt in and in the transfer
    worlds (:mod:`~tactile_braille.evaluation.worlds`), a row per group of runs that typed in them."""
    from tactile_braille.evaluation.worlds import TRANSFER_SUITE

    worlds = list(TRANSFER_SUITE)
    for record in (r for records in groups.values() for r in records if r.transfer):
        worlds += [w for w in record.transfer["worlds"] if w not in worlds]
    lines = [
        "| task | algo | track | seeds | where it learnt | " + " | ".join(f"`{w}`" for w in worlds) + " |",
        "|---|---|---|---|---|" + "---|" * len(worlds),
    ]
    for (task, algo, variant), records in groups.items():
        moved = [r for r in records if r.transfer]
        if not moved:
            continue
        home = _stat([r.typing["accuracy"] for r in moved if r.typing], 3)
        cells = [_stat([r.transfer["worlds"][w]["accuracy"] for r in moved if w in r.transfer["worlds"]], 3)
                 for w in worlds]  # fmt: skip
        track = moved[0].track
        lines.append(
            f"| {task} | {_label(algo, variant)} | {track} | {len(moved)} | {home} | "
            + " | ".join(cells)
            + " |"
        )
    return "\n".join(lines)


def run_list(records: list[RunRecord]) -> list[str]:
    """A line per run: its folder, seed and epochs (and a warm start's source)."""
    return [
        f"- `{r.path}`: seed {r.seed}, {len(r.returns)} epochs"
        + (f", warm start from `{Path(r.init['run']).name}` ({r.init['epochs']} epochs)" if r.init else "")
        for r in records
    ]


def transfer_section(transfer_dirs, runs_page: str | None = None) -> list[str]:
    """The report's lines on the runs typed in other worlds (none without such runs); the runs are
    listed below the table, or, given ``runs_page`` (a link), there."""
    moved = group(load_records(transfer_dirs, evaluate_missing=False)) if transfer_dirs else {}
    runs = [r for records in moved.values() for r in records if r.transfer]
    if not runs:
        return []
    where = f"listed on [the runs page]({runs_page})" if runs_page else "listed below the table"
    listed = [] if runs_page else [*run_list(runs), ""]
    return [
        "## Transfer: typing in worlds the policies did not learn in", "",
        f"Runs of their own ({where}), trained on the dataset backend (or, where the row "
        "says so, the render backend, and there with the work frame off by a random error each episode: "
        "'frame noise') and typed "
        "(`tactile-braille evaluate RUN --world transfer`, the paper's protocol) in the live renderer "
        "(`render`), in it with the work frame off by 1 mm and 2 degrees (`frame:DX,DY,DEG`), and "
        "with the other TacTip (`sensor:tactip_127`); docs/evaluation.md says what this does and "
        "does not show.", "", transfer_table(moved), "", *listed,
    ]  # fmt: skip


def warm_start_table(warm: dict, cold: dict) -> str:
    """Warm-started groups (``init_from``) beside the same settings started from scratch (``cold``'s
    group of their :attr:`RunRecord.cold_variant`): first epochs at 0.95, with the pretraining's."""
    lines = [
        "| task | algo | track | seeds | pretraining | its first epoch >= 0.95 | first epoch >= 0.95, warm "
        "| from scratch (seeds): first epoch >= 0.95 | pretraining + warm epochs to 0.95 | accuracy, warm "
        "| accuracy, from scratch |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]  # fmt: skip
    for (task, algo, _), records in warm.items():
        first = records[0]
        scratch = cold.get((task, algo, first.cold_variant), [])
        source = source_world(first.init.get("world"))
        pretrained = [convergence_epoch(r.init["test_returns"], level=0.95) for r in records]
        warm_reached = [r.reached_095 for r in records]
        totals = [r.init["epochs"] + e for r, e in zip(records, warm_reached, strict=True) if e is not None]
        cells = [
            TASK_NAMES.get(task, task), _label(algo, first.cold_variant), first.track, str(len(records)),
            f"{'/'.join(sorted({str(r.init['epochs']) for r in records}))} epochs, {source}",
            _reached_cell(pretrained),
            _reached_cell(warm_reached),
            f"({len(scratch)}) {_reached_cell([r.reached_095 for r in scratch])}" if scratch else "-",
            _stat(totals, 1) if len(totals) == len(records) else _reached_cell([None] * len(records)),
            _accuracy_after(records), _accuracy_after(scratch),
        ]  # fmt: skip
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _accuracy_after(records: list[RunRecord]) -> str:
    """Typing accuracy over seeds, and after how many epochs."""
    typed = [r for r in records if r.typing]
    if not typed:
        return "-"
    epochs = "/".join(sorted({str(len(r.returns)) for r in typed}, key=int))
    return f"{_stat([r.typing['accuracy'] for r in typed], 3)} after {epochs} epochs"


def warm_start_section(
    warm_dirs, cold: dict, figures: Path, link: str, written: set[str], runs_page: str | None = None
) -> list[str]:
    """The report's lines on warm-started runs (none without such runs); its figure joins ``written``.
    The runs are listed below the figure, or, given ``runs_page`` (a link), there."""
    records = load_records(warm_dirs, evaluate_missing=False) if warm_dirs else []
    warm = group([r for r in records if r.init is not None])
    if not warm:
        return []
    figure = plot_warm_starts(warm, cold, figures / "warm_starts.png").name
    written.add(figure)
    where = f"listed on [the runs page]({runs_page})" if runs_page else "listed below"
    listed = [] if runs_page else [*run_list(records), ""]
    return [
        "## Warm starts: learning on the paper's grid after a coarser one", "",
        "The paper's Discussion: policies trained on a 6 mm grid sped up learning on the 3 mm grid. "
        f"Runs of their own ({where}), each started (`tactile-braille train ... --init-from RUN`) "
        "from the last checkpoint of a run on a coarser grid (its networks, optimisers, temperature and "
        "touch encoder; not its replay), beside the same settings started from scratch in Table III. "
        "Epochs count from the warm start; the pretraining's are counted too, in their own columns.",
        "", warm_start_table(warm, cold), "", f"![warm starts]({link}{figure})", "", *listed,
    ]  # fmt: skip


def plot_warm_starts(warm: dict, cold: dict, path: str | Path) -> Path:
    """Test return per epoch of each warm-started group: the pretraining (negative epochs), the warm
    start, and the same settings from scratch."""
    from tactile_braille._figures import new_figure, save_figure

    fig, axes = new_figure(1, len(warm), figsize=(6.2 * len(warm), 3.6))
    for ax, ((task, algo, _), records) in zip(axes.ravel(), warm.items(), strict=False):
        for index, record in enumerate(records):
            pre = np.asarray(record.init["test_returns"])
            label = {"label": "pretraining (coarser grid)"} if index == 0 else {}
            ax.plot(np.arange(len(pre)) - len(pre) + 1, pre, color="grey", lw=0.8, alpha=0.6, **label)
        scratch = cold.get((task, algo, records[0].cold_variant), [])
        for members, colour, name in ((records, "C0", "warm start"), (scratch, "C1", "from scratch")):
            if not members:
                continue
            epochs, curves = seed_curves(members)
            ax.fill_between(epochs, curves.min(0), curves.max(0), color=colour, alpha=0.15)
            ax.plot(epochs, curves.mean(0), color=colour, lw=2, label=f"{name}: mean of {len(members)} seeds")
        ax.axvline(0.5, color="black", lw=0.6, ls=":")
        ax.axhline(0.95, color="black", lw=0.6, ls="--")
        pretraining = max(len(r.init["test_returns"]) for r in records)
        ax.set_xlim(-pretraining, 1.5 * max(len(r.returns) for r in records))  # the scratch runs may go on
        ax.set_title(textwrap.fill(f"{task}, {_label(algo, records[0].variant)}", 70), fontsize=9)
        ax.set_xlabel("epoch on the task's grid (250 steps; pretraining before 0)")
        ax.set_ylabel("test return")
        ax.set_ylim(-0.05, 1.05)
        ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    return save_figure(fig, path)


def run_bound(record: RunRecord, protocol: str) -> float | None:
    """The typing bound of a record's evaluation (:mod:`~tactile_braille.evaluation.bounds`): as its
    typing.json recorded it, or computed for records evaluated before bounds existed (in the default
    dataset's world when it is the record's; None otherwise)."""
    from tactile_braille._registration import ENV_IDS
    from tactile_braille.evaluation.bounds import typing_bound

    typed = record.typing if protocol == "paper" else record.typing["released_protocol"]
    if typed.get("typing_bound") is not None:
        return typed["typing_bound"]
    task_id = f"tactile_braille/{record.task}"
    task = task_of(task_id) if task_id in ENV_IDS else None
    if task is None or (record.config is not None and record.config.backend != "dataset"):
        return None
    default_world = record.config is not None and record.config.dataset is None
    if task.continuous and not (default_world and record.world == GENERATOR_VERSION):
        return None  # the bound depends on the grid: only the default dataset's is known here
    return typing_bound(task_id, protocol=protocol, seed=record.typing.get("typing_seed", 0))


def _bound_cell(values: list[float | None]) -> str:
    """One bound, or the range of the runs' (their evaluations' start poses may differ)."""
    values = [v for v in values if v is not None]
    if not values:
        return "-"
    low, high = math.floor(min(values) + 1e-6), math.floor(max(values) + 1e-6)  # rounded down: bounds
    return f"{low}" if low == high else f"{low}-{high}"


# ------------------------------------------------------------------ figures
def seed_curves(records: list[RunRecord]) -> tuple[np.ndarray, np.ndarray]:
    """(epochs, seeds x epochs test returns) over the epochs every record ran; epoch 1 ends after the
    first 250 steps, as in the paper."""
    length = min(len(r.returns) for r in records)
    return np.arange(1, length + 1), np.stack([r.returns[:length] for r in records])


def plot_curves(groups: dict[tuple[str, str, str], list[RunRecord]], path: str | Path) -> Path:
    """Test return per epoch for each group: seeds, their mean and range, convergence, the original run."""
    from tactile_braille._figures import new_figure, save_figure

    originals = original_curves()
    count = len(groups)
    columns = min(count, 2)
    rows = int(np.ceil(count / columns))
    fig, axes = new_figure(rows, columns, figsize=(6.2 * columns, 3.6 * rows))
    for ax, ((task, algo, variant), records) in zip(axes.ravel(), groups.items(), strict=False):
        epochs, curves = seed_curves(records)
        for record in records:
            ax.plot(np.arange(1, len(record.returns) + 1), record.returns, lw=0.7, alpha=0.45)
        ax.fill_between(epochs, curves.min(0), curves.max(0), alpha=0.2, label="seed range")
        ax.plot(epochs, curves.mean(0), lw=2, color="C0", label=f"mean of {len(records)} seeds")
        convergence = [r.convergence for r in records if r.convergence is not None]
        if convergence:
            ax.axvline(np.mean(convergence), color="grey", ls="--",
                       label=f"convergence (paper's rule): {np.mean(convergence):.1f}")  # fmt: skip
        original = originals.get(("sim", task, algo))
        if original is not None:
            shown = original[0] < max(len(epochs) * 1.5, 10)
            ax.plot(original[0][shown] + 1, original[1][shown], color="black", lw=1, ls=":",
                    label="original release (sim, seed 1)")  # fmt: skip
        paper = PAPER_TABLE.get(("sim", task, algo))
        title = f"{task}, {_label(algo, variant)}, {records[0].track} track"
        title += f" (paper: converged at epoch {paper[2]})" if paper else ""
        ax.set_title(textwrap.fill(title, 70), fontsize=9)  # ablations' titles name their settings
        ax.set_xlabel("epoch (250 steps)")
        ax.set_ylabel("test return")
        ax.set_ylim(-0.05, 1.05)
        ax.legend(fontsize=7, loc="lower right")
    for ax in axes.ravel()[count:]:
        ax.axis("off")
    fig.tight_layout()
    return save_figure(fig, path)


def plot_trajectories(record: RunRecord, path: str | Path, goals: int = 3, seed: int = 7) -> Path | None:
    """The paper's Figure 4: the sensor's path to a goal with the policies of the start, middle and end.

    Needs the run's policy snapshots; returns None without them.
    """
    import torch

    from tactile_braille._figures import new_figure, save_figure
    from tactile_braille.agents.rollout import run_episode
    from tactile_braille.agents.training import make_agent, make_env

    snapshots = sorted((record.path / "snapshots").glob("epoch_*.pt"))
    if not snapshots or record.config is None:
        return None
    chosen = (
        [snapshots[0], snapshots[len(snapshots) // 2], snapshots[-1]] if len(snapshots) >= 3 else snapshots
    )
    config = record.config
    env = make_env(config, render_mode="rgb_array")  # with the run's episode limit
    agent = make_agent(config, env)
    rng = np.random.default_rng(seed)
    goal_keys = env.unwrapped.goal_keys
    episode_goals = [goal_keys[i] for i in rng.choice(len(goal_keys), size=goals, replace=False)]
    fig, axes = new_figure(goals, len(chosen), figsize=(3.4 * len(chosen), 2.9 * goals))
    for column, snapshot in enumerate(chosen):
        agent.load_policy_state_dict(torch.load(snapshot, weights_only=False, map_location=agent.device))
        epoch = int(snapshot.stem.split("_")[1]) + 1  # files count from 0, figures from 1
        for row, goal in enumerate(episode_goals):
            episode = run_episode(
                agent, env, rng, seed=seed + row, options={"goal_key": goal}, deterministic=True
            )
            ax = axes[row, column]
            ax.imshow(env.render())
            ax.axis("off")
            pressed = episode.info.get("pressed_key") or "nothing"
            ax.set_title(f"epoch {epoch}: goal {goal}, pressed {pressed}, {episode.steps} steps", fontsize=7)
    fig.suptitle(f"{record.task}, {agent_label(record.algo)}, seed {record.seed}", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path)


def _run_line(record: RunRecord) -> str:
    """One run of a group: where it is, how far it went, how long it took, how it types."""
    config = record.config
    machine = f"{config.device}, {config.threads} thread{'s' * (config.threads > 1)}" if config else "?"
    line = (f"- `{record.path}`: seed {record.seed}, {len(record.returns)} epochs in "
            f"{record.seconds / 60:.0f} min ({machine}), convergence {record.convergence}")  # fmt: skip
    if not record.typing:
        return line + " (no typing evaluation)"
    line += f", typing accuracy {record.typing['accuracy']:.3f} in {record.typing['total_steps']} steps"
    reset = record.typing.get("released_protocol")
    return line + (f" (reset per key: {reset['accuracy']:.3f} in {reset['total_steps']})" if reset else "")


COMPARED_SEEDS = 5
"""Seeds a group needs to be drawn in :func:`plot_by_task`: the paper's, and the benchmark's rows'
(fewer on a task of :data:`TABLE3_SHORT_ROWS`: the seeds its rows ask)."""


def compared_seeds(task: str) -> int:
    """Seeds a group of ``task`` needs to be drawn in :func:`plot_by_task`."""
    return min(COMPARED_SEEDS, TABLE3_SHORT_ROWS.get(task, (COMPARED_SEEDS,))[0])


def compared_groups(groups: dict[tuple[str, str, str], list[RunRecord]]) -> dict[str, list[tuple]]:
    """Task -> [(algo, variant, records)] of the groups :func:`plot_by_task` draws: those with at least
    :func:`compared_seeds` seeds, in the groups' order."""
    tasks: dict[str, list[tuple]] = {}
    for (task, algo, variant), records in groups.items():
        if len(records) >= compared_seeds(task):
            tasks.setdefault(task, []).append((algo, variant, records))
    return tasks


def first_095_text(records: list[RunRecord]) -> str:
    """``first 0.95 at 4.2`` (the mean over seeds), or ``3/5 seeds reach 0.95`` where some do not."""
    reached = [r.reached_095 for r in records]
    if None not in reached:
        return f"first 0.95 at {np.mean(reached):.1f}"
    return f"{sum(e is not None for e in reached)}/{len(reached)} seeds reach 0.95"


def panels_with_legends(entries: list[int], columns: int = 2, width: float = 7.0, height: float = 3.6):
    """A figure of ``len(entries)`` panels, ``columns`` to a row, each with its legend in a row of its own
    below it, tall enough for the row's longest legend (``entries``: each panel's legend lines), so that
    no legend covers a curve. Returns the figure, the panels' axes and the legends' axes (blank)."""
    from tactile_braille._figures import new_figure

    columns = min(len(entries), columns)
    rows = int(np.ceil(len(entries) / columns))
    legend_rows = [max(entries[r * columns : (r + 1) * columns]) * 0.13 + 0.1 for r in range(rows)]
    heights = [h for legend in legend_rows for h in (height, legend)]
    fig, grid = new_figure(2 * rows, columns, figsize=(width * columns, sum(heights) + 0.8),
                           gridspec_kw={"height_ratios": heights})  # fmt: skip
    axes, legends = grid[0::2].ravel(), grid[1::2].ravel()
    for ax in (*axes[len(entries) :], *legends):
        ax.axis("off")
    return fig, axes[: len(entries)], legends[: len(entries)]


def plot_by_task(groups: dict[tuple[str, str, str], list[RunRecord]], path: str | Path) -> Path | None:
    """One panel per task: the mean test return of every group of that task run with at least
    :data:`COMPARED_SEEDS` seeds (its seed range shaded), solid for the ``tactile`` track and dashed
    for ``proprio``, over the original release's logged runs. Fewer-seed groups (ablations, tuning)
    are left to :func:`plot_curves`. None (and nothing written) where no group has the seeds."""
    from tactile_braille._figures import save_figure

    tasks = compared_groups(groups)
    if not tasks:
        return None
    originals = original_curves()
    # Legend entries: the groups and up to two logged runs.
    fig, axes, legends = panels_with_legends([len(members) + 2 for members in tasks.values()])
    for ax, legend, (task, members) in zip(axes, legends, tasks.items(), strict=True):
        longest = max(len(r.returns) for _, _, records in members for r in records)
        for index, (algo, variant, records) in enumerate(members):
            epochs, curves = seed_curves(records)
            first = first_095_text(records)
            colour, style = f"C{index % 10}", "-" if records[0].track == "tactile" else "--"
            ax.fill_between(epochs, curves.min(0), curves.max(0), color=colour, alpha=0.1)
            ax.plot(epochs, curves.mean(0), color=colour, ls=style, lw=1.8,
                    label=f"{_label(algo, variant)}, {records[0].track}: {first}")  # fmt: skip
        logged = sorted({algo for algo, _, _ in members if ("sim", task, algo) in originals})
        for (shade, dashes), algo in zip((("black", ":"), ("dimgrey", "-.")), logged, strict=False):
            original = originals.get(("sim", task, algo))
            if original is not None:
                shown = original[0] < longest * 1.2
                ax.plot(original[0][shown] + 1, original[1][shown], color=shade, lw=1, ls=dashes,
                        label=f"{agent_label(algo)}, original release's log (sim, seed 1)")  # fmt: skip
        paper = [f"{agent_label(a)} {PAPER_TABLE[('sim', task, a)][2]}" for a in PAPER_AGENTS
                 if ("sim", task, a) in PAPER_TABLE]  # fmt: skip
        ax.axhline(0.95, color="grey", lw=0.6)
        ax.set_ylim(-0.05, 1.05)
        _label_panel(ax, legend, f"{task} (paper's convergence epochs: {', '.join(paper)})",
                     "epoch (250 steps)", f"test return, mean of {compared_seeds(task)}+ seeds")  # fmt: skip
    fig.tight_layout()
    return save_figure(fig, path)


def _label_panel(ax, legend, title: str, xlabel: str, ylabel: str) -> None:
    """A panel's title and axis labels, and its legend in the blank axes ``legend`` below it."""
    ax.set_title(title, fontsize=9)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    legend.legend(*ax.get_legend_handles_labels(), fontsize=6.5, loc="upper left", frameon=False)


def by_task_section(groups: dict, figures: Path, link: str, written: set[str]) -> list[str]:
    """The report's lines on :func:`plot_by_task`'s figure (none where it draws nothing)."""
    if plot_by_task(groups, figures / "by_task.png") is None:
        return []
    written.add("by_task.png")
    return [
        f"Each task's rows of {COMPARED_SEEDS} or more seeds side by side (the continuous alphabet's of "
        f"{compared_seeds('ContinuousAlphabet-v0')}, the seeds its Table III rows ask; means, seed ranges "
        "shaded; dashed: the `proprio` track), over the original release's logged runs:", "",
        f"![curves by task]({link}by_task.png)", "",
    ]  # fmt: skip


PROFILE_FROM = 0.8
"""The lowest typing accuracy the report's performance profiles show (where the groups differ)."""


def plot_typing_profiles(
    groups: dict[tuple[str, str, str], list[RunRecord]], path: str | Path
) -> Path | None:
    """One panel per task: the performance profile (rliable's; :func:`~tactile_braille.evaluation.
    statistics.performance_profile`) of the typing accuracy of every group :func:`plot_by_task` draws,
    over its typed seeds, with a 95 % bootstrap band; the paper's accuracies dashed. None (nothing
    written) where no such group was typed."""
    from tactile_braille._figures import save_figure
    from tactile_braille.evaluation.statistics import performance_profile

    tasks = {task: [(algo, variant, [r.typing["accuracy"] for r in records if r.typing], records[0].track)
                    for algo, variant, records in members]
             for task, members in compared_groups(groups).items()}  # fmt: skip
    tasks = {task: [m for m in members if m[2]] for task, members in tasks.items()}
    tasks = {task: members for task, members in tasks.items() if members}
    if not tasks:
        return None
    fig, axes, legends = panels_with_legends([len(members) + 1 for members in tasks.values()], height=3.0)
    taus = np.linspace(PROFILE_FROM, 1.0, 201)
    for ax, legend, (task, members) in zip(axes, legends, tasks.items(), strict=True):
        for index, (algo, variant, accuracy, track) in enumerate(members):
            share, low, high = performance_profile([accuracy], taus)
            colour, style = f"C{index % 10}", "-" if track == "tactile" else "--"
            ax.step(taus, share, where="post", color=colour, ls=style, lw=1.5,
                    label=f"{_label(algo, variant)}, {track} ({len(accuracy)} seeds)")  # fmt: skip
            ax.fill_between(taus, low, high, step="post", color=colour, alpha=0.12, lw=0)
        for algo in PAPER_AGENTS:
            paper = PAPER_TABLE.get(("sim", task, algo))
            if paper is not None and paper[1] >= PROFILE_FROM:
                ax.axvline(paper[1], color="red", ls=":", lw=0.9)
        ax.plot([], [], color="red", ls=":", lw=0.9, label="the paper's Table III accuracies")
        ax.set_xlim(PROFILE_FROM, 1.0)
        ax.set_ylim(-0.03, 1.03)
        _label_panel(ax, legend, task, "typing accuracy threshold", "share of seeds above it")
    fig.tight_layout()
    return save_figure(fig, path)


def profiles_section(groups: dict, figures: Path, link: str, written: set[str]) -> list[str]:
    """The report's lines on :func:`plot_typing_profiles`'s figure (none where it draws nothing)."""
    if plot_typing_profiles(groups, figures / "typing_profiles.png") is None:
        return []
    written.add("typing_profiles.png")
    return [
        "Performance profiles of the same rows (rliable's): the share of seeds whose typing accuracy is "
        "above each threshold, with a 95 % percentile-bootstrap band (dashed: the `proprio` track); a "
        f"curve further up and to the right types better more reliably; thresholds from {PROFILE_FROM} "
        f"up (a row whose seeds all type below {PROFILE_FROM} lies at 0):", "",
        f"![performance profiles]({link}typing_profiles.png)", "",
    ]  # fmt: skip


def linked_figures(page: Path, link: str) -> set[str]:
    """The PNGs in ``link`` (a folder's link, ``results/``, or ``""``) that ``page`` links, if it exists."""
    if not page.exists():
        return set()
    return set(re.findall(r"\]\(" + re.escape(link) + r"([^)/]+\.png)\)", page.read_text()))


def group_sections(groups: dict, figures: Path, link: str, written: set[str]) -> list[str]:
    """A section per group: its runs (:func:`_run_line`), the typing confusion over its seeds and, for a
    run with policy snapshots, the paper's Figure 4; the figures go in ``figures`` and join ``written``."""
    from tactile_braille.evaluation.runs import save_typing_confusion

    lines = []
    for (task, algo, variant), records in groups.items():
        name = f"{task.split('-')[0]}__{algo}" + (
            f"__{variant}".replace(", ", "_").replace(" ", "-") if variant else ""
        )
        lines += [f"## {task}, {_label(algo, variant)}, track `{records[0].track}`", ""]
        lines += [_run_line(r) for r in records]
        typed = [r for r in records if r.typing]
        if typed:
            confusion = np.sum([r.typing["confusion"]["counts"] for r in typed], axis=0)
            first = typed[0].typing["confusion"]
            caption = f"{task}, {_label(algo, variant)}: typing over {len(typed)} seeds"
            path = figures / f"confusion_{name}.png"
            save_typing_confusion(confusion, first["rows"], first["columns"], path, caption)
            written.add(path.name)
            lines += ["", f"![typing confusion]({link}confusion_{name}.png)"]
        with_snapshots = [r for r in records if (r.path / "snapshots").is_dir()]
        if with_snapshots and plot_trajectories(with_snapshots[0], figures / f"trajectories_{name}.png"):
            written.add(f"trajectories_{name}.png")
            lines += ["", f"![trajectories]({link}trajectories_{name}.png)"]
        lines.append("")
    return lines


def write_report(
    run_dirs,
    output: str | Path,
    title: str = "Results",
    notes: str | None = None,
    command: str | None = None,
    transfer_dirs=(),
    warm_dirs=(),
    evaluate_missing: bool = True,
) -> Path:
    """Evaluate the runs and write the report with its figures; returns its path.

    Args:
        run_dirs: the runs' folders.
        output: a folder (``output/results.md`` and the figures in it) or a
            Markdown file (``docs/results.md``: the figures go in ``docs/results/``).
            Figures that the previous report there linked and this one does
            not (groups no longer reported) are removed.
        title: the report's title.
        notes: Markdown placed after the table (a reading of the results).
        command: the command that made the report, quoted in it.
        transfer_dirs: runs whose typing in other worlds (``transfer.json``)
            is tabled in a section of its own; their other figures are not.
        warm_dirs: warm-started runs (``init.json``) and their sources, tabled in a section of their
            own beside ``run_dirs``' runs of the same settings from scratch.
        evaluate_missing: run the typing evaluation of the runs that lack one of their last epoch
            (it writes ``typing.json`` and ``result.json`` into their folders); False: report them
            without typing (:func:`unevaluated` names them).
    """
    output = Path(output)
    if output.suffix == ".md":
        report, figures, link = output, output.with_suffix(""), output.with_suffix("").name + "/"
    else:
        report, figures, link = output / "results.md", output, ""
    groups = group(load_records(run_dirs, evaluate_missing=evaluate_missing))
    if not groups:
        raise ValueError("no runs to report")
    previous = linked_figures(report, link)
    figures.mkdir(parents=True, exist_ok=True)
    written = {plot_curves(groups, figures / "curves.png").name}
    lines = [
        f"# {title}", "",
        *([f"`{command}`", ""] if command else []),
        "Generated by `tactile-braille report` from the runs listed below. Each cell: mean over seeds "
        "[95 % bootstrap confidence interval] (and the interquartile mean from 4 seeds up). Typing "
        "steps and accuracy come from the paper's typing evaluation of each run's last checkpoint "
        "(`tactile-braille evaluate`): as the paper's text describes it (no reset between keys) and, "
        "'reset per key', as the released code ran it (a random start before every key; "
        "docs/evaluation.md); convergence is the paper's rule (first epoch reaching 95 % of "
        "the run's best test return) and, stricter, the first epoch whose test return reaches 0.95.",
        "", results_table(groups), "", *coverage_section(groups), *([notes.strip(), ""] if notes else []),
        f"![training curves]({link}curves.png)", "",
    ]  # fmt: skip
    lines += by_task_section(groups, figures, link, written) + profiles_section(
        groups, figures, link, written
    )
    lines += transfer_section(transfer_dirs) + warm_start_section(warm_dirs, groups, figures, link, written)
    lines += group_sections(groups, figures, link, written)
    with atomic_path(report) as temporary:
        temporary.write_text("\n".join(lines))
    for stale in previous - written:
        (figures / stale).unlink(missing_ok=True)
    return report
