"""A run folder: what a training run writes, and what a resume reads back.

``runs/{task}__{algo}__{seed}__{time}/`` holds ``config.json`` (the resolved
settings), ``world.json`` (the dataset or rig it learns from, with the
generator version and the keyboard's and sensor's parameters: a resume in
another world is refused), ``progress.csv`` (one row per epoch), TensorBoard
events (``charts/...``, ``losses/...``, when TensorBoard is installed),
``snapshots/epoch_NNNN.pt`` (policy snapshots) and, every
``checkpoint_every`` epochs, an atomic checkpoint (``checkpoint.pt``:
networks, optimisers, counters and generator states; ``replay.{epoch}.npz``:
the replay buffer it names; the checkpoint records how many rows of
``progress.csv`` it covers and their digest, so a log that lost rows, was torn or
was edited is refused). Every file is written atomically, so a crash or
``kill -9`` costs at most the work since the last checkpoint.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from tactile_braille._io import atomic_path
from tactile_braille.agents.config import TrainConfig, differences
from tactile_braille.envs.registry import task_name

CONFIG_FILE = "config.json"
WORLD_FILE = "world.json"
"""Where a run records the world it learns in (:attr:`BrailleEnv.world`)."""
CHECKPOINT_FILE = "checkpoint.pt"
PROGRESS_FILE = "progress.csv"
PROGRESS_FIELDS = (
    "epoch", "env_steps", "updates", "train/episodes", "train/episodic_return", "test/episodic_return",
    "test/episode_length", "test/success_rate",
)  # fmt: skip
"""The columns every run's ``progress.csv`` starts with; what the agent's updates return (``losses/...``,
``charts/...``) follows, in the order first logged, then :data:`TIMING_FIELDS`."""
TIMING_FIELDS = ("charts/SPS", "time_s")
"""The last columns: environment steps per second of training, and the epoch's seconds."""


@dataclass
class Counters:
    """Where a run stands: the next epoch to run, environment steps and gradient updates so far, and
    what the training loop carries across epochs: the episode in progress
    (:meth:`~tactile_braille.agents.training.Episodes.state`) and the last value of each loss."""

    epoch: int = 0
    env_steps: int = 0
    updates: int = 0
    episode: dict | None = None
    losses: dict = field(default_factory=dict)


LOCK_FILE = ".lock"
"""Held (``flock``) by the one process writing the run: a second writer is refused."""
MACHINE_SETTINGS = ("epochs", "device", "threads", "dataset")
"""Settings a resume may change: how far the run goes, and where it runs (where the dataset lies: the
world record checks what it holds)."""


def run_folder(config: TrainConfig | None, run_dir: str | Path | None, resume: bool) -> Path:
    """The run's folder: given, or for a new run ``runs/{task}__{algo}__{seed}__{time}``."""
    if run_dir is not None:
        return Path(run_dir)
    if resume:
        raise ValueError("resume needs the run folder")
    config = config or TrainConfig()
    stamp = time.strftime("%Y%m%d-%H%M%S")
    return Path(f"runs/{task_name(config.task)}__{config.algo}__{config.seed}__{stamp}")


def open_run(config: TrainConfig | None, run_dir: Path, resume: bool, rig=None) -> TrainConfig:
    """The run's settings: for a resume, the stored ones (with ``config``'s machine settings, if given:
    any other difference is refused; :func:`write_config` records them once the resume is under way);
    else ``config``, written to the new folder (after it is checked against the ``rig`` handed in, if
    any). Call it holding the run's lock (:data:`LOCK_FILE`)."""
    if resume:
        stored = read_config(run_dir)
        for stale in [*run_dir.glob(".*.tmp"), *run_dir.glob("snapshots/.*.tmp")]:
            stale.unlink()  # a writer killed mid-write left it (atomic writes go through such files)
        config = stored if config is None else _resumed(run_dir, stored, config)
        config.check_rig(rig)
        check_resumable(run_dir, config)
        return config
    config = config or TrainConfig()
    config.check_rig(rig)
    if (run_dir / CONFIG_FILE).exists():
        raise FileExistsError(f"{run_dir} holds a run already; resume it or choose another folder")
    run_dir.mkdir(parents=True, exist_ok=True)
    write_config(run_dir, config)
    return config


def write_config(run_dir: Path, config: TrainConfig) -> None:
    """Record the run's settings (atomically), where they are not recorded already."""
    path = run_dir / CONFIG_FILE
    if path.exists() and read_config(run_dir) == config:
        return
    with atomic_path(path) as temporary:
        temporary.write_text(json.dumps(config.to_json(), indent=2))


def _resumed(run_dir: Path, stored: TrainConfig, wanted: TrainConfig) -> TrainConfig:
    """The stored settings with ``wanted``'s machine settings; other differences are refused."""
    other = differences(stored, wanted, ignore=MACHINE_SETTINGS)
    if other:
        raise ValueError(
            f"{run_dir} was started with other settings ({'; '.join(other)}); a resume may change only "
            f"{', '.join(MACHINE_SETTINGS)}: start a new run for the others"
        )
    done = len(read_progress(run_dir)) if (run_dir / PROGRESS_FILE).exists() else 0
    if wanted.epochs < done:
        raise ValueError(
            f"{run_dir} has run {done} epochs already: --epochs {wanted.epochs} cannot shorten it"
        )
    return wanted


def check_resumable(run_dir: Path, config: TrainConfig) -> None:
    """Refuse a resume that would lose logged epochs: a checkpoint that was written but is gone.

    An epoch's row is logged before its checkpoint is written, so a run killed in between has one
    row more than its checkpoints cover; only a row beyond the first checkpoint's epoch proves that a
    checkpoint existed (a run killed before its first one starts again, losing nothing it had saved).
    """
    if (run_dir / CHECKPOINT_FILE).exists() or not (run_dir / PROGRESS_FILE).exists():
        return
    logged = len(read_progress(run_dir))
    if logged > min(config.checkpoint_every, config.epochs):
        raise ValueError(
            f"{run_dir} logged {logged} epochs but has no {CHECKPOINT_FILE} (deleted or moved?): resuming "
            f"would start again at epoch 0 and drop them. Put the checkpoint back, start a new run, or "
            f"delete {run_dir / PROGRESS_FILE} to train this one again from scratch"
        )


def read_config(run_dir: str | Path) -> TrainConfig:
    """A run's settings (config.json files of every version of the format are read)."""
    try:
        return TrainConfig.from_json(json.loads((Path(run_dir) / CONFIG_FILE).read_text()))
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise ValueError(f"{run_dir} is not a resumable run: {error}") from None


def setting_differences(run_dir: str | Path, config: TrainConfig) -> list[str]:
    """The settings, epochs aside, in which the run in ``run_dir`` differs from ``config``
    (``name: stored -> wanted``, dotted names for grouped settings).

    The stored config.json is read through :class:`TrainConfig`, so a run written before a setting
    existed compares with that setting's default (the behaviour it was trained with).
    """
    return differences(read_config(run_dir), config, ignore=("epochs",))


# ------------------------------------------------------------------ the world
def record_world(run_dir: Path, env, resume: bool) -> None:
    """Write the run's world, or check that a resumed run continues in the world it started in.

    The record is the environment's :attr:`~tactile_braille.envs.braille_env.BrailleEnv.world` with,
    on the dataset backend, the dataset's samples digest always (the world names a reference dataset
    by its parameters alone), so that a resume on other samples of the same parameters is refused. A
    run from before worlds were recorded is resumed without a record: what it started in is unknown,
    and recording the present world would claim it.
    """
    from tactile_braille.envs.braille_env import BrailleEnv

    if not isinstance(env.unwrapped, BrailleEnv):  # goal-conditioned toys have no tactile world
        return
    world = json.loads(json.dumps(env.unwrapped.world))  # as stored: tuples become lists
    if env.unwrapped.dataset is not None:
        world["samples_sha256"] = env.unwrapped.dataset.samples_sha256
    path = run_dir / WORLD_FILE
    if path.exists():
        stored = json.loads(path.read_text())
        stored.pop("dataset", None)  # where the dataset lies may change; what it holds may not
        if stored.get("backend") == "rig" and world.get("backend") == "render":
            stored["backend"] = "render"  # recorded before the render backend named itself: the same world
        if "samples_sha256" not in stored:  # recorded before runs recorded their samples' digest
            world.pop("samples_sha256", None)
        differ = json_differences(stored, {k: v for k, v in world.items() if k != "dataset"})
        if differ:
            shown = "; ".join(differ[:3]) + (f"; and {len(differ) - 3} more" if len(differ) > 3 else "")
            raise ValueError(
                f"{run_dir} was trained in another world than this one ({shown}); "
                "start a new run instead of resuming it"
            )
        return
    if resume and (run_dir / CHECKPOINT_FILE).exists():
        return
    with atomic_path(path) as temporary:
        temporary.write_text(json.dumps(world, indent=2, sort_keys=True))


def json_differences(stored, now, path: str = "") -> list[str]:
    """``path: stored -> now`` for each leaf in which two JSON values differ."""
    if isinstance(stored, dict) and isinstance(now, dict):
        return [
            line
            for key in sorted(set(stored) | set(now))
            for line in json_differences(stored.get(key), now.get(key), f"{path}.{key}" if path else key)
        ]
    return [] if stored == now else [f"{path or 'world'}: {json.dumps(stored)} -> {json.dumps(now)}"]


def run_world(run_dir: str | Path) -> dict | None:
    """The world a run recorded, or ``None`` for a run from before worlds were recorded."""
    path = Path(run_dir) / WORLD_FILE
    return json.loads(path.read_text()) if path.exists() else None


# ------------------------------------------------------------------ checkpoints
def save_checkpoint(run_dir: Path, agent, buffer, rng: np.random.Generator, counters: Counters) -> None:
    """Write the replay buffer, then the checkpoint that names it, then drop older buffers.

    ``counters.epoch`` is the epoch just finished. Each step is atomic, so a
    crash anywhere leaves the previous checkpoint and the buffer it names
    intact. The checkpoint holds every generator the loop draws from (the
    run's, torch's) and the episode in progress as the loop records it
    (``counters.episode``: its reset and its actions so far), which a resume
    plays again, so that it goes on as the uninterrupted run did.
    """
    replay = f"replay.{counters.epoch}.npz"
    buffer.save(run_dir / replay)
    with open(run_dir / PROGRESS_FILE, newline="") as handle:  # the row of this epoch is logged already
        rows = [row for row in csv.DictReader(handle) if int(row["epoch"]) <= counters.epoch]
    state = {
        "agent": agent.state_dict(), "rng": rng.bit_generator.state, "torch_rng": torch.get_rng_state(),
        "cuda_rng": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else None,
        "epoch": counters.epoch, "env_steps": counters.env_steps, "updates": counters.updates,
        "replay": replay, "progress_rows": len(rows), "progress_sha256": progress_digest(rows),
        "episode": counters.episode, "losses": dict(counters.losses),
    }  # fmt: skip
    with atomic_path(run_dir / CHECKPOINT_FILE, fsync=True) as temporary:
        torch.save(state, temporary)
    for old in run_dir.glob("replay.*.npz"):
        if old.name != replay:
            old.unlink()


def restore_checkpoint(run_dir: Path, agent, buffer, rng: np.random.Generator) -> Counters:
    """Load the last checkpoint into the agent, the replay buffer and the generators; the counters to
    continue from (a fresh start's if the run has no checkpoint yet). A damaged checkpoint or replay
    file is refused (a ValueError naming it) before anything is changed on disk."""
    path = run_dir / CHECKPOINT_FILE
    if not path.exists():
        return Counters()
    state = read_checkpoint_file(path, agent.device)
    try:
        counters = Counters(int(state["epoch"]) + 1, int(state["env_steps"]), int(state["updates"]),
                            state.get("episode"), dict(state.get("losses", {})))  # fmt: skip
        agent.load_state_dict(state["agent"])
    except Exception as error:  # a checkpoint of another agent, or one missing its entries
        raise _unreadable(path, error) from None
    rng.bit_generator.state = state["rng"]
    torch.set_rng_state(state["torch_rng"].cpu())
    if state.get("cuda_rng") is not None and torch.cuda.is_available():
        torch.cuda.set_rng_state_all([s.cpu() for s in state["cuda_rng"]])
    try:
        buffer.load(run_dir / state["replay"])
    except Exception as error:  # a missing file, a damaged zip, arrays of another shape
        raise ValueError(
            f"{run_dir / state['replay']} (the replay buffer {path.name} names) is unreadable "
            f"({type(error).__name__}: {str(error)[:120]}): restore it from a copy, or start a new run"
        ) from None
    return counters


def read_checkpoint_file(path: Path, device, mmap: bool = False) -> dict:
    """A checkpoint's contents, or a ValueError naming it where it is unreadable."""
    try:
        state = torch.load(path, weights_only=False, map_location=device, mmap=mmap)
        int(state["epoch"])
        return state
    except Exception as error:  # torch raises many kinds on a truncated or foreign file
        raise _unreadable(path, error) from None


def _unreadable(path: Path, error: Exception) -> ValueError:
    return ValueError(
        f"{path} is unreadable ({type(error).__name__}: {str(error)[:120]}); it is truncated, damaged or "
        "not a checkpoint of this run: restore it from a copy, or start a new run"
    )


# ------------------------------------------------------------------ warm starts
INIT_FILE = "init.json"
"""What a warm-started run (``init_from``) took from its source run."""
INIT_FREE = (
    "seed", "epochs", "steps_per_epoch", "start_steps", "update_after", "backend", "frame_noise", "edges",
    "tap_depth", "key_grid", "dataset", "device", "precision", "threads", "checkpoint_every", "init_from",
    "preset", "replay.", "evaluation.",
)  # fmt: skip
"""Settings in which a warm-started run may differ from its source (names ending in a dot: a whole
group): where it learns and for how long; the learner itself (task, algorithm, networks, touch
encoder, hyperparameters, track) must be the source's."""


def check_init_from(config: TrainConfig, run_dir: Path) -> None:
    """Refuse a warm start (``config.init_from``) that cannot run, before anything is written: a source
    that holds no run or no checkpoint, the run's own folder, or a source learner other than this one."""
    if config.init_from is None:
        return
    source = Path(config.init_from)
    if not (source / CONFIG_FILE).exists():
        raise ValueError(f"init_from {source}: no training run there (no {CONFIG_FILE})")
    if source.resolve() == Path(run_dir).resolve():
        raise ValueError(f"init_from {source} is this run's own folder: resume it instead (--resume)")
    other = _init_differences(read_config(source), config)
    if other:
        listed = "; ".join(line if len(line) <= 80 else line[:77] + "..." for line in other[:3])
        more = f"; and {len(other) - 3} more" if len(other) > 3 else ""
        raise ValueError(
            f"init_from {source} learnt with other settings ({listed}{more}): a warm start may change only "
            "where and how long it learns (world, seed, length, replay, evaluation, machine); start from a "
            "run of the same task, algorithm and hyperparameters"
        )
    if not (source / CHECKPOINT_FILE).exists():
        raise ValueError(f"init_from {source}: the run has no {CHECKPOINT_FILE} to start from")
    _source_checkpoint(source, "cpu")
    if not (source / PROGRESS_FILE).exists():
        raise ValueError(f"init_from {source}: the run has no {PROGRESS_FILE}")


def _init_differences(source: TrainConfig, config: TrainConfig) -> list[str]:
    """The settings in which a warm start's source differs from it beyond :data:`INIT_FREE`, the task
    and algorithm first, then other top-level settings, then grouped ones (another algorithm's
    hyperparameters all differ: they go unlisted)."""
    free = tuple(name for name in INIT_FREE if not name.endswith("."))
    groups = tuple(name for name in INIT_FREE if name.endswith("."))
    other = [line for line in differences(source, config, ignore=free) if not line.startswith(groups)]
    if any(line.startswith("algo:") for line in other):
        other = [line for line in other if not line.startswith("agent.")]
    return sorted(other, key=lambda line: (line.partition(":")[0] not in ("algo", "task"),
                                           "." in line.partition(":")[0]))  # fmt: skip


def _source_checkpoint(source: Path, device) -> dict:
    """A warm start's source checkpoint, or a ValueError naming it where it is unreadable."""
    path = source / CHECKPOINT_FILE
    try:
        state = torch.load(path, weights_only=False, map_location=device)
        return {"agent": state["agent"], "epoch": int(state["epoch"]), "env_steps": int(state["env_steps"]),
                "updates": int(state["updates"])}  # fmt: skip
    except Exception as error:  # torch raises many kinds on a truncated or foreign file
        raise ValueError(
            f"init_from {path} is unreadable ({type(error).__name__}: {str(error)[:120]})"
        ) from None


def warm_start(run_dir: Path, config: TrainConfig, agent) -> None:
    """Load the source run's last checkpointed agent (:func:`check_init_from` has passed) and record
    in ``init.json`` what was taken: its epochs, steps, test returns and world."""
    source = Path(config.init_from)
    state = _source_checkpoint(source, agent.device)
    agent.load_state_dict(state["agent"])
    epochs = state["epoch"] + 1
    record = {
        "run": str(source), "seed": read_config(source).seed, "epochs": epochs,
        "env_steps": state["env_steps"], "updates": state["updates"],
        "test_returns": [row["test/episodic_return"] for row in read_progress(source)[:epochs]],
        "world": run_world(source),
    }  # fmt: skip
    with atomic_path(run_dir / INIT_FILE) as temporary:
        temporary.write_text(json.dumps(record, indent=2))


def snapshot_epochs(epochs: int, snapshots: int) -> set[int]:
    """Epochs after which a policy snapshot is kept: ``snapshots`` of them, first to last."""
    if snapshots <= 0:
        return set()
    return {round(float(e)) for e in np.linspace(0, epochs - 1, min(snapshots, epochs))}


def save_snapshot(run_dir: Path, agent, epoch: int) -> None:
    """The policy after ``epoch`` (what acting needs, for the trajectory figure)."""
    (run_dir / "snapshots").mkdir(exist_ok=True)
    with atomic_path(run_dir / "snapshots" / f"epoch_{epoch:04d}.pt") as temporary:
        torch.save(agent.policy_state_dict(), temporary)


# ------------------------------------------------------------------ the epoch log
class EpochLog:
    """Where each epoch's row goes: ``progress.csv``, TensorBoard (when installed) and a progress bar.

    A context manager: leaving it closes the writer and the bar.
    """

    def __init__(
        self, run_dir: Path, epochs: int, start_epoch: int, progress: bool, resumed_at: int | None = None
    ) -> None:
        """``resumed_at``: for a resume, the environment steps of its checkpoint."""
        self.path = run_dir / PROGRESS_FILE
        self.writer = _tensorboard(run_dir, resumed_at)
        self.bar = None
        if progress:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=epochs, initial=start_epoch, desc=run_dir.name, unit="epoch")

    def __enter__(self) -> EpochLog:
        return self

    def __exit__(self, *exc) -> None:
        if self.bar is not None:
            self.bar.close()
        if self.writer is not None:
            self.writer.close()

    def write(self, row: dict) -> None:
        """Log one epoch (its ``env_steps`` is TensorBoard's step)."""
        append_progress(self.path, row)
        if self.writer is not None:
            for key, value in row.items():
                if "/" in key:
                    name = key if key.startswith(("charts", "losses")) else f"charts/{key}"
                    self.writer.add_scalar(name, value, row["env_steps"])
            self.writer.flush()
        if self.bar is not None:
            self.bar.set_postfix(
                test_return=f"{row['test/episodic_return']:.2f}", sps=f"{row['charts/SPS']:.0f}"
            )
            self.bar.update(1)


def _tensorboard(run_dir: Path, resumed_at: int | None):
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError:  # TensorBoard is optional; the CSV log is always written
        return None
    # A resume drops what was logged after its checkpoint (epochs that are run again).
    return SummaryWriter(str(run_dir), purge_step=None if resumed_at is None else resumed_at + 1)


def read_progress(run_dir: str | Path) -> list[dict[str, float]]:
    """The run's per-epoch log as a list of rows (numbers as floats, blanks as NaN).

    A log that cannot be the run's whole history is refused (a ValueError that says what is wrong and
    how to recover): a torn last row (an incomplete line), a row with the wrong number of fields, epochs
    not 0, 1, 2, ... in order (rows lost or repeated), or, where the run has a checkpoint, fewer rows
    than it covers or rows that differ from the digest it recorded of them (checkpoints from before
    digests record only their epoch). Rows after the checkpoint (epochs a resume runs again) are normal.
    A record without a checkpoint (an archived run under ``results/``) gets the first checks.
    """
    return [
        {key: float(value) if value != "" else float("nan") for key, value in row.items()}
        for row in _checked_rows(Path(run_dir))
    ]


def check_progress(run_dir: str | Path) -> None:
    """Refuse a run whose log is damaged (:func:`read_progress`'s checks), or missing though its
    checkpoint covers logged epochs: before a resume changes anything."""
    run_dir = Path(run_dir)
    if (run_dir / PROGRESS_FILE).exists():
        _checked_rows(run_dir)
        return
    covered, _ = _checkpoint_covers(run_dir)
    if covered:
        raise ValueError(
            f"{run_dir} has no {PROGRESS_FILE}, but its {CHECKPOINT_FILE} holds epoch {covered - 1}: its "
            f"epochs' rows cannot be recreated: restore {PROGRESS_FILE} from a backup or start the run again"
        )


def progress_digest(rows: list[dict[str, str]]) -> str:
    """SHA-256 of logged rows as written (every column, the timing ones included). A column first
    logged in a later epoch is blank in the earlier rows: blanks are left out, so a row's digest never
    changes once it is written."""
    text = json.dumps([{k: v for k, v in row.items() if v != ""} for row in rows], sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def _checkpoint_covers(run_dir: Path) -> tuple[int, str | None]:
    """How many rows of the log the run's checkpoint covers (0 without one), and their digest (None
    for a checkpoint from before digests)."""
    path = run_dir / CHECKPOINT_FILE
    if not path.exists():
        return 0, None
    state = read_checkpoint_file(path, "cpu", mmap=True)  # mapped, not read: the networks are not needed
    return int(state.get("progress_rows", int(state["epoch"]) + 1)), state.get("progress_sha256")


def _checked_rows(run_dir: Path) -> list[dict[str, str]]:
    """The log's rows as written (strings), after :func:`read_progress`'s checks."""
    path = run_dir / PROGRESS_FILE
    text = path.read_bytes().decode("utf-8", errors="replace")
    rows = list(csv.DictReader(io.StringIO(text, newline="")))
    covered, digest = _checkpoint_covers(run_dir)

    def refuse(problem: str, first_bad: int) -> ValueError:
        if covered and first_bad >= covered:  # only rows after the checkpoint: a resume runs them again
            recovery = (
                f"delete its rows from epoch {covered} on and resume (--resume runs them again); or "
                f"restore {PROGRESS_FILE} from a backup"
            )
        else:
            recovery = "those rows cannot be recreated: "
            recovery += f"restore {PROGRESS_FILE} from a backup or start the run again"
        return ValueError(f"{path} {problem}; {recovery}")

    if text and not text.endswith("\n"):
        raise refuse(
            "is damaged: its last row is torn (an incomplete CSV line: cut while copied?)", len(rows) - 1
        )
    for index, row in enumerate(rows):
        if None in row or None in row.values():
            raise refuse(f"is damaged: line {index + 2} has another number of fields than the header", index)
        try:
            epoch = float(row["epoch"])
            for value in row.values():
                if value != "":
                    float(value)
        except (KeyError, ValueError):
            raise refuse(f"is damaged: line {index + 2} holds a value that is not a number", index) from None
        if epoch != index:
            lost = f"is damaged: line {index + 2} logs epoch {row['epoch']}, not {index}"
            lost += ": rows were lost or repeated"
            raise refuse(lost, index)
    if len(rows) < covered:
        raise refuse(
            f"has {len(rows)} rows, but {CHECKPOINT_FILE} holds epoch {covered - 1} ({covered} rows): rows "
            "were lost (truncated?)",
            len(rows),
        )
    if digest is not None and progress_digest(rows[:covered]) != digest:
        raise refuse(
            f"is damaged: its first {covered} rows differ from those {CHECKPOINT_FILE} recorded (edited?)", 0
        )
    return rows


def append_progress(path: Path, row: dict) -> None:
    """Append one epoch to the CSV log (rows of epochs already logged are replaced on resume)."""
    rows = []
    if path.exists():
        with open(path, newline="") as handle:
            rows = [r for r in csv.DictReader(handle) if int(r["epoch"]) < row["epoch"]]
    rows.append(row)
    logged = dict.fromkeys(name for logged_row in rows for name in logged_row)
    fields = [
        *PROGRESS_FIELDS,
        *(n for n in logged if n not in (*PROGRESS_FIELDS, *TIMING_FIELDS)),
        *TIMING_FIELDS,
    ]
    with atomic_path(path) as temporary, open(temporary, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=fields, restval="")
        writer.writeheader()
        writer.writerows(rows)
