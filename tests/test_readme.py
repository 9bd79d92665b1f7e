"""The README as a newcomer uses it: short, its quick start runs as written, its commands exist."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from tactile_braille.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def _blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", README, flags=re.S)


def test_the_readme_is_short_and_opens_with_the_pitch_picture_and_commands():
    assert len(README.encode()) <= 10 * 1024
    sections = re.findall(r"^## (.+)$", README, flags=re.M)
    assert sections[:3] == ["Install, run, test", "Quick start", "The tasks"]
    assert README.index("docs/images/episode_") < README.index("## Install")
    assert "make run" in _blocks("bash")[0] and "make test" in _blocks("bash")[0]


def test_the_quick_start_runs_as_written(env_datasets, monkeypatch, tmp_path):
    """The README's Python block, run from a fresh folder (its run goes to runs/ there); the test datasets
    stand in for the default ones that a first run generates."""
    (quick_start,) = _blocks("python")
    import gymnasium as gym

    make = gym.make
    arrows = "tactile_braille/DiscreteArrows-v0"

    def make_with_test_data(env_id, **kwargs):
        if env_id == arrows and "dataset" not in kwargs and kwargs.get("backend", "dataset") == "dataset":
            kwargs["dataset"] = str(env_datasets[arrows])
        return make(env_id, **kwargs)

    monkeypatch.setattr(gym, "make", make_with_test_data)
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"DATASET": str(env_datasets[arrows])}
    shorter = quick_start.replace("epochs=1", "epochs=1, steps_per_epoch=40, dataset=DATASET")  # seconds
    assert shorter != quick_start
    exec(compile(shorter, "README.md", "exec"), namespace)
    assert namespace["report"].keys_asked == 96 and namespace["report"].accuracy <= 1.0
    assert (namespace["run_dir"] / "progress.csv").exists() and namespace["run_dir"].is_relative_to("runs")


COMMAND_LINES = [line for block in _blocks("bash") for line in block.replace("\\\n", " ").splitlines()]


@pytest.mark.parametrize("line", COMMAND_LINES)
def test_every_command_line_names_a_command_that_exists(line):
    """``tactile-braille`` lines parse as given (placeholders aside); make targets exist in the Makefile."""
    command = line.split("#")[0].strip()
    if not command:
        return
    words = shlex.split(command)
    if words[0] == "make":
        assert re.search(rf"^{words[1]}:", (ROOT / "Makefile").read_text(), flags=re.M), words[1]
    elif words[0] == "tactile-braille":
        build_parser().parse_args(words[1:])
    else:
        assert words[:1] == ["python"] and (ROOT / words[1]).exists(), line


def test_the_headline_table_is_what_the_committed_records_give():
    """The README's results table is generated (``make results``): the records committed under results/,
    ranked as the Makefile ranks them, give exactly the table the README holds."""
    from tactile_braille.evaluation.leaderboard import HEADLINE_MARKERS, headline_markdown, load_results

    apart = ("tuning", "diagnostics", "transfer", "warm-start")
    records = sorted({path.parent for path in [*ROOT.glob("results/*/*/config.json"),
                                               *ROOT.glob("results/*/*/*/config.json")]})  # fmt: skip
    ranked = [
        record
        for record in records
        if record.relative_to(ROOT / "results").parts[0] not in apart
        and not record.relative_to(ROOT / "results").parts[0].startswith("ablation-")
    ]
    files = sorted(ROOT.glob("results/leaderboard/*/*.json"))
    start, end = HEADLINE_MARKERS
    held = README.split(start)[1].split(end)[0]
    assert held.strip() == headline_markdown(load_results([*ranked, *files])).strip()
