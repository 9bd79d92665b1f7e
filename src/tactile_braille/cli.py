"""The ``tactile-braille`` command: thin wrappers over the library."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")  # the command only writes files

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from tactile_braille.sensor.config import PRESETS


def _show(args: argparse.Namespace) -> int:
    from tactile_braille.gallery import dataset_figure, live_gallery_tiles, save_figure, save_gallery

    if args.dataset is not None:
        dataset = _load_named_dataset(args.dataset, args.sensor, args.seed)
        path = save_figure(dataset_figure(dataset), args.output)
        print(f"wrote {path} ({len(dataset)} taps in {args.dataset})")
        return 0
    from tactile_braille.rigs.virtual import VirtualRig

    rig = VirtualRig(sensor=args.sensor, seed=args.seed)
    tiles = live_gallery_tiles(rig, depth_mm=args.depth)
    path = save_gallery(
        tiles,
        args.output,
        title=f"Live renders, sensor {args.sensor}, tap depth {args.depth} mm (processed 100x100)",
    )
    print(f"wrote {path} ({len(tiles)} tactile images)")
    return 0


def _make_rig(args: argparse.Namespace):
    if args.rig == "virtual":
        from tactile_braille.rigs.virtual import VirtualRig

        return VirtualRig(sensor=args.sensor)
    raise SystemExit(f"unknown rig {args.rig!r}")  # argparse's choices make this unreachable


def _collect(args: argparse.Namespace) -> int:
    from tactile_braille.datasets.collector import collect
    from tactile_braille.datasets.procedures import GridTaps, PerturbedTaps

    if args.procedure == "perturbed":
        procedure = PerturbedTaps(keys=args.keys, per_key=args.per_key, split=args.split, seed=args.seed)
    else:
        if args.keys == "all":
            raise ValueError("a grid covers one task's work frame: choose --keys alphabet or --keys arrows")
        procedure = GridTaps(keys=args.keys, spacing_mm=args.spacing_mm, depth_step_mm=args.depth_step_mm)
    start = time.perf_counter()
    with _make_rig(args) as rig:
        path = collect(rig, procedure, args.output, seed=args.seed, resume=args.resume)
    size_mb = path.stat().st_size / 1e6
    print(f"wrote {path}: {len(procedure)} taps, {size_mb:.1f} MB, {time.perf_counter() - start:.1f} s")
    return 0


def _import(args: argparse.Namespace) -> int:
    from tactile_braille.datasets.importer import import_original

    path = import_original(
        args.csv, args.output, videos_dir=args.videos, grid_frame=args.grid_frame, resume=args.resume
    )
    print(f"wrote {path}")
    return 0


def _data(args: argparse.Namespace) -> int:
    from tactile_braille.datasets.cache import DEFAULT_DATASETS, default_dataset, default_dataset_path

    for name in DEFAULT_DATASETS:
        start = time.perf_counter()
        dataset = default_dataset(name, sensor=args.sensor, seed=args.seed)
        path = default_dataset_path(name, args.sensor, args.seed)
        print(
            f"{name:16s} {len(dataset):6d} taps {path.stat().st_size / 1e6:6.1f} MB "
            f"{time.perf_counter() - start:6.1f} s  {path}"
        )
    return 0


def _load_named_dataset(name_or_path: str, sensor: str, seed: int):
    from tactile_braille.datasets.cache import DEFAULT_DATASETS, default_dataset
    from tactile_braille.datasets.store import load_dataset

    if not Path(name_or_path).exists() and name_or_path in DEFAULT_DATASETS:
        return default_dataset(name_or_path, sensor=sensor, seed=seed)
    return load_dataset(name_or_path)


def _classify(args: argparse.Namespace) -> int:
    import torch

    from tactile_braille.supervised.classifier import (
        ClassifierConfig,
        confusion_matrix,
        predict,
        save_classifier,
        select_classes,
        train_classifier,
    )
    from tactile_braille.supervised.report import save_confusion_matrix, top_confusions

    torch.set_num_threads(args.threads)
    train = _load_named_dataset(args.train, args.sensor, 0)
    validation = _load_named_dataset(args.validation, args.sensor, 0)
    config = ClassifierConfig(max_epochs=args.epochs, seed=args.seed)
    start = time.perf_counter()
    result = train_classifier(train, validation, config, progress=True)
    images, labels = select_classes(validation, config.classes)
    truth = [config.classes[i] for i in labels]
    predicted = predict(result.model, images, config.classes)
    accuracy = float((predicted == np.asarray(truth)).mean())
    matrix = confusion_matrix(np.asarray(truth), predicted, config.classes)
    mistakes = top_confusions(matrix, config.classes)
    output = Path(args.output or f"runs/classifier__seed{args.seed}__{time.strftime('%Y%m%d-%H%M%S')}")
    metrics = {"val_accuracy": accuracy, "top_confusions": mistakes}
    metrics.update(train=str(train.path), validation=str(validation.path))
    save_classifier(result, output, metrics)
    save_confusion_matrix(matrix, config.classes, output / "confusion.png",
                          f"validation accuracy {accuracy:.1%} ({len(truth)} images)")  # fmt: skip
    print(f"validation accuracy {accuracy:.2%} on {len(truth)} images, best epoch {result.best_epoch}, "
          f"{time.perf_counter() - start:.0f} s")  # fmt: skip
    for mistake in mistakes[:5]:
        print(
            f"  {mistake['true']} -> {mistake['predicted']}: {mistake['count']}"
            + (f" (differ by dots {mistake['dots_differing']})" if "dots_differing" in mistake else "")
        )
    print(f"wrote {output}")
    return 0


def _train(args: argparse.Namespace) -> int:
    from tactile_braille.agents.presets import preset_config
    from tactile_braille.agents.train import train

    if args.resume is not None:
        run = train(run_dir=args.resume, resume=True, progress=not args.quiet)
    else:
        if args.task is None:
            raise ValueError("give a TASK (an environment id) or --resume RUN_DIR")
        task = args.task if "/" in args.task else f"tactile_braille/{args.task}"
        overrides = {
            name: getattr(args, name)
            for name in ("seed", "epochs", "backend", "device", "precision", "threads", "test_episodes",
                         "updates_per_step", "checkpoint_every")
            if getattr(args, name) is not None
        }  # fmt: skip
        if args.no_her:
            overrides["her"] = False
        agent = {"shared_encoder": True} if args.shared_encoder else {}
        if args.shared_encoder and args.algo == "dqn":
            raise ValueError("--shared-encoder is for actor-critic agents (sac_discrete, sac, td3)")
        config = preset_config(args.preset, task, args.algo, agent=agent, **overrides)
        run = train(config, run_dir=args.run_dir, progress=not args.quiet)
    print(f"run folder: {run}")
    return 0


def _report(args: argparse.Namespace) -> int:
    from tactile_braille.agents.report import write_report

    for run in args.runs:
        report = write_report(run, episodes=args.episodes)
        print(report.read_text())
        print(f"wrote {report} and {report.parent / 'curve.png'}")
    if args.output is not None:
        from tactile_braille.evaluation.report import write_report as write_results

        results = write_results(args.runs, args.output, title=args.title)
        print(results.read_text().split("![training curves]")[0])
        print(f"wrote {results} and its figures")
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    from tactile_braille.evaluation import evaluate_typing

    for run in args.runs:
        result = evaluate_typing(run, sentences=not args.no_sentences, seed=args.seed)
        print(f"{run}: typing accuracy {result['accuracy']:.3f} over {result['keys_asked']} keys "
              f"({result['sequences']} sequences), {result['total_steps']} steps")  # fmt: skip
        for sentence in result.get("sentences", []):
            score = f"({sentence['accuracy']:.0%}, {sentence['steps']} steps)"
            print(f"  {sentence['text']}\n  {sentence['typed']}  {score}")
        print(f"wrote {run / 'typing.json'} and {run / 'typing_confusion.png'}")
    return 0


def _sweep_overrides(args: argparse.Namespace) -> dict:
    return {name: getattr(args, name) for name in ("epochs", "precision", "backend", "threads")
            if getattr(args, name, None) is not None}  # fmt: skip


def _run_sweep(args: argparse.Namespace, trials) -> int:
    from tactile_braille.evaluation.report import write_report
    from tactile_braille.sweep import sweep

    use_ray = {"auto": None, "yes": True, "no": False}[args.ray]
    runs = sweep(trials, args.root, use_ray=use_ray, address=args.address, cpus_per_trial=args.cpus_per_trial,
                 max_failures=args.max_failures)  # fmt: skip
    if args.report is not None:
        report = write_report(runs, args.report, title=args.title)
        print(f"wrote {report}")
    return 0


def _sweep(args: argparse.Namespace) -> int:
    from tactile_braille.sweep import plan

    return _run_sweep(args, plan(args.tasks, args.algos, args.seeds, args.preset, **_sweep_overrides(args)))


def _benchmark(args: argparse.Namespace) -> int:
    from tactile_braille.sweep import PAPER_SIM_RUNS, Trial

    if not args.paper:
        raise ValueError("say which benchmark: --paper (the simulated part of the paper's Table III)")
    overrides = _sweep_overrides(args)
    trials = [Trial(task, algo, seed, "paper", overrides) for task, algo in PAPER_SIM_RUNS
              for seed in range(args.num_seeds)]  # fmt: skip
    args.report = args.report or Path(args.root) / "report"
    return _run_sweep(args, trials)


def _add_sweep_options(parser: argparse.ArgumentParser, root: str) -> None:
    parser.add_argument("--epochs", type=int, default=None, help="default: each preset's")
    parser.add_argument("--precision", choices=("fp32", "bf16"), default=None)
    parser.add_argument("--threads", type=int, default=None, help="torch threads per trial")
    parser.add_argument("--root", type=Path, default=Path(root), help=f"run folders go here (default {root})")
    parser.add_argument("--ray", choices=("auto", "yes", "no"), default="auto",
                        help="run trials on Ray Tune (auto: when installed)")  # fmt: skip
    parser.add_argument("--address", default=None, help="Ray cluster address (default: a local Ray)")
    parser.add_argument("--cpus-per-trial", type=float, default=2)
    parser.add_argument("--max-failures", type=int, default=2, help="retries of a failed trial")
    parser.add_argument("--title", default="Results", help="title of the report")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``tactile-braille``."""
    parser = argparse.ArgumentParser(
        prog="tactile-braille", description="Learning to type on a braille keyboard by touch."
    )
    commands = parser.add_subparsers(dest="command", required=True)

    show = commands.add_parser("show", help="write a gallery PNG of live renders or of a dataset")
    show.add_argument(
        "dataset", nargs="?", help="a dataset file or a default dataset's name (default: live renders)"
    )
    show.add_argument("--output", default="outputs/gallery.png", help="PNG to write")
    show.add_argument("--sensor", default="braille_331", choices=sorted(PRESETS))
    show.add_argument("--depth", type=float, default=5.0, help="tap depth in mm (default 5)")
    show.add_argument("--seed", type=int, default=0, help="seed of the sensor nuisances")
    show.set_defaults(handler=_show)

    collect = commands.add_parser("collect", help="run a collection procedure on a rig into a dataset")
    collect.add_argument("--procedure", choices=("perturbed", "grid"), default="perturbed")
    collect.add_argument("--keys", choices=("arrows", "alphabet", "all"), default="all")
    collect.add_argument("--rig", choices=("virtual",), default="virtual")
    collect.add_argument("--sensor", default="braille_331", choices=sorted(PRESETS))
    collect.add_argument("--output", type=Path, required=True, help="dataset file (.h5) to write")
    collect.add_argument("--seed", type=int, default=0)
    collect.add_argument("--resume", action="store_true", help="continue an interrupted collection")
    collect.add_argument("--per-key", type=int, default=100, help="perturbed: taps per key")
    collect.add_argument("--split", choices=("train", "validation"), default="train")
    collect.add_argument("--spacing-mm", type=float, default=None, help="grid: x/y step (paper's)")
    collect.add_argument("--depth-step-mm", type=float, default=None, help="grid: depth step (paper's)")
    collect.set_defaults(handler=_collect)

    importer = commands.add_parser("import", help="import the original release's csv + mp4 recordings")
    importer.add_argument("csv", type=Path, help="targets_video.csv")
    importer.add_argument("--output", type=Path, required=True)
    importer.add_argument("--videos", type=Path, default=None, help="video folder (default: videos/)")
    importer.add_argument("--grid-frame", choices=("alphabet", "arrows"), default=None)
    importer.add_argument("--resume", action="store_true")
    importer.set_defaults(handler=_import)

    classify = commands.add_parser("classify", help="train and evaluate the supervised key classifier")
    classify.add_argument("--train", default="keys-train", help="dataset file or default dataset name")
    classify.add_argument("--validation", default="keys-validation", help="dataset file or default name")
    classify.add_argument(
        "--output", type=Path, default=None, help="run folder (default: runs/classifier__...)"
    )
    classify.add_argument("--epochs", type=int, default=60, help="maximum epochs (early stopping)")
    classify.add_argument("--seed", type=int, default=0)
    classify.add_argument("--sensor", default="braille_331", choices=sorted(PRESETS))
    classify.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    classify.set_defaults(handler=_classify)

    trainer = commands.add_parser(
        "train", help="train an agent on a task (checkpointed, resumable)",
        description="Settings come from --preset (the paper's Table II by default); options override them.",
    )  # fmt: skip
    trainer.add_argument("task", nargs="?", help="environment id, e.g. DiscreteArrows-v0")
    trainer.add_argument("algo", nargs="?", default="dqn", choices=("dqn", "sac_discrete", "sac", "td3"))
    trainer.add_argument(
        "--preset",
        choices=("paper", "released"),
        default="paper",
        help="the paper's hyperparameters or the released code's (docs/agents.md)",
    )
    trainer.add_argument("--seed", type=int, default=None, help="default 0")
    trainer.add_argument("--epochs", type=int, default=None, help="default: the preset's")
    trainer.add_argument("--backend", choices=("dataset", "render"), default=None)
    trainer.add_argument("--device", default=None, help="cpu (default) or cuda")
    trainer.add_argument(
        "--precision",
        choices=("fp32", "bf16"),
        default=None,
        help="bf16: bfloat16 autocast in the updates (default fp32)",
    )
    trainer.add_argument("--threads", type=int, default=None, help="torch CPU threads (default 2)")
    trainer.add_argument("--test-episodes", type=int, default=None)
    trainer.add_argument("--updates-per-step", type=int, default=None)
    trainer.add_argument("--checkpoint-every", type=int, default=None, help="epochs (default 1)")
    trainer.add_argument(
        "--shared-encoder",
        action="store_true",
        help="actor reuses the critic's encoder, detached (not the paper's setting)",
    )
    trainer.add_argument("--no-her", action="store_true", help="turn hindsight relabelling off")
    trainer.add_argument("--run-dir", type=Path, default=None, help="run folder (default: runs/...)")
    trainer.add_argument("--resume", type=Path, default=None, metavar="RUN_DIR", help="continue a run")
    trainer.add_argument("--quiet", action="store_true", help="no progress bar")
    trainer.set_defaults(handler=_train)

    report = commands.add_parser("report", help="reports of training runs (and over runs and seeds)")
    report.add_argument("runs", nargs="+", type=Path, metavar="RUN_DIR")
    report.add_argument("--episodes", type=int, default=100, help="final test episodes (default 100)")
    report.add_argument(
        "--output",
        type=Path,
        default=None,
        help="also write OUTPUT/results.md over all runs (Table III, curves, typing, Figure 4)",
    )
    report.add_argument("--title", default="Results", help="title of results.md")
    report.set_defaults(handler=_report)

    evaluate = commands.add_parser("evaluate", help="the paper's typing evaluation of a training run")
    evaluate.add_argument("runs", nargs="+", type=Path, metavar="RUN_DIR")
    evaluate.add_argument("--no-sentences", action="store_true", help="alphabet tasks: skip the sentences")
    evaluate.add_argument("--seed", type=int, default=0, help="seed of the start poses")
    evaluate.set_defaults(handler=_evaluate)

    sweeper = commands.add_parser("sweep", help="train tasks x algorithms x seeds (Ray Tune when installed)")
    sweeper.add_argument(
        "--tasks", nargs="+", required=True, help="e.g. DiscreteArrows-v0 DiscreteAlphabet-v0"
    )
    sweeper.add_argument("--algos", nargs="+", required=True, choices=("dqn", "sac_discrete", "sac", "td3"))
    sweeper.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    sweeper.add_argument("--preset", choices=("paper", "released"), default="paper")
    sweeper.add_argument("--backend", choices=("dataset", "render"), default=None)
    sweeper.add_argument("--report", type=Path, default=None, help="write REPORT/results.md over the runs")
    _add_sweep_options(sweeper, "runs/sweep")
    sweeper.set_defaults(handler=_sweep)

    bench = commands.add_parser("benchmark", help="reproduce the simulated part of the paper's Table III")
    bench.add_argument("--paper", action="store_true", help="the paper's 8 simulated task x algorithm runs")
    bench.add_argument("--num-seeds", type=int, default=3)
    bench.add_argument("--report", type=Path, default=None, help="default: ROOT/report")
    _add_sweep_options(bench, "runs/paper-benchmark")
    bench.set_defaults(handler=_benchmark)

    data = commands.add_parser("data", help="generate (or reuse) the default datasets in the cache")
    data.add_argument("--sensor", default="braille_331", choices=sorted(PRESETS))
    data.add_argument("--seed", type=int, default=0)
    data.set_defaults(handler=_data)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``tactile-braille``."""
    args = build_parser().parse_args(argv)
    try:
        return args.handler(args)
    except (FileExistsError, FileNotFoundError, ValueError) as error:
        # DatasetError is a ValueError: bad input gets its message, not a traceback.
        print(f"tactile-braille: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
