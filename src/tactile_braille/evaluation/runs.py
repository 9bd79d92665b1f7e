"""Our training runs on the benchmark's protocol: typing of a run's last checkpoint, and its results file.

``evaluate_typing(RUN_DIR)`` scores the run's agent with
:func:`~tactile_braille.evaluation.scoring.evaluate_policy` (the function any
other agent goes through) under both protocols and writes
``RUN_DIR/typing.json`` (what reports read), ``RUN_DIR/result.json`` (the
benchmark's results file) and ``RUN_DIR/typing_confusion.png``;
``evaluate_transfer(RUN_DIR, worlds)`` types in other worlds (the live
renderer, a calibration error, another sensor: :mod:`.worlds`) and writes
``RUN_DIR/transfer.json``. A run whose settings a search chose holds that search's record as
``RUN_DIR/tuning.json`` (:mod:`tactile_braille.tuning`), and its results file carries it.
:func:`run_result` reads a run's results file, or makes it from a record
archived before results files existed.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from tactile_braille._io import atomic_path
from tactile_braille.agents.registry import agent_label, agent_spec
from tactile_braille.agents.run import read_config, read_progress, run_world
from tactile_braille.envs.memory import TapMemory
from tactile_braille.envs.registry import task_name, task_of
from tactile_braille.evaluation.protocol import paper_sequences
from tactile_braille.evaluation.report import departures
from tactile_braille.evaluation.results import make_result, read_result, write_result
from tactile_braille.evaluation.scoring import (
    TypingReport,
    evaluate_policy,
    fingerprint,
    protocol_conditions,
    touch_optimum,
)

RESULT_FILE = "result.json"
TRANSFER_FILE = "transfer.json"
TUNING_FILE = "tuning.json"
LEGACY_VERSION = "0.1.0"
"""The project's version when typing.json held no fingerprint (every record before results files)."""


def run_method(config, tuned: bool = False) -> str:
    """A run's method name on a leaderboard: algorithm, HER, preset, and each setting in which the run
    departs from its preset (``name=value``): a preset's name alone would claim the preset's agent.
    ``tuned``: a search chose those settings (``..., tuned: name=value``)."""
    her = " + HER" if config.replay.her and agent_spec(config.algo).hindsight else ""
    settings = ", ".join(departures(config))
    if tuned:
        settings = "tuned" + (f": {settings}" if settings else "")
    algo = agent_label(config.algo)
    return f"tactile_braille {algo}{her} (`{config.preset or 'custom'}`{', ' if settings else ''}{settings})"


def run_tuning(run_dir) -> dict | None:
    """The record of the search that chose a run's settings (``RUN_DIR/tuning.json``), or None."""
    path = Path(run_dir) / TUNING_FILE
    return json.loads(path.read_text()) if path.exists() else None


def evaluate_typing(run_dir, sentences: bool = True, seed: int = 0) -> dict:
    """The typing evaluation of a run's last checkpoint (the module docstring); returns typing.json's
    content. For the alphabet tasks, ``sentences`` adds the typing of the sentences."""

    from tactile_braille.agents.report import load_run, read_checkpoint

    run_dir = Path(run_dir)
    config, env, agent = load_run(run_dir)
    state = read_checkpoint(run_dir)
    epoch, env_steps = int(state["epoch"]), int(state["env_steps"])  # what the scored policy trained
    limit = config.max_episode_steps  # the run's own (None: the task's registered one)
    report = evaluate_policy(agent, config.task, env=env, track=config.track, seed=seed, sentences=sentences,
                             max_episode_steps=limit)  # fmt: skip
    released = evaluate_policy(agent, config.task, env=env, track=config.track, seed=seed,
                               protocol="released", sentences=False, max_episode_steps=limit)  # fmt: skip
    output = {"task": config.task, "algo": config.algo, "seed": config.seed, "checkpoint_epoch": epoch,
              "typing_seed": seed, **_summary(report), "confusion": report.confusion,
              "fingerprint": report.fingerprint,
              "released_protocol": {**_summary(released), "fingerprint": released.fingerprint}}  # fmt: skip
    if report.sentences is not None:
        output["sentences"] = report.sentences
    # The results file is made (and checked) before anything is written.
    tuning = run_tuning(run_dir)
    result = make_result(report, method=run_method(config, tuned=tuning is not None), seed=config.seed,
                         epochs=epoch + 1, env_steps=env_steps, tuning=tuning)  # fmt: skip
    confusion = np.array(report.confusion["counts"])
    save_typing_confusion(confusion, report.confusion["rows"], report.confusion["columns"],
                          run_dir / "typing_confusion.png",
                          f"{task_name(config.task)}, {config.algo}: accuracy {report.accuracy:.3f}, "
                          f"{report.total_steps} steps")  # fmt: skip
    with atomic_path(run_dir / "typing.json") as temporary:
        temporary.write_text(json.dumps(output, indent=2))
    write_result(result, run_dir / RESULT_FILE, overwrite=True)
    return output


def evaluate_transfer(run_dir, worlds: list[str], seed: int = 0) -> dict:
    """The typing evaluation of a run's last checkpoint in other worlds (:mod:`.worlds`); returns
    ``RUN_DIR/transfer.json``'s content, which keeps the other worlds' entries of the same checkpoint."""

    from tactile_braille.agents.report import load_run, read_checkpoint
    from tactile_braille.evaluation.worlds import expand_worlds

    run_dir = Path(run_dir)
    chosen = expand_worlds(worlds)  # a mistyped world is refused before anything runs
    config = read_config(run_dir)
    if task_of(config.task) is None:
        raise ValueError(f"{run_dir} trained on {config.task}, which has no keyboard to transfer to")
    if not (run_dir / "checkpoint.pt").exists():
        raise FileNotFoundError(f"{run_dir} has no checkpoint yet: nothing to type with")
    state = read_checkpoint(run_dir)
    epoch = int(state["epoch"])
    path = run_dir / TRANSFER_FILE
    output = json.loads(path.read_text()) if path.exists() else {}
    if output.get("checkpoint_epoch") != epoch or output.get("typing_seed") != seed:
        output = {"task": config.task, "algo": config.algo, "seed": config.seed, "checkpoint_epoch": epoch,
                  "typing_seed": seed, "worlds": {}}  # fmt: skip
    sensor = (run_world(run_dir) or {}).get("sensor", {}).get("name", "braille_331")
    options = {"max_episode_steps": config.max_episode_steps} if config.max_episode_steps else {}
    if config.edges != "stop":  # the run's edge rule holds in every world (its depth lookup: the grid's)
        options["edges"] = config.edges
    agent = None
    for world in chosen:
        env = world.make_env(config.task, sensor, proprio=bool(config.touch.pose_inputs), **options)
        env = TapMemory(env, config.taps) if config.taps > 1 else env
        if agent is None:  # the checkpoint once: every world has the task's spaces and layout
            _, _, agent = load_run(run_dir, env=env)
        report = evaluate_policy(agent, config.task, env=env, track=config.track, seed=seed, sentences=False,
                                 max_episode_steps=config.max_episode_steps)  # fmt: skip
        output["worlds"][world.name] = {**_summary(report), "fingerprint": report.fingerprint,
                                        "world": report.conditions["world"]}  # fmt: skip
        with atomic_path(path) as temporary:  # after each world: a long evaluation keeps what it scored
            temporary.write_text(json.dumps(output, indent=2))
    return output


def _summary(report: TypingReport) -> dict:
    return {"sequences": report.sequences, "keys_asked": report.keys_asked, "accuracy": report.accuracy,
            "total_steps": report.total_steps, "steps_per_key": report.steps_per_key,
            "touch_optimum": report.touch_optimum, "typing_bound": report.typing_bound}  # fmt: skip


def run_result(run_dir) -> dict:
    """The results file of a run folder or an archived record.

    A record archived before results files existed is read from its
    ``typing.json``, ``world.json``, ``config.json`` and ``progress.csv``: the
    fingerprint is computed from the world it recorded, the sequences and
    start seed its evaluation used, and the project version of that time.
    """
    run_dir = Path(run_dir)
    config = read_config(run_dir)
    rows = read_progress(run_dir)
    if (run_dir / RESULT_FILE).exists():
        result = read_result(run_dir / RESULT_FILE)
        if result["budget"]["epochs"] == len(rows):  # else evaluated before the run went on: stale
            return result
    typing_file = run_dir / "typing.json"
    if not typing_file.exists():
        raise ValueError(f"{run_dir} has no typing evaluation: run `tactile-braille evaluate {run_dir}`")
    typing = json.loads(typing_file.read_text())
    if "fingerprint" in typing:  # written with its result.json, which is gone: not to be guessed
        raise ValueError(f"{run_dir} lacks the result.json of its typing evaluation: run "
                         f"`tactile-braille evaluate {run_dir}` again")  # fmt: skip
    if typing.get("checkpoint_epoch") != len(rows) - 1:
        raise ValueError(
            f"{run_dir}: its typing evaluation is of epoch {typing.get('checkpoint_epoch')}, not of its "
            f"last ({len(rows) - 1}): run `tactile-braille evaluate {run_dir}`"
        )
    world = run_world(run_dir)
    if world is None or task_of(config.task) is None:
        raise ValueError(f"{run_dir} recorded no world (it predates world.json): it has no fingerprint")
    return make_result(
        _legacy_report(config, typing, world),
        method=run_method(config),
        seed=config.seed,
        epochs=len(rows),
        env_steps=int(rows[-1]["env_steps"]) if rows else 0,
    )


def _legacy_report(config, typing: dict, world: dict) -> TypingReport:
    """The report a typing.json without a fingerprint records (the paper's protocol, start seed 0)."""
    import gymnasium as gym

    keys = task_of(config.task).keys
    sequences = paper_sequences(keys)
    limit = config.max_episode_steps or gym.spec(config.task).max_episode_steps
    conditions = protocol_conditions(
        config.task, "paper", sequences, limit, typing.get("typing_seed", 0), world
    )
    conditions["project_version"] = LEGACY_VERSION
    return TypingReport(
        task=task_name(config.task), protocol="paper", track=config.track, accuracy=typing["accuracy"],
        total_steps=typing["total_steps"], keys_asked=typing["keys_asked"], sequences=typing["sequences"],
        fingerprint=fingerprint(conditions), conditions=conditions, confusion=typing["confusion"],
        touch_optimum=None if task_of(config.task).continuous else touch_optimum(keys, sequences, "paper"),
        sentences=typing.get("sentences"),
    )  # fmt: skip


def save_typing_confusion(matrix: np.ndarray, keys, columns, path, title: str):
    """The typing confusion matrix as a PNG (rows: goal key; columns: key pressed, OTHER, NONE)."""
    from tactile_braille._figures import new_figure, save_figure

    size = 2.5 + 0.28 * len(columns)
    fig, axes = new_figure(figsize=(size, size * 0.9))
    ax = axes[0, 0]
    ax.imshow(np.where(matrix > 0, matrix, np.nan), cmap="viridis", interpolation="nearest")
    ax.set_xticks(range(len(columns)), columns, rotation=90, fontsize=7)
    ax.set_yticks(range(len(keys)), keys, fontsize=7)
    ax.set_xlabel("key pressed")
    ax.set_ylabel("goal key")
    for i, j in zip(*np.nonzero(matrix), strict=True):
        ax.text(j, i, str(matrix[i, j]), ha="center", va="center", fontsize=6,
                color="white" if i != j else "black")  # fmt: skip
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path)
