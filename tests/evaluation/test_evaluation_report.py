"""Reports over runs and seeds: statistics with known answers, the table, the figures."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tactile_braille.agents import TrainConfig, train
from tactile_braille.agents.config import replace_settings
from tactile_braille.agents.presets import preset_config
from tactile_braille.datasets.procedures import PerturbedTaps
from tactile_braille.evaluation.report import (
    PAPER_TABLE,
    RunRecord,
    _reached_cell,
    compared_groups,
    coverage_section,
    coverage_table,
    dataset_label,
    departures,
    group,
    load_records,
    original_curves,
    plot_by_task,
    plot_typing_profiles,
    profiles_section,
    results_table,
    source_world,
    transfer_table,
    warm_start_table,
    write_report,
)


def record(task, algo, seed, returns, accuracy=None, steps=None, reset=None):
    typing = None if accuracy is None else {"accuracy": accuracy, "total_steps": steps}
    if reset is not None:
        typing["released_protocol"] = {"accuracy": reset[0], "total_steps": reset[1]}
    return RunRecord(path=f"runs/{task}/{seed}", task=task, algo=algo, seed=seed, returns=np.array(returns),
                     typing=typing)  # fmt: skip


def test_the_first_epoch_at_095_says_within_how_many_epochs_the_others_did_not_reach_it():
    assert _reached_cell([4, 6], [100, 100]) == "5.0 [4.0, 6.0]"
    assert (
        _reached_cell([4, None, None], [10, 100, 120]) == "1/3 reached, not by epochs 100-120; 4.0 (one run)"
    )
    assert _reached_cell([None], [54]) == "0/1 reached, not by epoch 54"
    assert _reached_cell([None, 3]) == "1/2 reached; 3.0 (one run)"  # epochs unknown: the count alone


def test_results_table_has_the_papers_shape_and_numbers():
    records = [
        record("DiscreteArrows-v0", "dqn", 0, [0.2, 0.96, 1.0], 1.0, 240),
        record("DiscreteArrows-v0", "dqn", 1, [0.1, 0.5, 1.0], 1.0, 250),
        record("DiscreteAlphabet-v0", "dqn", 0, [0.1, 0.5, 0.9], 0.9, 1800, reset=(0.8, 1900)),
        record("DiscreteArrows-v0", "sac_discrete", 0, [0.0, 0.2, 0.5], 0.5, 400),
    ]
    groups = group(records)
    assert list(groups) == [("DiscreteArrows-v0", "dqn", ""), ("DiscreteArrows-v0", "sac_discrete", ""),
                            ("DiscreteAlphabet-v0", "dqn", "")]  # fmt: skip
    table = results_table(groups).splitlines()
    assert table[0].count("|") == 17
    arrows_dqn = table[2]
    # The optimal steps beside ours: the pose-aware bound for typing seed 0 (242), the expectation with
    # a reset per key (224; a record without that evaluation shows none).
    assert (
        "| disc arrow | DQN | tactile | 2 | 245 [240, 250] | 242 | 1.000 [1.000, 1.000] | - | - | - |"
        in arrows_dqn
    )
    assert "2.5 [2.0, 3.0]" in arrows_dqn  # convergence epochs 2 and 3 (95 % of 1.0; counted from 1)
    assert arrows_dqn.endswith("| 230 | 1.000 | 8 |")  # the paper's Table III
    assert "| 0/1 reached, not by epoch 3 |" in table[3]  # discrete SAC never reached 0.95 in its 3 epochs
    assert "| 400 (one run) |" in table[3]
    with pytest.raises(ValueError, match="repeats seed 0"):
        group([*records, record("DiscreteArrows-v0", "dqn", 0, [0.5])])
    assert table[4].endswith("| 1722 | 0.981 | 45 |")
    assert "| 1800 (one run) | 1309 | 0.900 (one run) | 1900 (one run) | 1433 | 0.800 (one run) |" in table[4]


def test_coverage_counts_only_full_runs_of_a_presets_own_settings():
    task = "tactile_braille/DiscreteAlphabet-v0"
    paper = preset_config("paper", task, "dqn", precision="bf16")
    released = preset_config("released", task, "dqn", precision="bf16")
    earlier = replace_settings(released, {"agent": {"dueling_split": False}})  # an earlier released preset
    records = []
    for seed in range(5):  # paper: five seeds of 100 epochs
        records.append(record("DiscreteAlphabet-v0", "dqn", seed, [0.5] * 100))
        records[-1].config = paper
    for seed, epochs in ((0, 100), (1, 100), (2, 54)):  # released: two full runs and one stopped early
        records.append(record("DiscreteAlphabet-v0", "dqn", seed, [0.5] * epochs))
        records[-1].config = released
    for seed in range(5):  # five full runs that depart from today's released preset
        records.append(record("DiscreteAlphabet-v0", "dqn", seed, [0.5] * 100))
        records[-1].config = earlier
    records.append(record("ContinuousAlphabet-v0", "sac", 0, [0.1] * 120))
    records[-1].config = preset_config("paper", "tactile_braille/ContinuousAlphabet-v0", "sac")
    rows = {
        tuple(cell.strip() for cell in line.strip("|").split("|")[:2]): line
        for line in coverage_table(group(records)).splitlines()[2:]
    }
    assert len(rows) == 16  # the eight simulated rows of Table III, each with both presets
    assert rows["disc alpha, DQN", "paper"].endswith("| tactile | 5 | 100 | 5 x 100 | complete |")
    assert rows["disc alpha, DQN", "released"].endswith(
        "| tactile | 2 | 100 | 5 x 100 | 3 more seeds; 1 stopped at epoch 54 |"
    )
    # The continuous alphabet is asked as far as compute allows: 3 seeds of 100 epochs or more.
    assert rows["cont alpha, SAC", "paper"].endswith("| 1 | 120 | 3 x 100 (of 2,000) | 2 more seeds |")
    assert rows["disc arrow, SAC_DISC", "released"].endswith("| 0 | - | 5 x 25 | not run |")
    # A report with a run of the paper's presets carries the table; one of other presets' runs does not.
    assert coverage_section(group(records))[0].startswith("### Table III coverage")
    fast = record("DiscreteAlphabet-v0", "dqn", 0, [0.5] * 100)
    fast.config = preset_config("fast", task, "dqn")
    assert coverage_section(group([fast])) == []


def test_a_continuous_run_in_our_world_is_named_so_and_not_counted():
    """Since 2026-11-27 the paper's presets take the released simulator's workspace edge and depth
    lookup on the continuous tasks; the runs made before, in ours, depart from them."""
    task = "tactile_braille/ContinuousArrows-v0"
    stopped = replace_settings(
        preset_config("paper", task, "td3"), {"edges": "stop", "tap_depth": "commanded"}
    )
    assert departures(stopped) == ["edges=stop", "tap_depth=commanded"]
    records = [record("ContinuousArrows-v0", "td3", seed, [0.5] * 100) for seed in range(5)]
    for one in records:
        one.config = stopped
    rows = {
        tuple(cell.strip() for cell in line.strip("|").split("|")[:2]): line
        for line in coverage_table(group(records)).splitlines()[2:]
    }
    assert rows["cont arrow, TD3", "paper"].endswith("| 0 | - | 5 x 100 | not run |")


def test_runs_of_two_tracks_are_tabled_apart_under_their_tracks():
    paper = preset_config("paper", "tactile_braille/DiscreteArrows-v0", "dqn")
    fast = preset_config("fast", "tactile_braille/DiscreteArrows-v0", "dqn")
    records = [record("DiscreteArrows-v0", "dqn", seed, [0.5, 1.0], 1.0, 240) for seed in (0, 1)]
    records[0].config, records[1].config = paper, fast
    text = results_table(group(records))
    tactile, proprio = text.split("### ")[1:]
    assert tactile.startswith("Track `tactile`") and proprio.startswith("Track `proprio`")
    assert "| DQN (paper, fp32) | tactile |" in tactile
    assert "proprio" not in tactile.split("\n", 1)[1]  # nothing but the heading names the other track
    assert "| DQN (fast, fp32) | proprio |" in proprio


def test_transfer_table_shows_each_world_beside_the_world_learnt_in():
    records = [record("ContinuousAlphabet-v0", "sac", seed, [0.5, 1.0], accuracy, 900) for seed, accuracy
               in ((0, 1.0), (1, 0.9), (2, 0.95))]  # fmt: skip
    for r, (render, frame) in zip(records[:2], ((0.9, 0.5), (0.8, 0.7)), strict=True):
        r.transfer = {"worlds": {"render": {"accuracy": render}, "frame:+1,0,+2": {"accuracy": frame},
                                 "frame:+3,0,0": {"accuracy": 0.1}}}  # fmt: skip
    header, _, row = transfer_table(group(records)).splitlines()
    assert header.startswith("| task | algo | track | seeds | where it learnt | `render` | `frame:+1,0,+2` |")
    assert header.endswith("| `sensor:tactip_127` | `frame:+3,0,0` |")  # the suite first, then others
    cells = [c.strip() for c in row.split("|")[1:-1]]
    assert cells[:5] == [
        "ContinuousAlphabet-v0",
        "SAC",
        "tactile",
        "2",
        "0.950 [0.900, 1.000]",
    ]  # seed 2: none
    assert cells[5:7] == ["0.850 [0.800, 0.900]", "0.600 [0.500, 0.700]"]
    assert cells[-2:] == ["-", "0.100 [0.100, 0.100]"]


def test_original_curves_are_vendored():
    curves = original_curves()
    epochs, returns = curves[("sim", "DiscreteArrows-v0", "dqn")]
    assert list(epochs) == list(range(24))  # the log holds 24 epochs, counted from 0 here
    assert np.all((returns >= 0) & (returns <= 1))
    sim = {key for key in curves if key[0] == "sim"}
    assert sim == {
        ("sim", task, algo)
        for task in ("DiscreteArrows-v0", "DiscreteAlphabet-v0")
        for algo in ("dqn", "sac_discrete")
    } | {("sim", "ContinuousArrows-v0", "sac"), ("sim", "ContinuousArrows-v0", "td3")}
    assert {key for key in curves if key[0] == "robot"} <= set(PAPER_TABLE)


def test_write_report_over_two_seeds(env_datasets, tmp_path):
    dataset = str(env_datasets["tactile_braille/DiscreteArrows-v0"])
    runs = []
    for seed in (0, 1):
        config = TrainConfig(
            agent={
                "batch_size": 8,
                "hidden": (16,),
            },  # a small agent: the test is of the loop, not of learning
            seed=seed,
            epochs=3,
            steps_per_epoch=30,
            start_steps=20,
            updates_per_step=1,
            dataset=dataset,
            threads=1,
            evaluation={"test_episodes": 2},
            replay={"capacity": 500},
        )
        runs.append(train(config, run_dir=tmp_path / f"run{seed}", progress=False))
    # Figures the previous report linked, of a group this one no longer holds, are removed;
    # files it did not link are left alone.
    (tmp_path / "report").mkdir()
    for leftover in ("confusion_gone.png", "trajectories_gone.png", "confusion_not_ours.png", "notes.txt"):
        (tmp_path / "report" / leftover).write_bytes(b"old")
    (tmp_path / "report" / "results.md").write_text(
        "![a](confusion_gone.png)\n![b](trajectories_gone.png)\n![c](curves.png)\n"
    )
    report = write_report(runs, tmp_path / "report", title="Two seeds")
    assert sorted(p.name for p in (tmp_path / "report").iterdir()) == [
        "confusion_DiscreteArrows__dqn__custom_fp32_tactile-track.png", "confusion_not_ours.png",
        "curves.png", "notes.txt", "results.md",
        "trajectories_DiscreteArrows__dqn__custom_fp32_tactile-track.png",
    ]  # fmt: skip
    text = report.read_text()
    assert text.startswith("# Two seeds")
    assert "| sim | disc arrow | DQN (custom, fp32, tactile track) | tactile | 2 |" in text
    for name in ("curves.png", "confusion_DiscreteArrows__dqn__custom_fp32_tactile-track.png",
                 "trajectories_DiscreteArrows__dqn__custom_fp32_tactile-track.png"):  # fmt: skip
        assert (tmp_path / "report" / name).read_bytes()[:4] == b"\x89PNG", name
        assert f"]({name})" in text
    typing = json.loads((runs[0] / "typing.json").read_text())  # evaluated on the way
    assert typing["keys_asked"] == 96 and 0.0 <= typing["accuracy"] <= 1.0
    assert typing["checkpoint_epoch"] == 2
    assert sum(map(sum, typing["confusion"]["counts"])) == 96
    assert [r.seed for r in load_records(runs)] == [0, 1]
    # A typing evaluation older than the run's last epoch is stale: it is done again.
    stale = dict(typing, checkpoint_epoch=1, accuracy=-1.0)
    (runs[0] / "typing.json").write_text(json.dumps(stale))
    assert load_records(runs[:1])[0].typing["accuracy"] >= 0.0
    with pytest.raises(FileNotFoundError, match="not a training run"):
        load_records([tmp_path])
    # A report written to a Markdown file (docs/results.md): figures beside it in a folder of its name,
    # linked through it, the notes after the table and the command quoted.
    page = write_report(runs, tmp_path / "docs" / "results.md", notes="Reading: **fine**.", command="make it")
    text = page.read_text()
    assert page == tmp_path / "docs" / "results.md"
    assert (tmp_path / "docs" / "results" / "curves.png").read_bytes()[:4] == b"\x89PNG"
    assert (
        "](results/curves.png)" in text
        and "](results/confusion_DiscreteArrows__dqn__custom_fp32_tactile-track.png)" in text
    )
    assert "`make it`" in text
    assert "## Transfer" not in text  # no run typed in other worlds
    # Runs typed in other worlds (transfer.json of their last checkpoint) get a section of their own.
    worlds = {"render": {"accuracy": 0.25}, "sensor:tactip_127": {"accuracy": 0.0}}
    (runs[0] / "transfer.json").write_text(json.dumps({"checkpoint_epoch": 2, "worlds": worlds}))
    (runs[1] / "transfer.json").write_text(json.dumps({"checkpoint_epoch": 1, "worlds": worlds}))  # stale
    moved = write_report(runs, tmp_path / "moved.md", transfer_dirs=runs).read_text()
    section = moved.split("## Transfer: typing in worlds the policies did not learn in")[1]
    row = section.split("\n| DiscreteArrows-v0 |")[1].split("\n")[0]
    assert (
        row.startswith(" DQN (custom, fp32, tactile track) | tactile | 1 |") and "| 0.250 (one run) |" in row
    )
    # A warm start (init.json) gets a section of its own, beside its settings from scratch, with a figure.
    source = {"run": str(runs[0]), "epochs": 4, "test_returns": [0.0, 0.5, 0.96, 1.0], "world": None}
    (runs[1] / "init.json").write_text(json.dumps(source))
    warm = write_report(runs[:1], tmp_path / "warm.md", warm_dirs=runs).read_text()
    row = warm.split("## Warm starts")[1].split("\n| disc arrow | ")[1].split("\n")[0]
    assert row.startswith(
        "DQN (custom, fp32, tactile track) | tactile | 1 | 4 epochs, default dataset | 3.0 "
    )
    assert "| (1) " in row and "](warm/warm_starts.png)" in warm
    assert (tmp_path / "warm" / "warm_starts.png").read_bytes()[:4] == b"\x89PNG"
    assert (
        text.index("| sim | disc arrow |")
        < text.index("Reading: **fine**.")
        < text.index("![training curves]")
    )


GRID_6MM = {"procedure": {"procedure": "grid", "keys": "alphabet", "spacing_mm": 6.0, "depth_step_mm": 1.0}}


def test_dataset_label_names_only_a_dataset_other_than_the_tasks():
    assert dataset_label(GRID_6MM) == "6 mm grid"
    deeper = {"procedure": {**GRID_6MM["procedure"], "depth_step_mm": 2.0}}
    assert dataset_label(deeper) == "6 mm grid (2 mm depth steps)"
    paper = {"procedure": {**GRID_6MM["procedure"], "spacing_mm": 3.0}}
    assert dataset_label(paper) is None and dataset_label(None) is None
    assert dataset_label({"procedure": {"procedure": "perturbed", "keys": "all"}}) is None
    perturbed = PerturbedTaps(per_key=3).describe()  # the paper's bounds, fewer taps: the same world's kind
    assert dataset_label({"procedure": json.loads(json.dumps(perturbed))}) is None
    fixed = PerturbedTaps(per_key=1, position_range_mm=0, depth_range_mm=(-0.5, -0.5), yaw_range_deg=0)
    assert (
        dataset_label({"procedure": json.loads(json.dumps(fixed.describe()))}) == "1 unperturbed tap per key"
    )
    narrow = PerturbedTaps(position_range_mm=0.5, yaw_range_deg=5).describe()
    assert (
        dataset_label({"procedure": narrow}) == "100 taps per key within +-0.5 mm, +-5 deg, depth -1 to +0 mm"
    )
    assert source_world(GRID_6MM) == "6 mm grid" and source_world({"backend": "render"}) == "render backend"
    assert source_world(None) == "default dataset"


def test_a_warm_start_is_tabled_beside_the_same_settings_from_scratch():
    task = "ContinuousAlphabet-v0"
    config = preset_config("fast", f"tactile_braille/{task}", "sac")
    warm_config = replace_settings(config, {"init_from": "runs/pre"})

    def run(seed, returns, accuracy, init=None):
        typing = {"accuracy": accuracy, "total_steps": 1000}
        return RunRecord(path=f"runs/{seed}", task=task, algo="sac", seed=seed, returns=np.array(returns),
                         typing=typing, config=warm_config if init else config, init=init)  # fmt: skip

    def init(returns):
        return {"run": "runs/pre", "epochs": 15, "test_returns": returns, "world": GRID_6MM}

    cold = group([run(0, [0.1, 0.5, 0.96, 1.0], 0.9), run(1, [0.1, 0.5, 0.9, 0.97], 0.8)])
    warm = group([
        run(0, [0.97, 1.0], 1.0, init([0.2, 0.96])), run(1, [0.5, 0.96], 0.96, init([0.2, 0.5])),
    ])  # fmt: skip
    [(key, records)] = warm.items()
    assert key == (task, "sac", "fast, fp32, warm start: 15 epochs on the 6 mm grid")
    assert records[0].cold_variant == "fast, fp32" and (task, "sac", "fast, fp32") in cold
    row = warm_start_table(warm, cold).splitlines()[2].split(" | ")
    assert row[1:5] == ["SAC (fast, fp32)", "proprio", "2", "15 epochs, 6 mm grid"]
    assert row[5] == "1/2 reached; 2.0 (one run)"  # the pretraining's own first epoch at 0.95
    assert row[6].startswith("1.5 [1.0, 2.0]")  # epochs 1 and 2 after the warm start
    assert row[7].startswith("(2) 3.5 [3.0, 4.0]")  # from scratch: epochs 3 and 4
    assert row[8].startswith("16.5 [16.0, 17.0]")  # 15 pretraining epochs each
    assert row[9].startswith("0.980") and row[9].endswith("after 2 epochs")
    assert row[10].startswith("0.850") and row[10].endswith("after 4 epochs |")


def test_a_run_with_frame_noise_names_it_in_its_variant():
    task = "ContinuousAlphabet-v0"
    config = preset_config("fast", f"tactile_braille/{task}", "sac", backend="render", frame_noise=(1.0, 2.0))
    run = RunRecord(path="runs/0", task=task, algo="sac", seed=0, returns=np.zeros(2), config=config)
    assert run.variant == "fast, fp32, render backend, frame noise 1 mm, 2 deg"


def test_the_by_task_figure_draws_rows_of_five_seeds_or_more(tmp_path):
    """Five seeds or more, the paper's; on the continuous alphabet three, the seeds its rows ask."""
    five = [record("DiscreteArrows-v0", "dqn", seed, [0.5, 0.96, 1.0], 1.0, 240) for seed in range(5)]
    three = [record("DiscreteArrows-v0", "sac_discrete", seed, [0.0, 0.5], 0.5, 400) for seed in range(3)]
    alphabet = [record("DiscreteAlphabet-v0", "dqn", seed, [0.1, 0.2], 0.2, 1900) for seed in range(6)]
    long = [record("ContinuousAlphabet-v0", "td3", seed, [0.0, 0.05], 0.0, 270) for seed in range(3)]
    two = [record("ContinuousAlphabet-v0", "sac", seed, [0.0, 0.1], 0.0, 270) for seed in range(2)]
    groups = group(five + three + alphabet + long + two)
    compared = compared_groups(groups)
    assert list(compared) == ["DiscreteArrows-v0", "DiscreteAlphabet-v0", "ContinuousAlphabet-v0"]
    assert [(algo, len(runs)) for algo, _, runs in compared["DiscreteArrows-v0"]] == [("dqn", 5)]
    assert [(algo, len(runs)) for algo, _, runs in compared["ContinuousAlphabet-v0"]] == [("td3", 3)]
    assert plot_by_task(groups, tmp_path / "by_task.png").read_bytes()[:4] == b"\x89PNG"
    assert plot_by_task(group(three), tmp_path / "none.png") is None  # an ablation alone: no figure
    assert not (tmp_path / "none.png").exists()


# ------------------------------------------------------------------ the repository's results pages
def write_record(folder, config, seed, returns, accuracy, steps):
    """A run record as ``tactile-braille archive`` leaves it (no checkpoint): settings, world, progress
    log and typing, both protocols, with its confusion and typing bound."""
    from tactile_braille.agents.run import write_config
    from tactile_braille.datasets.collector import GENERATOR_VERSION

    folder.mkdir(parents=True)
    write_config(folder, replace_settings(config, {"seed": seed}))
    (folder / "world.json").write_text(json.dumps({"generator_version": GENERATOR_VERSION}))
    rows = ["epoch,test/episodic_return,time_s", *(f"{i},{r},60.0" for i, r in enumerate(returns))]
    (folder / "progress.csv").write_text("\n".join(rows) + "\n")
    confusion = {"rows": ["UP", "DOWN"], "columns": ["UP", "DOWN", "OTHER", "NONE"],
                 "counts": [[48, 0, 0, 0], [0, 48, 0, 0]]}  # fmt: skip
    typed = {"accuracy": accuracy, "total_steps": steps, "keys_asked": 96, "typing_bound": 242.0}
    reset = {**typed, "total_steps": steps - 10, "typing_bound": 224.0}
    typing = {
        **typed,
        "checkpoint_epoch": len(returns) - 1,
        "confusion": confusion,
        "released_protocol": reset,
    }
    (folder / "typing.json").write_text(json.dumps(typing))
    return folder


@pytest.fixture
def records_tree(tmp_path):
    """Records of a preset's own runs, of a departure, of an ablation, of tuning and of diagnostics."""
    task = "tactile_braille/DiscreteArrows-v0"
    paper = preset_config("paper", task, "dqn", precision="bf16")
    relabel = replace_settings(paper, {"replay": {"relabel": "all"}})
    fast = preset_config("fast", task, "dqn")
    results = tmp_path / "results"
    runs = [
        write_record(results / "table3" / f"p_{s}", paper, s, [0.5, 0.96, 1.0], 1.0, 250 + s) for s in (0, 1)
    ]
    runs += [write_record(results / "fast" / f"f_{s}", fast, s, [0.97, 1.0], 1.0, 242) for s in (0, 1)]
    runs += [write_record(results / "relabel" / f"r_{s}", relabel, s, [0.9, 1.0], 1.0, 245) for s in (0, 1)]
    ablations = [write_record(results / "ablation-x" / "p_7", paper, 7, [0.2, 0.5], 0.5, 400)]
    shorter = replace_settings(paper, {"epochs": 2})  # the preset's settings, trained for fewer epochs
    ablations.append(write_record(results / "ablation-x" / "p_8", shorter, 8, [0.1, 0.3], 0.25, 600))
    write_record(results / "tuning" / "DAr_relabel-all_100", relabel, 100, [0.3, 0.96], 1.0, 250)
    study = results / "diagnostics" / "gpu-node"
    write_record(study / "DiscreteArrows-v0__dqn__0", paper, 0, [0.4, 0.97], 1.0, 269)
    (study / "README.md").write_text("# GPU wall-clock: one node (2026-11-27)\n\nWhat ran.\n")
    (study / "epochs.tsv").write_text("trial\tseconds\n")
    write_record(results / "diagnostics" / "DA_single_0", paper, 0, [0.1, 0.2], 0.3, 900)
    return tmp_path, runs, ablations


def test_a_presets_own_rows_are_the_headline_and_the_rest_depart(records_tree):
    from tactile_braille.evaluation.results_pages import departure_text, preset_of, split_groups

    _, runs, ablations = records_tree
    own, departed = split_groups(load_records(runs), load_records(ablations))
    assert [key[2] for key in own] == ["fast, fp32", "paper, bf16"]
    assert [len(records) for records in own.values()] == [2, 2]
    # A departure is named by what differs; an ablation's runs depart even with the preset's own settings,
    # and are named by their epochs where those are not the preset's.
    assert [key[2] for key in departed] == [
        "paper, bf16, 2 epochs, run as an ablation",
        "paper, bf16, replay.relabel=all",
        "paper, bf16, run as an ablation",
    ]
    assert [len(records) for records in departed.values()] == [1, 2, 1]
    shorter = departed["DiscreteArrows-v0", "dqn", "paper, bf16, 2 epochs, run as an ablation"]
    assert [r.seed for r in shorter] == [8]
    assert departure_text("paper, bf16, replay.relabel=all, taps=2") == "replay.relabel=all, taps=2"
    assert departure_text("paper, bf16") == "" and preset_of("fast-tactile, fp32, x=1") == "fast-tactile"


def test_the_same_departure_trained_for_other_epochs_is_a_group_of_its_own(tmp_path):
    from tactile_braille.evaluation.results_pages import split_groups

    relabel = preset_config("paper", "tactile_braille/DiscreteArrows-v0", "dqn", precision="bf16",
                            replay={"relabel": "all"})  # fmt: skip
    runs = [write_record(tmp_path / "relabel" / "r_0", relabel, 0, [0.9, 1.0], 1.0, 245)]
    longer = replace_settings(relabel, {"epochs": 40})
    ablations = [write_record(tmp_path / "ablation-x" / "r_0", longer, 0, [0.5, 0.9], 0.9, 300)]
    own, departed = split_groups(load_records(runs), load_records(ablations))  # seed 0 twice, no clash
    assert not own
    assert {key[2]: [r.path for r in records] for key, records in departed.items()} == {
        "paper, bf16, replay.relabel=all": runs,
        "paper, bf16, replay.relabel=all, 40 epochs": ablations,
    }


def test_the_results_pages_are_written_whole_and_again_byte_for_byte(records_tree, monkeypatch, capsys):
    from tactile_braille.evaluation.results_pages import main

    root, runs, ablations = records_tree
    monkeypatch.chdir(root)  # the Makefile's paths: relative to the checkout
    docs = Path("docs")
    docs.mkdir()
    (docs / "notes").mkdir()
    (docs / "notes" / "results-account.md").write_text("# The account\n")
    (docs / "results").mkdir()
    (docs / "results" / "confusion_gone.png").write_bytes(b"old")  # a figure of a row no longer reported
    (docs / "results-runs.md").write_text("![a](results/confusion_gone.png)\n")
    (docs / "notes.md").write_text("## Reading the table\n\nRead **this**.\n")
    argv = [*(str(Path(r).relative_to(root)) for r in runs), "--ablations",
            *(str(Path(r).relative_to(root)) for r in ablations), "--tuning", "results/tuning",
            "--diagnostics", "results/diagnostics", "--notes", "docs/notes.md",
            "--title", "Results here"]  # fmt: skip
    assert main(argv) == 0
    pages = ["results.md", "results-ablations.md", "results-runs.md", "results-tuning.md"]
    assert [line.split()[1] for line in capsys.readouterr().out.splitlines()] == [f"docs/{p}" for p in pages]
    text = {page: (docs / page).read_text() for page in pages}
    for page in pages:  # each page links every other near its top, and the account beside them
        top = text[page].split("\n\n", 3)
        assert all(f"]({other})" in "\n".join(top[:3]) for other in pages if other != page), page
        assert "](notes/results-account.md)" in text[page]
    headline = text["results.md"]
    assert headline.startswith("# Results here\n")
    assert "### `paper`: the paper's settings" in headline and "### `fast`: ours" in headline
    assert headline.index("## Track `tactile`") < headline.index("## Track `proprio`")
    assert (
        "| disc arrow | DQN | 2 | 250 [250, 251] | 242 | 1.000 [1.000, 1.000] | 240 [240, 241] | 224 |"
        in headline
    )
    assert "relabel" not in headline.split("## Table III coverage")[0]  # departures are not headline rows
    assert (
        headline.index("![steps per key") < headline.index("| disc arrow |") < headline.index("Read **this**")
    )
    ablated = text["results-ablations.md"]
    assert "## Departures from `paper` (track `tactile`)" in ablated
    rows = [line for line in ablated.splitlines() if line.startswith("| disc arrow")]
    assert [row.split(" | ")[2] for row in rows] == [
        "none: the preset's own row", "2 epochs, run as an ablation", "replay.relabel=all",
        "run as an ablation",
    ]  # fmt: skip
    assert rows[3].endswith("| `results/ablation-x/` |")  # an ablation with the preset's settings
    assert (
        "## DiscreteArrows-v0, DQN (paper, bf16, replay.relabel=all), track `tactile`"
        in text["results-runs.md"]
    )
    tuning = text["results-tuning.md"]
    assert (
        "| `DAr_relabel-all_100` | disc arrow | DQN | paper, bf16, replay.relabel=all | tactile | 100 |"
        in tuning
    )
    assert "### `gpu-node/`: GPU wall-clock: one node (2026-11-27)" in tuning
    assert "[Its README](../results/diagnostics/gpu-node/README.md)" in tuning and "`epochs.tsv`" in tuning
    assert "| `DA_single_0` | disc arrow | DQN | paper, bf16 |" in tuning.split("### Single runs")[1]
    figures = sorted(p.name for p in (docs / "results").iterdir())
    assert "confusion_gone.png" not in figures  # linked before, not now: removed
    assert {"steps_per_key.png", "curves.png", "ablations.png"} <= set(figures)  # by task: 5 seeds a row
    before = {p: p.read_bytes() for p in [*docs.glob("results*.md"), *(docs / "results").iterdir()]}
    assert main(argv) == 0
    assert {p: p.read_bytes() for p in [*docs.glob("results*.md"), *(docs / "results").iterdir()]} == before


def test_the_profiles_figure_draws_the_typed_rows_of_the_by_task_figure(tmp_path):
    typed = [
        record("DiscreteArrows-v0", "dqn", seed, [0.5, 1.0], 0.9 + 0.02 * seed, 240) for seed in range(5)
    ]
    untyped = [record("DiscreteAlphabet-v0", "dqn", seed, [0.1, 0.2]) for seed in range(5)]
    few = [record("DiscreteArrows-v0", "sac_discrete", seed, [0.0, 0.5], 1.0, 400) for seed in range(3)]
    written: set[str] = set()
    lines = profiles_section(group(typed + untyped + few), tmp_path, "figures/", written)
    assert (
        written == {"typing_profiles.png"} and "![performance profiles](figures/typing_profiles.png)" in lines
    )
    assert (tmp_path / "typing_profiles.png").read_bytes()[:4] == b"\x89PNG"
    assert (
        plot_typing_profiles(group(untyped + few), tmp_path / "none.png") is None
    )  # nothing typed to compare
    assert profiles_section(group(few), tmp_path, "", written) == [] and not (tmp_path / "none.png").exists()


def test_the_pages_figures_draw_nothing_without_rows(tmp_path):
    from tactile_braille.evaluation.results_pages import (
        plot_departures,
        plot_preset_curves,
        plot_steps_per_key,
    )

    assert plot_steps_per_key({}, tmp_path / "a.png") is None
    assert plot_preset_curves({}, tmp_path / "b.png") is None
    assert plot_departures({}, {}, tmp_path / "c.png") is None
    untyped = group([record("DiscreteArrows-v0", "dqn", 0, [0.5, 1.0])])
    assert plot_steps_per_key(untyped, tmp_path / "d.png") is None
    assert not list(tmp_path.iterdir())
