"""Results files: one agent's typing report on one task for one training seed, as JSON that outlives
the machine it was made on (the format is documented in docs/benchmark.md).

>>> sorted(REQUIRED)
['budget', 'fingerprint', 'format', 'method', 'report', 'seed', 'task', 'track']
"""

from __future__ import annotations

import json
from pathlib import Path

from tactile_braille._io import atomic_path
from tactile_braille._version import __version__
from tactile_braille.evaluation.scoring import TRACKS, TypingReport, fingerprint

RESULT_FORMAT = "tactile_braille.result/1"
REQUIRED = ("format", "method", "task", "track", "seed", "budget", "fingerprint", "report")
CONDITIONS = {"task", "protocol", "sequences", "max_episode_steps", "start_seed", "world", "project_version"}
"""What a report's conditions (what its fingerprint hashes) must name."""


def make_result(
    report: TypingReport,
    *,
    method: str,
    seed: int | None = None,
    env_steps: int | None = None,
    epochs: int | None = None,
    notes: str = "",
) -> dict:
    """A results file's content: the report, who made it (``method``: free text), the training
    ``seed`` and budget (environment steps, and epochs of 250 steps where the method counts them)."""
    if not method.strip():
        raise ValueError("a result needs a method name (free text, e.g. 'SB3 DQN + HER')")
    for name, value in (("seed", seed), ("env_steps", env_steps), ("epochs", epochs)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 0):
            raise ValueError(f"{name} must be a non-negative integer or None, got {value!r}")
    return {
        "format": RESULT_FORMAT, "method": method.strip(), "task": report.task, "track": report.track,
        "seed": seed, "budget": {"env_steps": env_steps, "epochs": epochs}, "notes": notes,
        "fingerprint": report.fingerprint, "project_version": __version__, "report": report.to_dict(),
    }  # fmt: skip


def write_result(result: dict, path: str | Path, overwrite: bool = False) -> Path:
    """Write a results file (atomically); an existing file is replaced only with ``overwrite``."""
    check_result(result, str(path))
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(
            f"{path} is a folder; name the results file to write (e.g. {path}/result.json)"
        )
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; choose another name or pass overwrite (--overwrite)")
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as temporary:
        temporary.write_text(json.dumps(result, indent=2) + "\n")
    return path


def read_result(path: str | Path) -> dict:
    """A results file, checked: its format, its fields, and a fingerprint that matches its conditions."""
    path = Path(path)
    try:
        result = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ValueError(f"{path} is not a readable results file ({error})") from None
    return check_result(result, str(path))


def check_result(result, where: str) -> dict:
    """``result`` if it is a well-formed results file, else a ValueError naming what is wrong."""
    if not isinstance(result, dict) or result.get("format") != RESULT_FORMAT:
        found = result.get("format") if isinstance(result, dict) else type(result).__name__
        raise ValueError(f"{where} is not a results file of format {RESULT_FORMAT!r} (found {found!r})")
    missing = [name for name in REQUIRED if name not in result]
    if missing:
        raise ValueError(f"{where} lacks {missing}")
    if result["track"] not in TRACKS:
        raise ValueError(f"{where}: track must be one of {TRACKS}, got {result['track']!r}")
    try:
        report = TypingReport.from_dict(result["report"])
    except (TypeError, ValueError) as error:
        raise ValueError(f"{where}: its report is malformed ({error})") from None
    if fingerprint(report.conditions) != report.fingerprint or result["fingerprint"] != report.fingerprint:
        raise ValueError(f"{where}: its fingerprint does not match the conditions it records (edited?)")
    if (report.task, report.track) != (result["task"], result["track"]):
        raise ValueError(f"{where}: its task or track differs from its report's")
    conditions = report.conditions
    if not isinstance(conditions, dict) or not set(conditions) >= CONDITIONS:
        raise ValueError(f"{where}: its report's conditions lack what a fingerprint covers")
    if (conditions["task"], conditions["protocol"]) != (report.task, report.protocol):
        raise ValueError(f"{where}: its task or protocol differs from the conditions it was scored under")
    if not isinstance(result["budget"], dict):
        raise ValueError(f"{where}: budget must be an object with env_steps and epochs")
    return result
