"""The leaderboard: results files ranked per task and track, beside the paper's Table III.

``tactile-braille leaderboard RESULTS... --output docs/leaderboard.md``.
RESULTS are results files (docs/benchmark.md) or run folders and archived
records (their ``result.json``, or one made from their typing evaluation).
Per task, results are grouped by method, track, fingerprint and training
budget (their seeds averaged), and ranked by typing accuracy, then by typing steps. A results file
given twice (the same file, or the same content), or two results of a group whose training seed is
unknown (None), are refused: they cannot be told apart as seeds. A task's reference fingerprint (or
the one given) is chosen by its conditions, not by counting: the task scored as its registered
environment comes (:func:`registered_conditions`: the paper's protocol, the default world with none of
the released simulator's rules, :data:`~tactile_braille.envs.core.WORLD_RULES`, the ``dataset``
backend, typing start seed 0, the registry's episode limit). Where several fingerprints hold those
conditions (another dataset or project version), or none does, the one most of those results (or of
all the task's results) hold, the lowest hash on a tie. A reproduction in the released simulator's
world, a ``--seed 1`` typing or a live render, however many its runs, never moves the reference.
Results under other conditions are listed apart with what differs, never ranked with the rest (or
refused, with ``strict``).
"""

from __future__ import annotations

import json
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import gymnasium as gym
import numpy as np

from tactile_braille._io import atomic_path
from tactile_braille._tasks import official_budget
from tactile_braille.agents.registry import agent_label
from tactile_braille.agents.run import json_differences
from tactile_braille.envs.core import WORLD_RULES
from tactile_braille.evaluation.report import PAPER_TABLE, TASK_NAMES, TRACK_TITLES
from tactile_braille.evaluation.results import check_result, read_result
from tactile_braille.evaluation.statistics import (
    bootstrap_interval,
    iqm,
    performance_profile,
    probability_of_improvement,
)

PAPER_METHOD = "Church et al. 2020, Table III (sim)"


def load_results(paths) -> list[tuple[str, dict]]:
    """(where, result) for each results file or run folder in ``paths``."""
    from tactile_braille.evaluation.runs import run_result

    loaded, given = [], {}
    for path in map(Path, paths):
        if path.resolve() in given:
            raise ValueError(f"{given[path.resolve()]} and {path} are the same results file, given twice: "
                             "give each once (a result counted twice would count as two seeds)")  # fmt: skip
        given[path.resolve()] = path
        if path.is_dir():
            if not (path / "config.json").exists():
                raise ValueError(f"{path} is a folder but not a run or a record (no config.json)")
            loaded.append((str(path), run_result(path)))
        elif path.exists():
            loaded.append((str(path), read_result(path)))
        else:
            raise FileNotFoundError(f"{path} does not exist")
    return loaded


@dataclass
class Row:
    """One method's results on one task, over its seeds."""

    method: str
    track: str
    fingerprint: str
    accuracy: list[float]
    steps: list[float]
    env_steps: list[int | None]
    optimum: float | None = None
    paper: bool = False
    tuning: str = "-"
    """How the method's settings were chosen: the search its results files record (``12 trials``;
    ``12 trials of 7,500 steps`` where its trials trained for fewer steps than the row; ``16 trials on 3
    seeds`` where each trial trained on several tuning seeds), else ``-`` (no search: published
    settings, or a preset chosen by hand; docs/benchmark.md)."""
    scores: list[float] = field(default_factory=list)
    """Each seed's :func:`typing_score` (the statistics' measure)."""

    def rank_key(self) -> tuple[float, float]:
        return -float(np.mean(self.accuracy)), float(np.mean(self.steps))


def _rows(results: list[tuple[str, dict]]) -> dict[str, list[Row]]:
    """Rows per task: results grouped by (method, track, fingerprint, training budget); one seed once
    per row; each result checked and its seal verified (:func:`check_result`)."""
    rows: dict[tuple, Row] = {}
    seeds: dict[tuple, dict] = {}
    contents: dict[str, str] = {}
    for where, result in results:
        check_result(result, where)  # given in memory, checked as a file is when it is read
        content = json.dumps(result, sort_keys=True)
        if content in contents:
            raise ValueError(f"{contents[content]} and {where} hold the same result (a copy?): give each "
                             "result once (counted twice it would count as two seeds)")  # fmt: skip
        contents[content] = where
        budget = result["budget"].get("env_steps")
        key = (result["task"], result["method"], result["track"], result["fingerprint"], budget)
        report = result["report"]
        if key not in rows:
            tuning = result.get("tuning") if isinstance(result.get("tuning"), dict) else {}
            trials, trial_steps = tuning.get("trials"), tuning.get("steps")
            searched = f"{trials} trials" if isinstance(trials, int) and not isinstance(trials, bool) else "-"
            if searched != "-" and isinstance(trial_steps, int) and trial_steps != budget:
                searched += f" of {trial_steps:,} steps"  # its trials trained for fewer steps than the row
            if searched != "-" and len(tuning.get("seeds") or []) > 1:
                searched += f" on {len(tuning['seeds'])} seeds"  # each trial trained on several seeds
            rows[key] = Row(result["method"], result["track"], result["fingerprint"], [], [], [],
                            report.get("touch_optimum"), tuning=searched)  # fmt: skip
        taken = seeds.setdefault(key, {})
        unknown = taken.get(None) if result["seed"] is not None else next(iter(taken.values()), None)
        if unknown is not None:
            raise ValueError(f"{unknown} and {where}: two results of {result['method']} on {result['task']} "
                             f"({result['track']} track, fingerprint {result['fingerprint'][:12]}, budget "
                             f"{budget}), not both of known training seed (None: unknown), cannot be told "
                             "apart as seeds: score each with its --train-seed, or under a --method of its "
                             "own")  # fmt: skip
        if result["seed"] in taken:
            raise ValueError(f"{where} repeats seed {result['seed']} of {taken[result['seed']]} "
                             f"({result['method']}, {result['task']})")  # fmt: skip
        taken[result["seed"]] = where
        rows[key].accuracy.append(report["accuracy"])
        rows[key].steps.append(report["total_steps"])
        rows[key].env_steps.append(result["budget"].get("env_steps"))
        rows[key].scores.append(typing_score(report["accuracy"], report["total_steps"], report["keys_asked"]))
    per_task: dict[str, list[Row]] = {}
    for (task, *_), row in rows.items():
        per_task.setdefault(task, []).append(row)
    return per_task


def _references(given: dict[str, str], results) -> dict[str, str]:
    """Each task's chosen fingerprint, whole: a prefix must match exactly one of the task's results."""
    resolved = {}
    for task, prefix in given.items():
        name = task.removeprefix("tactile_braille/")
        held = sorted({r["fingerprint"] for _, r in results if r["task"] == name})
        if not held:
            raise ValueError(f"--reference {task}: no result of that task is given")
        hits = [f for f in held if f.startswith(prefix)]
        if len(hits) != 1:
            raise ValueError(f"--reference {task}={prefix} matches {len(hits)} of its results' fingerprints "
                             f"({', '.join(f[:12] for f in held)})")  # fmt: skip
        resolved[name] = hits[0]
    return resolved


def registered_conditions(task: str, conditions: dict) -> bool:
    """Whether ``conditions`` (a report's) are those ``task`` is scored under as its registered environment
    comes: the paper's protocol, the default world (the ``dataset`` backend, none of the released
    simulator's rules), typing start seed 0 and the registry's episode limit."""
    try:
        limit = gym.spec(f"tactile_braille/{task}").max_episode_steps
    except gym.error.Error:  # a task this version does not register: no registered conditions
        return False
    world = conditions["world"]
    return (conditions["protocol"] == "paper" and world.get("backend") == "dataset"
            and not any(rule in world for rule in WORLD_RULES)
            and conditions["start_seed"] == 0 and conditions["max_episode_steps"] == limit)  # fmt: skip


def _default_reference(results, task: str) -> str:
    """The fingerprint of ``task``'s results scored under its :func:`registered_conditions`; where several
    are (or none is), the one most of those results (or of all the task's) hold, the lowest on a tie."""
    held = [r for _, r in results if r["task"] == task]
    default = [r for r in held if registered_conditions(task, r["report"]["conditions"])]
    counts = Counter(r["fingerprint"] for r in default or held)
    return min(counts, key=lambda f: (-counts[f], f))


def _conditions(results, task: str) -> dict[str, dict]:
    return {r["fingerprint"]: r["report"]["conditions"] for _, r in results if r["task"] == task}


def leaderboard_markdown(
    results: list[tuple[str, dict]],
    title: str = "Leaderboard",
    reference: dict[str, str] | None = None,
    strict: bool = False,
    figure: str | None = None,
) -> str:
    """The leaderboard page (the module docstring). ``reference``: task -> fingerprint (or a prefix of
    one, as the page shows them) to rank under; ``figure``: where the page finds the performance profiles
    (:func:`plot_performance_profiles`), relative to it, shown under the introduction."""
    lines = [f"# {title}", "", _INTRO, ""]
    if figure is not None:
        lines += [_PROFILES_CAPTION, "", f"![performance profiles]({figure})", ""]
    for task, chosen, ranked, over, apart in _tasks(results, reference):
        if strict and apart:
            where = next(w for w, r in results if r["task"] == task and r["fingerprint"] != chosen)
            raise ValueError(
                f"{where} was scored under other conditions (fingerprint {apart[0].fingerprint[:12]}) "
                f"than {task}'s reference {chosen[:12]}"
            )
        conditions = _conditions(results, task)
        budget = official_budget(task)
        lines += [f"## {task}", "", _describe(conditions[chosen], chosen), ""]
        if budget is not None:
            lines += [f"Ranked: methods trained within the official budget, {budget:,} environment steps "
                      f"({budget // 250} epochs of 250).", ""]  # fmt: skip
        for track in sorted({r.track for r in ranked}, key=lambda t: (t != "tactile", t)):
            lines += [f"### {TRACK_TITLES.get(track, track)}", "", *_table(
                sorted((r for r in ranked if r.track == track), key=Row.rank_key)), ""]  # fmt: skip
        lines += _statistics(ranked)
        if over:
            lines += ["### Over the official budget, or of no stated budget (not ranked with the above)", "",
                      "| method | track | seeds | accuracy | steps | env steps trained |",
                      "|---|---|---|---|---|---|"]  # fmt: skip
            lines += [
                f"| {row.method} | {row.track} | {len(row.accuracy)} | {_mean(row.accuracy, 3)} "
                f"| {_mean(row.steps, 0)} | {_budget(row)} |"
                for row in sorted(over, key=Row.rank_key)
            ]
            lines.append("")
        if apart:
            lines += ["### Under other conditions (not ranked with the above)", "",
                      "| method | track | seeds | accuracy | steps | fingerprint "
                      "| differs from the reference in |",
                      "|---|---|---|---|---|---|---|"]  # fmt: skip
            for row in sorted(apart, key=Row.rank_key):
                differ = "; ".join(
                    _short(line)
                    for line in json_differences(conditions[chosen], conditions[row.fingerprint])[:3]
                )
                lines.append(f"| {row.method} | {row.track} | {len(row.accuracy)} | {_mean(row.accuracy, 3)} "
                             f"| {_mean(row.steps, 0)} | `{row.fingerprint[:12]}` | {differ} |")  # fmt: skip
            lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def _tasks(results, reference: dict[str, str] | None):
    """Per task, in the reports' order: (task, its reference fingerprint, the rows under it within the
    task's official budget with the paper's beside them, the rows under it over that budget (or of no
    stated budget), the rows under other conditions)."""
    reference = _references(reference or {}, results)
    per_task = _rows(results)
    order = [*TASK_NAMES, *sorted(set(per_task) - set(TASK_NAMES))]
    for task in (t for t in order if t in per_task):
        chosen = reference.get(task) or _default_reference(results, task)
        apart = [row for row in per_task[task] if row.fingerprint != chosen]
        held = [row for row in per_task[task] if row.fingerprint == chosen]
        budget = official_budget(task)
        within = [row for row in held if _within(row, budget)]
        over = [row for row in held if not _within(row, budget)]
        yield task, chosen, within + _paper_rows(task), over, apart


def _within(row: Row, budget: int | None) -> bool:
    """Whether every seed of ``row`` trained within ``budget`` environment steps (any, without one)."""
    return budget is None or all(steps is not None and steps <= budget for steps in row.env_steps)


def typing_score(accuracy: float, total_steps: float, keys_asked: int) -> float:
    """One seed's typing as one number, the measure of the leaderboard's statistics: its accuracy, with
    ties broken by fewer steps (less than one key's worth: a key typed right outweighs any speed)."""
    return accuracy - total_steps / (keys_asked * 25 * 1_000)


OURS = "tactile_braille "
"""How the methods of this project's own runs begin (:func:`~tactile_braille.evaluation.runs.run_method`)."""

HEADLINE_MARKERS = ("<!-- headline: generated by make results -->", "<!-- /headline -->")
"""The lines between which :func:`write_headline` puts the headline table in a page (the README)."""


def headline_markdown(results: list[tuple[str, dict]], reference: dict[str, str] | None = None) -> str:
    """A table of one row per task: the paper's best row, our best method on each track and the best
    other method (a library's baseline), each ranked under the task's reference conditions as on the
    leaderboard (accuracy first, then steps)."""
    lines = [
        "| task | the paper (Table III) | ours, `tactile` track | ours, `proprio` track "
        "| best other method |",
        "|---|---|---|---|---|",
    ]
    for task, _, ranked, _, _ in _tasks(results, reference):
        best = {
            "paper": [r for r in ranked if r.paper],
            "tactile": [r for r in ranked if r.method.startswith(OURS) and r.track == "tactile"],
            "proprio": [r for r in ranked if r.method.startswith(OURS) and r.track == "proprio"],
            "other": [r for r in ranked if not r.paper and not r.method.startswith(OURS)],
        }
        cells = [_headline_cell(min(rows, key=Row.rank_key)) if rows else "-" for rows in best.values()]
        lines.append(f"| {task} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _headline_cell(row: Row) -> str:
    method = row.method.removeprefix(OURS).removeprefix(f"{PAPER_METHOD}: ")
    count = len(row.accuracy)
    seeds = "" if row.paper else f", {count} seed{'s' if count > 1 else ''}"
    return f"{np.mean(row.accuracy):.3f} in {np.mean(row.steps):,.0f} steps ({method}{seeds})"


def write_headline(path: Path, table: str) -> None:
    """Put ``table`` between the :data:`HEADLINE_MARKERS` of the page at ``path`` (atomically).

    Raises:
        ValueError: the page lacks the markers (nothing is written).
    """
    text = path.read_text(encoding="utf-8")
    start, end = HEADLINE_MARKERS
    if text.count(start) != 1 or text.count(end) != 1 or text.index(start) > text.index(end):
        raise ValueError(
            f"{path} needs the lines {start!r} and {end!r}, once each, to hold the headline table"
        )
    before, _, rest = text.partition(start)
    _, _, after = rest.partition(end)
    with atomic_path(path) as temporary:
        temporary.write_text(f"{before}{start}\n{table}{end}{after}", encoding="utf-8")


_INTRO = (
    "Generated by `tactile-braille leaderboard` from the results files under `results/` (`make results`); "
    "the format and how to add your agent: [benchmark.md](benchmark.md). Each row is a method's mean over "
    "its training seeds (range in brackets), typing the paper's sequences under the paper's protocol "
    "(no reset between keys), ranked by accuracy, then by steps. *Touch-only optimum*: the fewest steps "
    "a policy that knows only what it has felt can expect to type every key right in (discrete tasks; a "
    "lower bound under this protocol; a policy that presses wrong keys early can take fewer). *Tuning*: "
    "the trials of the search that chose the row's settings (the benchmark's protocol: "
    "[benchmark.md](benchmark.md#the-tuning-protocol)); `-` where no search did: the paper's and the "
    "released code's settings as published, and our other presets' settings, chosen by hand on tuning "
    "seeds. The libraries' baselines and their budgets: "
    "[benchmark.md](benchmark.md#baselines-from-other-libraries). "
    "The paper's rows are its reported figures: its exact conditions cannot be fingerprinted, "
    "its steps were most likely counted with a reset per key (docs/evaluation.md), and on the continuous "
    "tasks it was measured in the released simulator's world, where the workspace's edge does not stop "
    'the sensor and taps read 2 mm deeper (`edges="overrun"`, `tap_depth="released"`; '
    "docs/environments.md), not the environments' default world. On the discrete tasks the default world "
    "samples the released simulator's way (one of 100 jittered taps of the key under the sensor), from "
    "renders where the paper's were the real sensor's images, and how fast the paper's DQN learns the "
    "discrete alphabet depends on the images' spread ([notes/alphabet-gap.md](notes/alphabet-gap.md))."
)


def _paper_rows(task: str) -> list[Row]:
    return [
        Row(f"{PAPER_METHOD}: {agent_label(algo)}", "tactile", "",
            [accuracy], [steps], [None], paper=True)
        for (platform, name, algo), (steps, accuracy, _) in PAPER_TABLE.items()
        if platform == "sim" and name == task
    ]  # fmt: skip


def _table(rows: list[Row]) -> list[str]:
    lines = ["| rank | method | track | seeds | accuracy | steps | touch-only optimum | env steps trained "
             "| tuning |", "|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    rank = 0
    for row in rows:
        rank += not row.paper
        lines.append(
            f"| {'-' if row.paper else rank} | {row.method} | {row.track} "
            f"| {'-' if row.paper else len(row.accuracy)} | {_mean(row.accuracy, 3)} | {_mean(row.steps, 0)} "
            f"| {'-' if row.optimum is None else f'{row.optimum:.0f}'} | {_budget(row)} "
            f"| {'-' if row.paper else row.tuning} |"
        )
    return lines


def _budget(row: Row) -> str:
    budget = [b for b in row.env_steps if b is not None]
    return f"{np.mean(budget):,.0f}" if budget else "-"


def _tops(ranked: list[Row]) -> dict[str, Row]:
    """A task's best methods, as its statistics compare them: our best on each track, the best other."""
    best = {
        "ours, tactile": [r for r in ranked if r.method.startswith(OURS) and r.track == "tactile"],
        "ours, proprio": [r for r in ranked if r.method.startswith(OURS) and r.track == "proprio"],
        "best other": [r for r in ranked if not r.paper and not r.method.startswith(OURS)],
    }
    return {name: min(rows, key=Row.rank_key) for name, rows in best.items() if rows}


def _statistics(ranked: list[Row]) -> list[str]:
    """The field's statistics for a task's best methods (:func:`_tops`): the interquartile mean of each
    one's accuracy over its seeds with a bootstrap interval, and the probability that our best
    ``tactile`` method types better than the best other method (rliable's definitions, computed with
    SciPy)."""
    tops = _tops(ranked)
    if not tops:
        return []
    lines = ["Statistics (interquartile mean over seeds, 95 % percentile-bootstrap interval):", ""]
    for name, row in tops.items():
        low, high = bootstrap_interval(row.accuracy, "iqm")
        lines.append(f"- {name}: {row.method}: accuracy IQM {iqm(row.accuracy):.3f} [{low:.3f}, {high:.3f}] "
                     f"over {len(row.accuracy)} seed{'s' if len(row.accuracy) > 1 else ''}")  # fmt: skip
    if "ours, tactile" in tops and "best other" in tops:
        ours, other = tops["ours, tactile"], tops["best other"]
        value, (low, high) = probability_of_improvement(ours.scores, other.scores)
        lines.append(f"- probability of improvement, ours (`tactile`) over the best other method: "
                     f"{value:.2f} [{low:.2f}, {high:.2f}] (per seed: accuracy, then steps)")  # fmt: skip
    return [*lines, ""]


PROFILE_FROM = 0.8
"""The lowest accuracy threshold the profiles show (where the methods differ); a method whose seeds all
type below it lies at 0."""

PROFILE_COLOURS = {"ours, tactile": "tab:blue", "ours, proprio": "tab:green", "best other": "tab:orange"}

_PROFILES_CAPTION = (
    "Performance profiles (rliable's): for each task's best methods within its official budget (ours on "
    "each track, the best other method), the share of training seeds whose typing accuracy is above each "
    "threshold, with a 95 % percentile-bootstrap band; a curve further up and to the right types better "
    f"more reliably; thresholds from {PROFILE_FROM} up, where the best methods differ (a method whose "
    f"seeds all type below {PROFILE_FROM} lies at 0). The paper's typing accuracy is the dashed line."
)


def plot_performance_profiles(
    results: list[tuple[str, dict]], path: str | Path, reference: dict[str, str] | None = None
) -> Path | None:
    """A panel per task: the performance profile (:func:`~tactile_braille.evaluation.statistics.
    performance_profile`) of the typing accuracy of the task's best methods ranked within its official
    budget (those its statistics compare), the paper's accuracy beside them. None (nothing written)
    without ranked methods."""
    from matplotlib.lines import Line2D

    from tactile_braille._figures import new_figure, save_figure

    panels = [(task, _tops(ranked), [r for r in ranked if r.paper])
              for task, _, ranked, _, _ in _tasks(results, reference)]  # fmt: skip
    panels = [panel for panel in panels if panel[1]]
    if not panels:
        return None
    columns = min(len(panels), 2)
    rows = int(np.ceil(len(panels) / columns))
    fig, axes = new_figure(rows, columns, figsize=(5.2 * columns, 2.9 * rows + 0.6))
    taus = np.linspace(PROFILE_FROM, 1.0, 201)
    for ax, (task, tops, paper) in zip(axes.ravel(), panels, strict=False):
        for name, row in tops.items():
            share, low, high = performance_profile([row.accuracy], taus)
            colour = PROFILE_COLOURS[name]
            count = len(row.accuracy)
            label = f"{name}: {row.method.removeprefix(OURS)} ({count} seed{'s' if count > 1 else ''})"
            ax.step(taus, share, where="post", color=colour, label=_short(label, 70), lw=1.4)
            ax.fill_between(taus, low, high, step="post", color=colour, alpha=0.15, lw=0)
        for row in paper:
            if row.accuracy[0] >= PROFILE_FROM:
                ax.axvline(row.accuracy[0], color="red", ls="--", lw=0.8)
        ax.set_xlim(PROFILE_FROM, 1.0)
        ax.set_ylim(-0.03, 1.03)
        ax.set_title(task, fontsize=9)
        ax.set_xlabel("typing accuracy threshold", fontsize=8)
        ax.set_ylabel("share of seeds above it", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=6, loc="lower left", frameon=False)
    for ax in axes.ravel()[len(panels) :]:
        ax.axis("off")
    fig.legend(handles=[Line2D([], [], color="red", ls="--", lw=0.8, label="the paper's Table III")],
               loc="lower center", fontsize=7, frameon=False)  # fmt: skip
    fig.tight_layout(rect=(0, 0.3 / fig.get_figheight() + 0.01, 1, 1))
    return save_figure(fig, path)


def _mean(values, digits: int) -> str:
    text = f"{np.mean(values):.{digits}f}"
    return text if len(values) == 1 else f"{text} [{min(values):.{digits}f}, {max(values):.{digits}f}]"


def _describe(conditions: dict, chosen: str) -> str:
    world = conditions["world"]
    return (f"Reference conditions `{chosen[:12]}`: protocol `{conditions['protocol']}`, "
            f"{len(conditions['sequences'])} sequences, "
            f"{conditions['max_episode_steps']} steps per key at most, "
            f"start seed {conditions['start_seed']}, backend `{world.get('backend')}`, world "
            f"{world.get('generator_version', world.get('rig'))}{_rules(world)}, tactile_braille "
            f"{conditions['project_version']}.")  # fmt: skip


def _rules(world: dict) -> str:
    """The released simulator's rules a world follows (:data:`~tactile_braille.envs.core.WORLD_RULES`)."""
    rules = [f"{name} `{world[name]}`" for name in WORLD_RULES if name in world]
    return f" ({', '.join(rules)})" if rules else ""


def _short(line: str, width: int = 60) -> str:
    return line if len(line) <= width else line[: width - 3] + "..."
