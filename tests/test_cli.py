"""The ``tactile-braille`` command line: ``show``, usage errors, and ``train`` (a short run, bad options)."""

from __future__ import annotations

import json

import pytest

from agents_helpers import CONTINUOUS_TASK, train_module
from tactile_braille import cli
from tactile_braille.agents import read_progress
from tactile_braille.cli import build_parser, main
from tactile_braille.gallery import GALLERY_DEPTH_MM

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def test_show_writes_a_png(tmp_path, capsys):
    output = tmp_path / "nested" / "g.png"
    assert main(["show", "--output", str(output)]) == 0
    data = output.read_bytes()
    assert data.startswith(PNG_SIGNATURE)
    assert len(data) > 10_000
    assert f"wrote {output}" in capsys.readouterr().out
    # The atomic write leaves no temporary files behind.
    assert [p.name for p in output.parent.iterdir()] == ["g.png"]


def test_show_defaults():
    args = build_parser().parse_args(["show"])
    assert args.output == "outputs/gallery.png"
    assert args.sensor == "braille_331"
    assert args.depth == GALLERY_DEPTH_MM  # reading taps that press no key
    assert args.seed == 0


def test_show_options_are_parsed():
    args = build_parser().parse_args(["show", "--sensor", "tactip_127", "--depth", "6.5", "--seed", "3"])
    assert (args.sensor, args.depth, args.seed) == ("tactip_127", 6.5, 3)


@pytest.mark.parametrize(
    "argv",
    [[], ["bogus"], ["show", "--sensor", "gelsight"], ["show", "--depth", "deep"]],
)
def test_bad_arguments_exit_with_usage_error(argv, capsys):
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    assert "usage: tactile-braille" in capsys.readouterr().err


# ---------------------------------------------------------------- train
@pytest.mark.usefixtures("one_torch_thread")
def test_cli_train_uses_the_released_preset_and_the_options(env_datasets, tmp_path, monkeypatch, capsys):
    """A real ``tactile-braille train`` run, made short: steps per epoch and the dataset are not CLI
    options, so ``train`` is wrapped to set them on the config the CLI built (and to record it)."""
    built = []
    real_train = train_module.train

    def short_train(config=None, run_dir=None, resume=False, progress=True, rig=None):
        built.append(config)
        config = config.with_changes(
            steps_per_epoch=20, start_steps=10, dataset=str(env_datasets[CONTINUOUS_TASK])
        )
        return real_train(config, run_dir=run_dir, resume=resume, progress=progress, rig=rig)

    monkeypatch.setattr(train_module, "train", short_train)
    run = tmp_path / "cli"
    code = cli.main([
        "train", "ContinuousArrows-v0", "td3", "--preset", "released", "--epochs", "1",
        "--test-episodes", "1", "--threads", "1", "--run-dir", str(run), "--quiet", "--precision", "bf16",
        "--updates-per-step", "3", "--checkpoint-every", "1",
    ])  # fmt: skip
    assert code == 0
    assert f"run folder: {run}" in capsys.readouterr().out
    (config,) = built
    assert config.task == CONTINUOUS_TASK and config.algo == "td3"
    data = json.loads((run / "config.json").read_text())
    assert data["preset"] == "released"
    assert data["agent"]["learning_rate"] == 7.5e-5 and data["update_every"] == 100
    assert (data["epochs"], data["evaluation"]["test_episodes"], data["threads"]) == (1, 1, 1)
    assert (data["precision"], data["updates_per_step"], data["checkpoint_every"]) == ("bf16", 3, 1)
    assert len(read_progress(run)) == 1


@pytest.mark.usefixtures("one_torch_thread")
@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["train", "DiscreteArrows-v0", "dqn", "--agent.critic-pose"],
            "--agent.critic-pose is not a setting of dqn",
        ),
        (["train", "Piano-v0", "dqn"], "Piano-v0"),
        (["train", "DiscreteArrowsX-v0", "dqn"], "unknown task"),
        (["train", "DiscreteArrows-v0", "td3"], "td3 needs a continuous task"),
        (["train"], "TASK"),
    ],
)
def test_cli_train_argument_errors(argv, message, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # nothing may be written, but never into the repository
    assert cli.main(argv) == 2
    captured = capsys.readouterr()
    assert "error" in captured.err and message in captured.err
    assert not (tmp_path / "runs").exists()


def test_benchmark_runs_each_preset_in_its_own_folders_and_refuses_unknown_rows(
    tmp_path, monkeypatch, capsys
):
    calls = []
    monkeypatch.setattr(
        cli, "_run_sweep", lambda args, trials: calls.append((args.root, args.archive, trials))
    )
    argv = ["benchmark", "--paper", "--presets", "paper", "released", "--tasks", "DiscreteArrows-v0",
            "--seeds", "3", "4", "--root", str(tmp_path / "runs"),
            "--archive", str(tmp_path / "results")]  # fmt: skip
    assert main(argv) == 0
    assert [(root.name, archive.name) for root, archive, _ in calls] == [
        ("paper", "paper"),
        ("released", "released"),
    ]
    for _, _, trials in calls:
        assert {(t.task, t.algo, t.seed) for t in trials} == {
            ("DiscreteArrows-v0", algo, seed) for algo in ("dqn", "sac_discrete") for seed in (3, 4)
        }
    assert [t.preset for t in calls[1][2]] == ["released"] * 4
    # By default the committed rows' settings, so that a new seed joins its row rather than one of its own.
    assert all(t.overrides == {"precision": "bf16", "threads": 1} for _, _, trials in calls for t in trials)
    calls.clear()
    assert main([*argv, "--precision", "fp32", "--threads", "2"]) == 0
    assert calls[0][2][0].overrides == {"precision": "fp32", "threads": 2}
    assert main(["benchmark", "--paper", "--tasks", "DiscreteArrow-v0"]) == 2
    assert "no Table III rows for ['DiscreteArrow-v0']" in capsys.readouterr().err
    calls.clear()
    assert main([*argv, "--algos", "dqn"]) == 0  # one algorithm's rows: both presets, no other row
    assert [{(t.task, t.algo, t.seed) for t in trials} for _, _, trials in calls] == [
        {("DiscreteArrows-v0", "dqn", 3), ("DiscreteArrows-v0", "dqn", 4)}
    ] * 2
    assert main(["benchmark", "--paper", "--algos", "ddpg"]) == 2
    assert "no Table III rows for ['ddpg']; the algorithms are" in capsys.readouterr().err
    assert main(["benchmark", "--paper", "--tasks", "DiscreteArrows-v0", "--algos", "td3"]) == 2
    assert "Table III has no row of ['td3'] on ['DiscreteArrows-v0']" in capsys.readouterr().err
    assert len(calls) == 2  # nothing ran for the refused ones


def test_a_reports_command_names_a_folder_whose_every_entry_it_reports_as_folder_star(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for run in ("results/a/x", "results/a/y", "results/b/x", "results/b/y", "results/b/z"):
        (tmp_path / run).mkdir(parents=True)
    argv = ["report", "results/a/x", "results/a/y", "results/b/x", "results/b/y", "--output", "my file.md"]
    # Every entry of results/a is named; results/b/z is not, so results/b's runs stay listed one by one.
    assert cli._short_command(argv) == "report results/a/* results/b/x results/b/y --output 'my file.md'"
    (tmp_path / "results/a/notes.txt").write_text("not a run")  # a/* would now also name this file
    assert cli._short_command(argv[:3]) == "report results/a/x results/a/y"


def test_sweep_takes_the_train_commands_settings_under_a_variant_name(tmp_path, monkeypatch, capsys):
    calls = []
    monkeypatch.setattr(cli, "_run_sweep", lambda args, trials: calls.append(trials) or 0)
    argv = ["sweep", "--tasks", "DiscreteAlphabet-v0", "ContinuousArrows-v0", "--algos", "dqn", "sac",
            "--seeds", "100", "--epochs", "3", "--root", str(tmp_path / "runs"),
            "--replay.relabel", "all", "--agent.batch-size", "256"]  # fmt: skip
    assert main(argv) == 2  # settings without a name for them
    assert "need a --variant NAME" in capsys.readouterr().err
    assert main([*argv, "--variant", "relabel-all_batch256"]) == 0
    trials = calls[0]
    assert [t.name for t in trials] == [
        "DiscreteAlphabet-v0__dqn__relabel-all_batch256__100",
        "ContinuousArrows-v0__sac__relabel-all_batch256__100",
    ]
    for trial in trials:
        config = trial.config()
        assert (config.epochs, config.replay.relabel, config.agent.batch_size) == (3, "all", 256)
    assert main([*argv, "--variant", "a__b"]) == 2  # '__' separates a trial name's parts
    assert "variant 'a__b'" in capsys.readouterr().err
    assert main([*argv, "--variant", "eps", "--agent.epsilon-start", "0.5"]) == 2  # DQN's, not SAC's
    assert "--agent.epsilon-start is not a setting of sac" in capsys.readouterr().err
    assert main([*argv[:13], "--variant", "same"]) == 2  # a name for no change: the preset's runs again
    assert "--variant same names no setting" in capsys.readouterr().err
    assert main([*argv[:13], "--dataset", "grid.h5"]) == 0  # where a run is made, not what it is
    assert len(calls) == 2 and calls[1][0].name == "DiscreteAlphabet-v0__dqn__100"
    assert calls[1][0].config().dataset == "grid.h5"
    calls.pop()
    assert len(calls) == 1  # nothing ran after a refusal
    assert not (tmp_path / "runs").exists()


def test_collect_takes_the_perturbations_bounds_and_records_them(tmp_path, capsys):
    """A dataset of one unperturbed tap per key (the discrete world with one image per key)."""
    from tactile_braille.datasets.store import load_dataset
    from tactile_braille.keyboard.layout import KeyboardLayout

    output = tmp_path / "fixed.h5"
    argv = ["collect", "--keys", "arrows", "--per-key", "2", "--position-range-mm", "0", "--depth-range-mm",
            "-0.5", "-0.5", "--yaw-range-deg", "0", "--output", str(output)]  # fmt: skip
    assert main(argv) == 0 and f"wrote {output}: 10 taps" in capsys.readouterr().out
    dataset = load_dataset(output)
    procedure = dataset.metadata.procedure
    assert (procedure["position_range_mm"], procedure["depth_range_mm"], procedure["yaw_range_deg"]) == (
        0.0, [-0.5, -0.5], 0.0
    )  # fmt: skip
    layout, labels = KeyboardLayout(), dataset.label_names()
    for key in ("UP", "DOWN", "LEFT", "RIGHT"):
        poses = dataset.poses[labels == key]
        assert poses.tolist() == [[*layout.centre_mm(key), 4.5, 0.0]] * 2
