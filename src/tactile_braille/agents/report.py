"""A run's report: a final evaluation of its last checkpoint, convergence figures and its curve.

``tactile-braille report RUN_DIR`` writes ``RUN_DIR/report.md`` and
``RUN_DIR/curve.png``. Convergence is given two ways: the paper's (the first
epoch whose test return reaches 95 % of the run's best) and a stricter,
absolute one (the first epoch whose test return reaches 0.95), which compares
across runs. A run that never reached 0.95 has not converged under either:
the paper's rule, relative to a low best, would give it an early epoch.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch

from tactile_braille._io import atomic_path
from tactile_braille.agents.config import TrainConfig
from tactile_braille.agents.rollout import evaluate
from tactile_braille.agents.run import CHECKPOINT_FILE, CONFIG_FILE, read_config, read_progress
from tactile_braille.agents.training import make_agent, make_env
from tactile_braille.envs.registry import task_name


def convergence_epoch(
    returns: list[float], fraction: float | None = 0.95, level: float | None = None
) -> int | None:
    """First epoch reaching ``fraction`` of the best return (the paper's rule) or an absolute ``level``.

    ``returns[i]`` is the test after epoch ``i + 1``, and epochs count from 1
    as the original release's logs count them (epoch 1 ends after the first
    250 steps), so the figure compares with the paper's Table III. None when
    never reached, and, under the paper's rule, for a run that never scored
    (its best is 0, which every epoch would "reach").
    """
    values = np.asarray(returns, dtype=float)
    if values.size == 0 or np.all(np.isnan(values)):
        return None
    if level is None and np.nanmax(values) <= 0:
        return None
    threshold = level if level is not None else fraction * np.nanmax(values)
    reached = np.flatnonzero(values >= threshold)
    return int(reached[0]) + 1 if reached.size else None


def read_checkpoint(run_dir: str | Path, device="cpu", mmap: bool = False) -> dict:
    """The run's last checkpoint; a one-line error where it is missing, or unreadable (truncated,
    damaged, not a checkpoint: the message a resume gives). ``mmap``: mapped, not read (a check)."""
    from tactile_braille.agents.run import read_checkpoint_file  # the resume's reading and message

    run_dir = Path(run_dir)
    if not (run_dir / CHECKPOINT_FILE).exists():
        raise FileNotFoundError(f"{run_dir} has no checkpoint yet")
    return read_checkpoint_file(run_dir / CHECKPOINT_FILE, device, mmap=mmap)


def check_run(run_dir: str | Path, checkpoint: bool = True) -> tuple[TrainConfig, list[dict[str, float]]]:
    """A run's settings and log, read as a report reads them; a one-line error for a folder that holds
    no run, a damaged log, and (``checkpoint``) a missing or unreadable checkpoint."""
    run_dir = Path(run_dir)
    if not (run_dir / CONFIG_FILE).exists():
        raise ValueError(f"{run_dir} is not a training run (no {CONFIG_FILE})")
    config = read_config(run_dir)
    if checkpoint:
        read_checkpoint(run_dir, mmap=True)
    rows = read_progress(run_dir)
    if checkpoint and not rows:
        raise ValueError(f"{run_dir} has no finished epoch to report")
    return config, rows


CONVERGED = 0.95
"""The test return a run must reach to have converged in its report (the stricter rule)."""


def _epoch_cell(epoch: int | None) -> str:
    return "not reached" if epoch is None else str(epoch)


def convergence_cell(returns: list[float]) -> str:
    """The report's convergence epoch under the paper's rule (the first epoch at 95 % of the run's best
    test return), and for a run whose test return never reached :data:`CONVERGED` the best it reached:
    95 % of a low best is reached early (a curve flat at 0.90 "converges" at once), and the
    paper's epochs are of runs that reached it."""
    epoch = _epoch_cell(convergence_epoch(returns))
    if convergence_epoch(returns, level=CONVERGED) is not None:
        return epoch
    best = np.nanmax(returns) if not np.all(np.isnan(returns)) else float("nan")
    return f"{epoch} (of a best test return of {best:.2f}: {CONVERGED} never reached)"


def load_run(run_dir: str | Path, env=None, **env_options):
    """The run's config, a fresh environment (``gym.make`` options in ``env_options``; or ``env``, one
    of the task made elsewhere), and its agent restored from the last checkpoint (a missing or damaged
    checkpoint is a one-line error, as for a resume)."""
    run_dir = Path(run_dir)
    config = read_config(run_dir)
    read_checkpoint(run_dir, mmap=True)  # before an environment is made
    torch.set_num_threads(config.threads)
    env = env if env is not None else make_env(config, **env_options)
    agent = make_agent(config, env)
    state = read_checkpoint(run_dir, agent.device)
    try:
        agent.load_state_dict(state["agent"])
    except Exception as error:  # a checkpoint of another agent, or one missing its entries
        raise ValueError(
            f"{run_dir / CHECKPOINT_FILE} does not fit the run's agent ({type(error).__name__}: "
            f"{str(error)[:120]}): restore it from a copy, or train the run again"
        ) from None
    return config, env, agent


def evaluate_run(run_dir: str | Path, episodes: int = 100, seed: int = 123_456) -> dict[str, float]:
    """Test episodes of the run's last checkpoint (the agent's test-time actions)."""
    _, env, agent = load_run(run_dir)
    return evaluate(agent, env, episodes, seed)


def write_report(run_dir: str | Path, episodes: int = 100) -> Path:
    """Evaluate the run, plot its curve and write ``report.md``; returns the report's path."""
    from tactile_braille._figures import new_figure, save_figure

    run_dir = Path(run_dir)
    config, rows = check_run(run_dir)
    returns = [row["test/episodic_return"] for row in rows]
    absolute_epoch = convergence_epoch(returns, level=CONVERGED)
    paper_epoch = convergence_epoch(returns) if absolute_epoch is not None else None
    final = evaluate_run(run_dir, episodes)

    fig, axes = new_figure(figsize=(6, 3.4))
    ax = axes[0, 0]
    epochs = [int(row["epoch"]) + 1 for row in rows]  # counted from 1, as the paper does
    ax.plot(epochs, returns, marker="o", markersize=3, label="test return (each epoch)")
    train_returns = [row["train/episodic_return"] for row in rows]
    ax.plot(epochs, train_returns, alpha=0.5, label="training return")
    if paper_epoch is not None:
        ax.axvline(
            paper_epoch, color="grey", linestyle="--", label=f"convergence (paper's rule): {paper_epoch}"
        )
    ax.set_xlabel("epoch (250 steps)")
    ax.set_ylabel("average return")
    ax.set_ylim(-0.05, 1.05)
    ax.set_title(f"{task_name(config.task)}, {config.algo}, seed {config.seed}")
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    save_figure(fig, run_dir / "curve.png")

    her = "on" if config.replay.her else "off"
    minutes = sum(row["time_s"] for row in rows if not math.isnan(row["time_s"])) / 60
    steps, updates = int(rows[-1]["env_steps"]), int(rows[-1]["updates"])
    lines = [
        f"# {task_name(config.task)} with {config.algo} (seed {config.seed})",
        "",
        f"Preset `{config.preset}`, {config.precision}, backend `{config.backend}`, HER {her}.",
        "",
        "| | |",
        "|---|---|",
        f"| epochs trained | {len(rows)} ({steps} env steps, {updates} updates) |",
        f"| convergence epoch, paper's rule (95 % of the best) | {convergence_cell(returns)} |",
        f"| first epoch with test return >= 0.95 | {_epoch_cell(absolute_epoch)} |",
        f"| best test return in training | {np.nanmax(returns):.2f} |",
        f"| final evaluation ({episodes} episodes) | return {final['test/episodic_return']:.3f}, "
        f"success {final['test/success_rate']:.3f}, length {final['test/episode_length']:.1f} steps |",
        f"| training time | {minutes:.1f} min |",
        "",
        "![curve](curve.png)",
        "",
    ]  # fmt: skip
    report = run_dir / "report.md"
    with atomic_path(report) as temporary:
        temporary.write_text("\n".join(lines))
    return report
