"""Results files: one agent's typing report on one task for one training seed, as JSON that outlives
the machine it was made on (the format is documented in docs/benchmark.md).

A results file is checked, not trusted, when it is read: every number must be of its kind, finite and
in range and agree with the rest of the file (the accuracy with the confusion matrix, the keys with
the sequences the conditions name, the steps with the keys and the episode limit and, for a file that
typed every key right, with the fewest steps the world allows), and the file must match its **seal**:
a SHA-256 digest of each field, taken when it was made (:func:`make_result`), so an edit made after it
was written is refused with the field it changed. The seal guards against accidents (a hand edit, a
merge, a script that rewrote a number); it is not a signature, since anyone can seal a file again.

>>> sorted(REQUIRED)
['budget', 'fingerprint', 'format', 'method', 'report', 'seal', 'seed', 'task', 'track']
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

from tactile_braille._io import atomic_path
from tactile_braille._version import __version__
from tactile_braille.evaluation.scoring import TRACKS, TypingReport, fingerprint

RESULT_FORMAT = "tactile_braille.result/2"
"""The format written and read; files of ``/1`` (unsealed) are refused with how to score them again."""
REQUIRED = ("format", "method", "task", "track", "seed", "budget", "fingerprint", "report", "seal")
CONDITIONS = {"task", "protocol", "sequences", "max_episode_steps", "start_seed", "world", "project_version"}
"""What a report's conditions (what its fingerprint hashes) must name."""
REPORT_FIELDS = frozenset({"task", "protocol", "track", "accuracy", "total_steps", "keys_asked", "sequences",
                           "fingerprint", "conditions", "confusion", "touch_optimum", "sentences",
                           "steps_per_key"})  # fmt: skip
"""What every report holds (``typing_bound`` too, in files written since it was added)."""
SEAL_DIGITS = 16
"""Hexadecimal digits of each field's SHA-256 kept in a seal."""
TOLERANCE = 1e-9
"""How far a recorded accuracy or steps per key may sit from the value recomputed from its counts."""


def make_result(
    report: TypingReport,
    *,
    method: str,
    seed: int | None = None,
    env_steps: int | None = None,
    epochs: int | None = None,
    notes: str = "",
    tuning: dict | None = None,
) -> dict:
    """A results file's content, checked and sealed: the report, who made it (``method``: free text),
    the training ``seed`` and budget (environment steps, and epochs of 250 steps where the method
    counts them), and for a method whose settings a search chose, the search (``tuning``: its space,
    trials and choice; ``trials``, the number finished, is what the leaderboard shows)."""
    if not method.strip():
        raise ValueError("a result needs a method name (free text, e.g. 'SB3 DQN + HER')")
    result = {
        "format": RESULT_FORMAT, "method": method.strip(), "task": report.task, "track": report.track,
        "seed": seed, "budget": {"env_steps": env_steps, "epochs": epochs}, "notes": notes,
        "fingerprint": report.fingerprint, "project_version": __version__, "report": report.to_dict(),
        **({"tuning": tuning} if tuning is not None else {}),
    }  # fmt: skip
    result = json.loads(json.dumps(result))  # as it will be read back: tuples as lists, keys as strings
    check_content(result, f"the result of {result['method']}")
    return {**result, "seal": seal(result)}


def seal(result: dict) -> dict[str, str]:
    """A digest of each field of ``result`` (the report's fields one by one: ``report.accuracy``), the
    seal itself aside: the first :data:`SEAL_DIGITS` hexadecimal digits of the SHA-256 of the field's
    canonical JSON (sorted keys, no spaces)."""
    return {name: _digest(value) for name, value in _sealed_fields(result)}


def _sealed_fields(result: dict):
    for name, value in result.items():
        if name == "seal":
            continue
        if name == "report" and isinstance(value, dict):
            yield from ((f"report.{key}", item) for key, item in value.items())
        else:
            yield name, value


def _digest(value) -> str:
    text = json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()[:SEAL_DIGITS]


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
    """``result`` if it is a well-formed, consistent and sealed results file (the module docstring),
    else a ValueError naming what is wrong."""
    if not isinstance(result, dict) or result.get("format") != RESULT_FORMAT:
        found = result.get("format") if isinstance(result, dict) else type(result).__name__
        if found == "tactile_braille.result/1":
            raise ValueError(f"{where} is a results file of format {found!r}, written before results files "
                             "were sealed: score the policy again (`tactile-braille evaluate`) to write it "
                             f"in format {RESULT_FORMAT!r}")  # fmt: skip
        raise ValueError(f"{where} is not a results file of format {RESULT_FORMAT!r} (found {found!r})")
    missing = [name for name in REQUIRED if name not in result]
    if missing:
        raise ValueError(f"{where} lacks {missing}")
    check_content(result, where)
    _check_seal(result, where)
    return result


def _check_seal(result: dict, where: str) -> None:
    recorded = result["seal"]
    if not isinstance(recorded, dict):
        kind = type(recorded).__name__
        raise ValueError(f"{where}: its seal must be an object of field digests, got a {kind}")
    found = seal(result)
    sealed = {*REQUIRED, *(f"report.{name}" for name in REPORT_FIELDS)} - {"seal", "report"}
    unsealed = sorted(sealed - set(recorded))
    if unsealed:
        raise ValueError(f"{where}: its seal lacks {unsealed} (edited?); score the policy again")
    added = sorted(set(found) - set(recorded))
    removed = sorted(set(recorded) - set(found))
    changed = [name for name in found if name in recorded and recorded[name] != found[name]]
    for problem, names in (("were added", added), ("were removed", removed), ("were changed", changed)):
        if names:
            raise ValueError(f"{where}: fields {names} {problem} after the file was sealed (edited?); "
                             "score the policy again to write a new results file")  # fmt: skip


def check_content(result: dict, where: str) -> None:
    """ValueErrors for a result whose fields are of the wrong kind or disagree with each other."""
    if result["track"] not in TRACKS:
        raise ValueError(f"{where}: track must be one of {TRACKS}, got {result['track']!r}")
    if not isinstance(result["method"], str) or not result["method"].strip():
        raise ValueError(f"{where}: method must be a non-empty string, got {result['method']!r}")
    _check_count(result["seed"], "seed", where, none=True)
    budget = result["budget"]
    if not isinstance(budget, dict) or set(budget) != {"env_steps", "epochs"}:
        raise ValueError(f"{where}: budget must be an object with env_steps and epochs")
    for name, value in budget.items():
        _check_count(value, f"budget.{name}", where, none=True)
    if not isinstance(result["report"], dict):
        raise ValueError(f"{where}: its report must be an object, got {type(result['report']).__name__}")
    missing = sorted(REPORT_FIELDS - set(result["report"]))
    if missing:
        raise ValueError(f"{where}: its report lacks {missing}")
    try:
        report = TypingReport.from_dict(result["report"])
    except (TypeError, ValueError) as error:
        raise ValueError(f"{where}: its report is malformed ({error})") from None
    conditions = report.conditions
    if not isinstance(conditions, dict) or not set(conditions) >= CONDITIONS:
        raise ValueError(f"{where}: its report's conditions lack what a fingerprint covers")
    if fingerprint(conditions) != report.fingerprint or result["fingerprint"] != report.fingerprint:
        raise ValueError(f"{where}: its fingerprint does not match the conditions it records (edited?)")
    if (report.task, report.track) != (result["task"], result["track"]):
        raise ValueError(f"{where}: its task or track differs from its report's")
    if (conditions["task"], conditions["protocol"]) != (report.task, report.protocol):
        raise ValueError(f"{where}: its task or protocol differs from the conditions it was scored under")
    _check_report(report, result["report"], where)


def _check_count(value, name: str, where: str, none: bool = False) -> None:
    if value is None and none:
        return
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ValueError(f"{where}: {name} must be a non-negative integer{' or null' if none else ''}, "
                         f"got {value!r}")  # fmt: skip


def _check_fraction(value, name: str, where: str) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not 0 <= value <= 1:
        raise ValueError(f"{where}: {name} must be a number in [0, 1], got {value!r}")


def _check_report(report: TypingReport, recorded: dict, where: str) -> None:
    """The report's numbers checked against each other and against the conditions they were scored under."""
    sequences, limit = report.conditions["sequences"], report.conditions["max_episode_steps"]
    listed = isinstance(sequences, list) and all(isinstance(s, list) and s for s in sequences)
    if not listed or not sequences:
        raise ValueError(f"{where}: report.conditions.sequences must be a non-empty list of key sequences")
    _check_count(limit, "report.conditions.max_episode_steps", where)
    for name in ("total_steps", "keys_asked", "sequences"):
        _check_count(getattr(report, name), f"report.{name}", where)
    _check_fraction(report.accuracy, "report.accuracy", where)
    keys = sum(map(len, sequences))
    if (report.keys_asked, report.sequences) != (keys, len(sequences)):
        raise ValueError(f"{where}: report.keys_asked and report.sequences ({report.keys_asked}, "
                         f"{report.sequences}) differ from the {keys} keys in {len(sequences)} sequences its "
                         "conditions name")  # fmt: skip
    if not keys <= report.total_steps <= keys * limit:
        raise ValueError(f"{where}: report.total_steps ({report.total_steps}) must lie between the keys "
                         f"asked ({keys}: a step each at least) and keys x episode limit "
                         f"({keys * limit})")  # fmt: skip
    steps_per_key = recorded.get("steps_per_key", report.steps_per_key)
    if not isinstance(steps_per_key, int | float) or abs(steps_per_key - report.steps_per_key) > TOLERANCE:
        raise ValueError(f"{where}: report.steps_per_key ({steps_per_key!r}) is not total_steps / keys_asked "
                         f"({report.steps_per_key})")  # fmt: skip
    right = _confusion_right(report.confusion, sequences, where)
    if abs(report.accuracy - right / keys) > TOLERANCE:
        raise ValueError(f"{where}: report.accuracy ({report.accuracy}) contradicts its confusion matrix "
                         f"({right} of {keys} keys right: {right / keys})")  # fmt: skip
    for name in ("touch_optimum", "typing_bound"):
        value = getattr(report, name)
        if value is not None and (isinstance(value, bool) or not isinstance(value, int | float)
                                  or not math.isfinite(value) or value < 0):  # fmt: skip
            raise ValueError(f"{where}: report.{name} must be a non-negative number or null, got {value!r}")
    bound = report.typing_bound
    all_right = right == keys and report.protocol == "paper"  # a wrong press can take fewer steps
    if all_right and bound is not None and report.total_steps < bound - 1e-6:
        raise ValueError(f"{where}: report.total_steps ({report.total_steps}) is below the fewest steps the "
                         f"world allows for typing every key right ({bound})")  # fmt: skip
    for index, sentence in enumerate(report.sentences or []):
        if not isinstance(sentence, dict):
            raise ValueError(f"{where}: report.sentences[{index}] must be an object")
        _check_fraction(sentence.get("accuracy"), f"report.sentences[{index}].accuracy", where)
        _check_count(sentence.get("steps"), f"report.sentences[{index}].steps", where)


def _confusion_right(confusion, sequences, where: str) -> int:
    """The keys typed right by the confusion matrix, once its counts are checked against the goals the
    sequences ask."""
    try:
        rows, columns, counts = confusion["rows"], confusion["columns"], confusion["counts"]
        shape_ok = len(counts) == len(rows) and all(len(row) == len(columns) for row in counts)
    except (TypeError, KeyError):
        shape_ok = False
    if not shape_ok:
        raise ValueError(f"{where}: report.confusion must hold rows, columns and counts of rows x columns")
    if not all(isinstance(c, int) and not isinstance(c, bool) and c >= 0 for row in counts for c in row):
        raise ValueError(f"{where}: report.confusion.counts must be non-negative integers")
    asked = {key: sum(s.count(key) for s in sequences) for key in rows}
    if sum(asked.values()) != sum(map(len, sequences)):
        raise ValueError(f"{where}: report.confusion.rows lack keys its sequences ask")
    for key, row in zip(rows, counts, strict=True):
        if sum(row) != asked[key]:
            raise ValueError(f"{where}: report.confusion counts {sum(row)} goals {key!r}, its sequences ask "
                             f"{asked[key]}")  # fmt: skip
    return sum(row[columns.index(key)] for key, row in zip(rows, counts, strict=True) if key in columns)
