"""The run report (agents/report.py): when a learning curve has converged, and a trained run's report."""

from __future__ import annotations

from tactile_braille.agents import TrainConfig, train


def test_convergence_epoch_rules():
    from tactile_braille.agents.report import convergence_epoch

    curve = [0.1, 0.5, 0.8, 0.78, 0.9, 0.85]
    # Epochs count from 1, as in the paper's logs: curve[i] is the test after epoch i + 1.
    assert convergence_epoch(curve) == 5  # 95 % of the best (0.9) is 0.855: first reached by curve[4]
    assert convergence_epoch(curve, fraction=0.85) == 3  # 0.765
    assert convergence_epoch(curve, level=0.95) is None  # never reaches 0.95 in absolute terms
    assert convergence_epoch([0.0, 0.96, 1.0], level=0.95) == 2
    assert convergence_epoch([]) is None
    assert convergence_epoch([0.0, 0.0, 0.0]) is None  # a run that never scored has not converged


def test_report_evaluates_the_checkpoint_and_draws_the_curve(env_datasets, tmp_path):
    from tactile_braille.cli import main

    config = TrainConfig(
        agent={"batch_size": 8, "hidden": (16,)},  # a small agent: the test is of the loop, not of learning
        epochs=2,
        steps_per_epoch=40,
        start_steps=20,
        updates_per_step=1,
        dataset=str(env_datasets["tactile_braille/DiscreteArrows-v0"]),
        threads=1,
        evaluation={"test_episodes": 2},
        replay={"capacity": 500},
    )
    run = train(config, run_dir=tmp_path / "run", progress=False)
    assert main(["report", str(run), "--episodes", "3"]) == 0
    report = (run / "report.md").read_text()
    assert "| epochs trained | 2 (80 env steps" in report
    assert "final evaluation (3 episodes)" in report
    assert (run / "curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["report", str(tmp_path / "missing")]) == 2  # a clear error, not a traceback
