"""The ``tactile-braille`` command: thin wrappers over the library."""

from __future__ import annotations

import argparse
import contextlib
import os
import shlex
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from tactile_braille._io import LockedError
from tactile_braille._tasks import KEY_SETS
from tactile_braille.agents.config import BACKENDS, PRECISIONS
from tactile_braille.agents.presets import PRESETS as TRAINING_PRESETS
from tactile_braille.agents.registry import agent_names
from tactile_braille.gallery import GALLERY_DEPTH_MM
from tactile_braille.rigs.base import RigError
from tactile_braille.sensor.config import PRESETS as SENSORS


def _output_file(path, option: str = "--output") -> Path:
    """An output file's path, refused (before any work) where it is a folder."""
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{option} {path} is a folder; name the file to write (e.g. {path / 'out.png'})")
    return path


def _show(args: argparse.Namespace) -> int:
    from tactile_braille._figures import save_figure
    from tactile_braille.gallery import dataset_figure, live_gallery_tiles, save_gallery

    _output_file(args.output)
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
    rig, _ = _open_ur5(args.rig_config, simulated=args.rig == "simulated-ur5")
    return rig


def _ur5_hardware(
    config_path: Path | None,
    simulated: bool,
    dry_run: bool = False,
    command: str = "the rig",
    option="--config",
):
    """The UR5 rig's settings, its drivers and, on simulated hardware, the simulated world.

    Simulated hardware takes ``config_path``'s frames, or the simulated defaults without one; the real
    robot needs its settings file. ``dry_run`` logs the arm's commands instead of sending them.
    """
    import dataclasses

    from tactile_braille.rigs.ur5 import UR5Config

    if simulated:
        from tactile_braille.rigs.fakes import SimulatedUR5, simulated_config

        config = UR5Config.load(config_path) if config_path is not None else simulated_config()
        config = dataclasses.replace(config, dry_run=dry_run or config.dry_run)
        world = SimulatedUR5(config)
        return config, world.drivers(), world
    if config_path is None:
        raise ValueError(f"{command} needs the rig's settings: {option} rig.json (see docs/hardware.md)")
    from tactile_braille.rigs.hardware import real_drivers

    config = UR5Config.load(config_path)
    return dataclasses.replace(config, dry_run=dry_run or config.dry_run), real_drivers(), None


def _open_ur5(config_path: Path | None, simulated: bool, dry_run: bool = False):
    """The UR5 rig of ``config_path``, or a simulated one, and its simulated world (None on hardware)."""
    from tactile_braille.rigs.ur5 import UR5Rig

    config, drivers, world = _ur5_hardware(config_path, simulated, dry_run, "the UR5 rig", "--rig-config")
    return UR5Rig(config, drivers=drivers), world


def _print_commands(commands) -> None:
    for name, command_args in commands:
        shown = ", ".join(
            "[" + ", ".join(f"{v:.5f}" for v in a) + "]" if isinstance(a, list) else f"{a}"
            for a in command_args
        )
        print(f"  {name}({shown})")


def _layout_keys(text: str, option: str) -> list[str]:
    """Comma-separated key names, each checked against the keyboard's layout."""
    from tactile_braille.keyboard.layout import KeyboardLayout

    keys = [key.strip() for key in text.split(",") if key.strip()]
    known = {key.name for key in KeyboardLayout().keys}
    unknown = [key for key in keys if key not in known]
    if unknown or not keys:
        raise ValueError(
            f"{option}: unknown keys {unknown or [text]}; the keyboard's keys are e.g. A, SPACE, UP"
        )
    return keys


def _rig_check(args: argparse.Namespace) -> int:
    from tactile_braille.sensor.processing import process_frame

    simulated = args.simulated or args.config is None
    keys = _layout_keys(args.keys, "--keys")
    rig, world = _open_ur5(args.config, simulated=simulated, dry_run=args.dry_run)
    mode = ("simulated hardware" if simulated else str(args.config)) + (
        ", dry run" if rig.config.dry_run else ""
    )
    print(f"UR5 rig check ({mode}): taps at depth {args.depth} mm on {args.keys}")
    with rig:
        for key in keys:
            x, y = rig.layout.centre_mm(key)
            sample = rig.tap(x, y, args.depth)
            white = float((process_frame(sample.frame, rig.processing) > 0).mean())
            print(f"{key:>6}: pressed {sample.pressed_key or 'nothing'}, "
                  f"{rig.stats['last_tap_time_s']:.3f} s, observation {white:.1%} white")  # fmt: skip
        sent = list(rig.arm.sent)
    print(f"arm commands ({'logged, not sent' if rig.config.dry_run else 'sent'}; m, rad, m/s, m/s^2):")
    _print_commands(sent)
    if world is not None and not rig.config.dry_run:
        print(f"simulated keyboard registered: {world.pressed_log}")
    return 0


def _rig_calibrate(args: argparse.Namespace) -> int:
    import dataclasses

    from tactile_braille.rigs.calibration import ask_operator, fit_work_frame, record_reference_poses
    from tactile_braille.rigs.hardware import URArm
    from tactile_braille.rigs.transforms import tcp_offset_to_ur

    keys = [k.strip() for k in args.keys.split(",")]
    config, drivers, world = _ur5_hardware(args.config, args.simulated, command="calibrate")
    wait = world.jog_to_key_top if world is not None else ask_operator  # a simulated operator
    # Read only: no control script is started, the operator jogs from the pendant.
    arm = URArm(drivers, config.host, tcp_offset_to_ur(config.tcp_offset_mm_deg), dry_run=True)
    try:
        poses = record_reference_poses(arm.tool_pose, keys, wait)
    finally:
        arm.close()
    fit = fit_work_frame(poses, config.clearance_mm)
    print("work_frame_mm_deg:", "[" + ", ".join(f"{v:.3f}" for v in fit.work_frame_mm_deg) + "]")
    for key, residual in fit.residuals_mm.items():
        print(f"  {key:>6}: residual {residual:.2f} mm")
    print(f"rms {fit.rms_mm:.2f} mm; key-top heights spread {fit.height_spread_mm:.2f} mm")
    if args.write:
        if args.config is None:
            raise ValueError("--write needs --config (the file to update)")
        dataclasses.replace(config, work_frame_mm_deg=fit.work_frame_mm_deg).save(args.config)
        print(f"wrote {args.config}")
    return 0


def _rig_crop(args: argparse.Namespace) -> int:
    import dataclasses

    from tactile_braille.rigs.calibration import propose_crop_box, save_threshold_preview
    from tactile_braille.rigs.hardware import TacTipCamera
    from tactile_braille.sensor.config import sensor_preset

    _output_file(args.output)
    config, drivers, _ = _ur5_hardware(args.config, args.simulated, command="crop")
    camera = TacTipCamera(drivers, config.camera_index, config.camera_size_px, config.camera_exposure)
    try:
        frame = camera.read()
    finally:
        camera.close()
    if frame is None:
        raise RigError("the camera returned no frame")
    crop = propose_crop_box(frame)
    processing = dataclasses.replace(sensor_preset(config.sensor).processing, crop_px=crop)
    path = save_threshold_preview(frame, processing, args.output)
    print(f"proposed crop_px: {list(crop)}; wrote {path} (check the observation's pins are clean dots)")
    if args.write:
        if args.config is None:
            raise ValueError("--write needs --config (the file to update)")
        dataclasses.replace(config, crop_px=crop).save(args.config)
        print(f"wrote {args.config}")
    return 0


def _keycaps(args: argparse.Namespace) -> int:
    from tactile_braille.keyboard.keycaps import KeycapGeometry, write_keycaps
    from tactile_braille.keyboard.layout import ALL_TASK_KEYS, KeyboardLayout

    layout = KeyboardLayout()
    keys = (
        ALL_TASK_KEYS
        if args.keys is None
        else tuple(dict.fromkeys(k.strip().upper() for k in args.keys.split(",")))
    )
    unknown = [k for k in keys if k not in layout]
    if unknown:
        raise ValueError(f"unknown keys {unknown}; e.g. A, SPACE, UP (the layout's names)")
    start = time.perf_counter()
    paths = write_keycaps(args.out, keys, KeycapGeometry(resolution_mm=args.resolution_mm), layout)
    size_mb = sum(p.stat().st_size for p in paths) / 1e6
    print(f"wrote {len(paths) - 1} STL keycaps and {paths[-1].name} to {args.out} "
          f"({size_mb:.1f} MB, {time.perf_counter() - start:.1f} s)")  # fmt: skip
    return 0


def _collect(args: argparse.Namespace) -> int:
    from tactile_braille.datasets.collector import collect
    from tactile_braille.datasets.procedures import GridTaps, PerturbedTaps

    if args.procedure == "perturbed":
        bounds = ("position_range_mm", "depth_range_mm", "yaw_range_deg")
        jitter = {name: getattr(args, name) for name in bounds if getattr(args, name) is not None}
        procedure = PerturbedTaps(
            keys=args.keys, per_key=args.per_key, split=args.split, seed=args.seed, **jitter
        )
    else:
        if args.keys == "all":
            raise ValueError("a grid covers one task's work frame: choose --keys alphabet or --keys arrows")
        procedure = GridTaps(keys=args.keys, spacing_mm=args.spacing_mm, depth_step_mm=args.depth_step_mm)
    start = time.perf_counter()
    with _make_rig(args) as rig:
        path = collect(rig, procedure, args.output, seed=args.seed, resume=args.resume, restart=args.restart)
    size_mb = path.stat().st_size / 1e6
    print(f"wrote {path}: {len(procedure)} taps, {size_mb:.1f} MB, {time.perf_counter() - start:.1f} s")
    return 0


def _import(args: argparse.Namespace) -> int:
    from tactile_braille.datasets.importer import import_original

    path = import_original(
        args.csv,
        args.output,
        videos_dir=args.videos,
        grid_frame=args.grid_frame,
        resume=args.resume,
        restart=args.restart,
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

    from tactile_braille.supervised.classifier import ClassifierConfig, train_classifier
    from tactile_braille.supervised.report import evaluate_classifier

    output = Path(args.output or f"runs/classifier__seed{args.seed}__{time.strftime('%Y%m%d-%H%M%S')}")
    if output.exists() and not (output.is_dir() and args.overwrite):  # checked before the training
        raise FileExistsError(
            f"--output {output} exists; choose another folder"
            + (" (or pass --overwrite to replace it)" if output.is_dir() else " (it is a file)")
        )
    torch.set_num_threads(args.threads)
    train = _load_named_dataset(args.train, args.sensor, 0)
    validation = _load_named_dataset(args.validation, args.sensor, 0)
    start = time.perf_counter()
    config = ClassifierConfig(max_epochs=args.epochs, seed=args.seed)
    result = train_classifier(train, validation, config, progress=True)
    scored = evaluate_classifier(result, validation, output, train_path=train.path)
    print(f"validation accuracy {scored.accuracy:.2%} on {scored.images} images, "
          f"best epoch {result.best_epoch}, {time.perf_counter() - start:.0f} s")  # fmt: skip
    for mistake in scored.mistakes[:5]:
        print(
            f"  {mistake['true']} -> {mistake['predicted']}: {mistake['count']}"
            + (f" (differ by dots {mistake['dots_differing']})" if "dots_differing" in mistake else "")
        )
    print(f"wrote {output}")
    return 0


def _train(args: argparse.Namespace) -> int:
    # Checked before torch loads and before anything is written.
    config = _resume_config(args) if args.resume is not None else _train_config(args)
    from tactile_braille.agents.training import train

    rig = None
    if args.rig_config is not None or args.simulated_rig:
        rig, _ = _open_ur5(args.rig_config, simulated=args.simulated_rig)
    try:
        run = train(config, run_dir=args.resume or args.run_dir, resume=args.resume is not None,
                    progress=not args.quiet, rig=rig)  # fmt: skip
    finally:
        if rig is not None:
            rig.close()
    print(f"run folder: {run}")
    return 0


def _resume_config(args: argparse.Namespace):
    """A resumed run's settings: the stored ones, with the options given on top (a resume may change only
    the machine settings; :func:`~tactile_braille.agents.run.open_run` refuses the others)."""
    from tactile_braille.agents.config import replace_settings
    from tactile_braille.agents.run import read_config
    from tactile_braille.cli_config import config_overrides

    stored = read_config(args.resume)
    given = {"task": args.task, "algo": args.algo, "preset": args.preset}
    for name, value in given.items():
        wanted = value if name != "task" or value is None or "/" in value else f"tactile_braille/{value}"
        if wanted is not None and wanted != getattr(stored, name):
            raise ValueError(
                f"{args.resume} is a run of {name} {getattr(stored, name)!r}, not {value!r}: a resume takes "
                "the run's own settings (drop it, or start a new run)"
            )
    overrides = config_overrides(args, stored.algo)
    if overrides.get("precision") == "auto":
        del overrides["precision"]  # the run's own: it was chosen when the run began
    return replace_settings(stored, overrides) if overrides else None


def _train_config(args: argparse.Namespace):
    """The run's settings: the preset's, with every option given on top (checked before anything runs)."""
    from tactile_braille.agents.config import replace_settings
    from tactile_braille.agents.presets import preset_config
    from tactile_braille.cli_config import config_overrides, resolve_precision

    if args.task is None:
        raise ValueError("give a TASK (an environment id) or --resume RUN_DIR")
    args.algo, args.preset = args.algo or "dqn", args.preset or "paper"
    overrides = config_overrides(args, args.algo)
    rig = args.rig_config is not None or args.simulated_rig
    if rig and overrides.setdefault("backend", "rig") != "rig":
        raise ValueError(
            f"--rig-config and --simulated-rig train on the rig: drop --backend {overrides['backend']}"
        )
    task = args.task if "/" in args.task else f"tactile_braille/{args.task}"
    precision = overrides.pop("precision", "auto")  # chosen once the settings have passed their checks
    config = preset_config(args.preset, task, args.algo, **overrides)
    return replace_settings(config, {"precision": resolve_precision(precision, config.device)})


def _report(args: argparse.Namespace) -> int:
    from tactile_braille.agents.report import check_run, write_report

    # Every run is read, and a damaged one refused, before anything is written. Without --output each
    # run gets its report in its own folder; with it, OUTPUT is the only place written to.
    for run in args.runs:
        if args.output is None and (run / "config.json").exists() and not (run / "checkpoint.pt").exists():
            raise ValueError(
                f"{run} has no checkpoint to evaluate (an archived record, or a run before its first "
                "epoch ended): table records with --output FILE.md"
            )
        check_run(run, checkpoint=args.output is None)
    if args.output is not None:
        return _report_over_runs(args)
    for run in args.runs:
        report = write_report(run, episodes=args.episodes)
        print(report.read_text())
        print(f"wrote {report} and {report.parent / 'curve.png'}")
    return 0


def _report_over_runs(args: argparse.Namespace) -> int:
    """``report RUN_DIR... --output OUTPUT``: the report over the runs, written under OUTPUT only."""
    from tactile_braille.agents.report import check_run
    from tactile_braille.evaluation.report import unevaluated
    from tactile_braille.evaluation.report import write_report as write_results

    for run in (*args.transfer, *args.warm_start):
        check_run(run, checkpoint=False)
    missing = unevaluated(args.runs)
    if missing:
        more = f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""
        raise ValueError(
            f"{missing[0]}{more} has no typing evaluation of its last epoch: run `tactile-braille evaluate "
            "RUN_DIR...` first (it writes typing.json and result.json in each run's folder)"
        )
    notes = args.notes.read_text() if args.notes is not None else None
    command = "tactile-braille " + _short_command(args.argv) if args.argv else None
    results = write_results(
        args.runs,
        args.output,
        title=args.title,
        notes=notes,
        command=command,
        transfer_dirs=args.transfer,
        warm_dirs=args.warm_start,
        evaluate_missing=False,
    )
    print(results.read_text().split("![training curves]")[0])
    print(f"wrote {results} and its figures")
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    if args.policy is not None:
        return _evaluate_policy(args)
    from tactile_braille.evaluation.runs import RESULT_FILE, evaluate_typing

    for flag in ("method", "output", "train_seed", "env_steps", "epochs", "track", "dataset", "protocol",
                 "backend", "overwrite"):  # fmt: skip
        if getattr(args, flag) is not None and getattr(args, flag) is not False:  # --epochs 0 counts
            raise ValueError(
                f"--{flag.replace('_', '-')} is for --policy; a run's results file takes its own"
            )
    from tactile_braille.agents.report import read_checkpoint
    from tactile_braille.agents.run import read_config

    for run in args.targets:  # every run is read before any is evaluated (and written to)
        if not (run / "config.json").exists():
            raise ValueError(
                f"{run} is not a training run (no config.json); to score a callable, use --policy"
            )
        read_config(run)
        read_checkpoint(run, mmap=True)  # a missing or damaged one: the message a resume gives
    if args.world:
        return _evaluate_transfer(args)
    for run in args.targets:
        result = evaluate_typing(run, sentences=not args.no_sentences, seed=args.seed)
        print(f"{run}: typing accuracy {result['accuracy']:.3f} over {result['keys_asked']} keys "
              f"({result['sequences']} sequences), {result['total_steps']} steps")  # fmt: skip
        for sentence in result.get("sentences", []):
            score = f"({sentence['accuracy']:.0%}, {sentence['steps']} steps)"
            print(f"  {sentence['text']}\n  {sentence['typed']}  {score}")
        print(f"wrote {run / 'typing.json'}, {run / RESULT_FILE} and {run / 'typing_confusion.png'}")
    return 0


def _evaluate_transfer(args: argparse.Namespace) -> int:
    """``evaluate RUN_DIR... --world W``: type in other worlds; writes each run's transfer.json."""
    from tactile_braille.evaluation.runs import TRANSFER_FILE, evaluate_transfer
    from tactile_braille.evaluation.worlds import expand_worlds

    expand_worlds(args.world)  # refuse a mistyped world before any run is loaded
    for run in args.targets:
        output = evaluate_transfer(run, args.world, seed=args.seed)
        for name, scored in output["worlds"].items():
            print(f"{run} in {name}: typing accuracy {scored['accuracy']:.3f} over "
                  f"{scored['keys_asked']} keys, {scored['total_steps']} steps")  # fmt: skip
        print(f"wrote {run / TRANSFER_FILE}")
    return 0


def _evaluate_policy(args: argparse.Namespace) -> int:
    """``evaluate --policy MODULE:NAME TASK``: score a user's callable and write its results file."""
    from tactile_braille.evaluation.results import make_result, write_result
    from tactile_braille.evaluation.scoring import evaluate_policy, load_policy

    if len(args.targets) != 1:
        raise ValueError(f"--policy scores one TASK, got {len(args.targets)} targets")
    if args.world:
        raise ValueError(
            "--world is for RUN_DIRs; a callable types in the live renderer with --backend render"
        )
    if args.method is None or args.output is None:
        raise ValueError("--policy needs --method NAME (free text) and --output FILE.json")
    if args.output.is_dir():
        raise ValueError(f"--output {args.output} is a folder; name the results file (e.g. result.json)")
    if args.output.exists() and not args.overwrite:
        raise FileExistsError(f"{args.output} exists; choose another name or pass --overwrite")
    with _importable_from_cwd():  # the policy's module, and what it imports as it runs
        policy = load_policy(args.policy)
        report = evaluate_policy(
            policy, str(args.targets[0]), protocol=args.protocol or "paper",
            backend=args.backend or "dataset", seed=args.seed,
            track=args.track or "tactile", dataset=args.dataset, sentences=not args.no_sentences,
            progress=sys.stderr.isatty(),  # a bar for a person watching, none in logs
        )  # fmt: skip
    result = make_result(report, method=args.method, seed=args.train_seed, env_steps=args.env_steps,
                         epochs=args.epochs)  # fmt: skip
    path = write_result(result, args.output, overwrite=args.overwrite)
    print(f"{args.method} on {report.task} ({report.track} track, {report.protocol} protocol): "
          f"typing accuracy {report.accuracy:.3f} over {report.keys_asked} keys, {report.total_steps} steps; "
          f"fingerprint {report.fingerprint[:12]}")  # fmt: skip
    print(f"wrote {path}")
    return 0


@contextlib.contextmanager
def _importable_from_cwd():
    """Modules in the current folder import within the block, as they do under ``python -m`` (the
    ``tactile-braille`` script's own folder is first on ``sys.path`` instead)."""
    cwd = os.getcwd()
    added = cwd not in sys.path
    if added:
        sys.path.insert(0, cwd)
    try:
        yield
    finally:
        if added and cwd in sys.path:
            sys.path.remove(cwd)


def _leaderboard(args: argparse.Namespace) -> int:
    from tactile_braille._io import atomic_path
    from tactile_braille.evaluation.leaderboard import (
        headline_markdown,
        leaderboard_markdown,
        load_results,
        plot_performance_profiles,
        write_headline,
    )

    reference = {}
    for item in args.reference:
        task, _, fingerprint = item.partition("=")
        if not fingerprint:
            raise ValueError(f"--reference takes TASK=FINGERPRINT, got {item!r}")
        reference[task] = fingerprint
    if args.output is not None and args.output.is_dir():
        raise ValueError(f"--output {args.output} is a folder; name the page to write (e.g. leaderboard.md)")
    if args.figure is not None and (args.output is None or args.figure.is_dir()):
        raise ValueError(f"--figure {args.figure}: name the PNG to write, with --output (the page links it)")
    results = load_results(args.results)
    link = None
    if args.figure is not None:
        link = Path(os.path.relpath(args.figure.resolve(), args.output.resolve().parent)).as_posix()
    options = {"title": args.title, "reference": reference, "strict": args.strict}
    page = leaderboard_markdown(results, **options, figure=link)
    if args.figure is not None:
        args.figure.parent.mkdir(parents=True, exist_ok=True)
        if plot_performance_profiles(results, args.figure, reference) is None:  # no method is ranked
            page = leaderboard_markdown(results, **options)
        else:
            print(f"wrote {args.figure}")
    if args.headline is not None:
        write_headline(args.headline, headline_markdown(results, reference))
        print(f"wrote the headline table into {args.headline}")
    if args.output is None:
        print(page)
        return 0
    args.output.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.output) as temporary:
        temporary.write_text(page)
    print(f"wrote {args.output} ({len(args.results)} results)")
    return 0


SWEEP_RUN_OPTIONS = ("epochs", "precision", "backend", "threads", "device")
"""Run settings that ``sweep`` and ``benchmark`` take as options of their own (for every trial)."""


def _sweep_overrides(args: argparse.Namespace) -> dict:
    return {name: getattr(args, name) for name in SWEEP_RUN_OPTIONS
            if getattr(args, name, None) is not None}  # fmt: skip


def _run_sweep(args: argparse.Namespace, trials) -> int:
    from tactile_braille.evaluation.report import write_report
    from tactile_braille.sweep import sweep

    use_ray = {"auto": None, "yes": True, "no": False}[args.ray]
    runs = sweep(trials, args.root, use_ray=use_ray, address=args.address, cpus_per_trial=args.cpus_per_trial,
                 max_failures=args.max_failures, jobs=args.jobs, archive=args.archive)  # fmt: skip
    if args.report is not None:
        report = write_report(runs, args.report, title=args.title)
        print(f"wrote {report}")
    return 0


def _sweep(args: argparse.Namespace) -> int:
    from tactile_braille.agents.run import MACHINE_SETTINGS
    from tactile_braille.cli_config import config_overrides
    from tactile_braille.sweep import plan

    settings = {algo: config_overrides(args, algo) for algo in args.algos}
    # Where a run is made (the dataset's file, say) is no variant of the preset: archives and resumes
    # ignore it too.
    changed = {name for changes in settings.values() for name in changes} - set(MACHINE_SETTINGS)
    if changed and not args.variant:
        raise ValueError("settings that change the preset need a --variant NAME: it names the trials' "
                         "folders, so that they are never taken for the preset's own runs")  # fmt: skip
    if args.variant and not changed:
        raise ValueError(f"--variant {args.variant} names no setting that changes the preset: its trials "
                         "would be the preset's own runs under another name")  # fmt: skip
    trials = plan(args.tasks, args.algos, args.seeds, args.preset, variant=args.variant or "",
                  settings=settings, **_sweep_overrides(args))  # fmt: skip
    return _run_sweep(args, trials)


def _benchmark(args: argparse.Namespace) -> int:
    from tactile_braille.sweep import PAPER_SIM_RUNS, Trial

    if not args.paper:
        raise ValueError("say which benchmark: --paper (the simulated part of the paper's Table III)")
    overrides = _sweep_overrides(args)
    for wanted, names, what in ((args.tasks, {t for t, _ in PAPER_SIM_RUNS}, "tasks"),
                                (args.algos, {a for _, a in PAPER_SIM_RUNS}, "algorithms")):  # fmt: skip
        if set(wanted or ()) - names:
            raise ValueError(
                f"no Table III rows for {sorted(set(wanted) - names)}; the {what} are {sorted(names)}"
            )
    rows = [(task, algo) for task, algo in PAPER_SIM_RUNS
            if (not args.tasks or task in args.tasks) and (not args.algos or algo in args.algos)]  # fmt: skip
    if not rows:
        raise ValueError(f"Table III has no row of {args.algos} on {args.tasks}")
    seeds = args.seeds if args.seeds is not None else range(args.num_seeds)
    root, archive, report = Path(args.root), args.archive, args.report
    for preset in args.presets:  # each preset's trials in its own folder (and archive folder)
        trials = [Trial(task, algo, seed, preset, overrides) for task, algo in rows for seed in seeds]
        args.root, args.archive = root / preset, archive / preset if archive else None
        args.report = (report or root / "report") / preset
        _run_sweep(args, trials)
    return 0


def _add_sweep_options(parser: argparse.ArgumentParser, root: str) -> None:
    parser.add_argument("--epochs", type=int, default=None, help="default: each preset's")
    parser.add_argument("--precision", choices=PRECISIONS, default=None)
    parser.add_argument("--threads", type=int, default=None, help="torch threads per trial")
    parser.add_argument("--root", type=Path, default=Path(root), help=f"run folders go here (default {root})")
    parser.add_argument("--ray", choices=("auto", "yes", "no"), default="auto",
                        help="run trials on Ray Tune (auto: when installed)")  # fmt: skip
    parser.add_argument("--address", default=None, help="Ray cluster address (default: a local Ray)")
    parser.add_argument("--cpus-per-trial", type=float, default=2)
    parser.add_argument("--max-failures", type=int, default=2, help="retries of a failed trial")
    parser.add_argument("--title", default="Results", help="title of the report")
    parser.add_argument("--device", default=None, help="torch device of every trial (cpu, cuda, cuda:N)")
    parser.add_argument("--jobs", type=int, default=1,
                        help="without Ray: trials run side by side, each in its own process")  # fmt: skip
    parser.add_argument("--archive", type=Path, default=None,
                        help="copy each finished trial's record (no checkpoint) here; trials archived "
                        "complete are not run again")  # fmt: skip


def _add_show_command(commands) -> None:
    """The ``show`` command."""
    show = commands.add_parser("show", help="write a gallery PNG of live renders or of a dataset")
    show.add_argument(
        "dataset", nargs="?", help="a dataset file or a default dataset's name (default: live renders)"
    )
    show.add_argument("--output", default="outputs/gallery.png", help="PNG to write")
    show.add_argument("--sensor", default="braille_331", choices=sorted(SENSORS))
    show.add_argument(
        "--depth",
        type=float,
        default=GALLERY_DEPTH_MM,
        help=f"tap depth in mm ({GALLERY_DEPTH_MM}: no key registers)",
    )
    show.add_argument("--seed", type=_non_negative, default=0, help="seed of the sensor nuisances")
    show.set_defaults(handler=_show)


def _add_collect_command(commands) -> None:
    """The ``collect`` command."""
    collect = commands.add_parser("collect", help="run a collection procedure on a rig into a dataset")
    collect.add_argument("--procedure", choices=("perturbed", "grid"), default="perturbed")
    collect.add_argument("--keys", choices=(*KEY_SETS, "all"), default="all")
    collect.add_argument(
        "--rig", choices=("virtual", "ur5", "simulated-ur5"), default="virtual",
        help="ur5: the real robot (--rig-config); simulated-ur5: the UR5 code path on simulated hardware",
    )  # fmt: skip
    collect.add_argument("--rig-config", type=Path, default=None, help="the UR5 rig's settings (JSON)")
    collect.add_argument("--sensor", default="braille_331", choices=sorted(SENSORS))
    collect.add_argument("--output", type=Path, required=True, help="dataset file (.h5) to write")
    collect.add_argument("--seed", type=_non_negative, default=0)
    collect.add_argument("--resume", action="store_true", help="continue an interrupted collection")
    collect.add_argument(
        "--restart",
        action="store_true",
        help="discard an interrupted collection (OUTPUT.partial) and start again",
    )
    collect.add_argument("--per-key", type=int, default=100, help="perturbed: taps per key")
    collect.add_argument("--split", choices=("train", "validation"), default="train")
    collect.add_argument(
        "--position-range-mm",
        type=float,
        default=None,
        help="perturbed: x and y drawn within +- this of each key's centre (the paper's 1)",
    )
    collect.add_argument(
        "--depth-range-mm",
        type=float,
        nargs=2,
        default=None,
        metavar=("LOW", "HIGH"),
        help="perturbed: the tap depth's offset from 5 mm, drawn in [LOW, HIGH] (the paper's -1 0)",
    )
    collect.add_argument("--yaw-range-deg", type=float, default=None,
                         help="perturbed: the sensor turned within +- this (the paper's 10)")  # fmt: skip
    collect.add_argument("--spacing-mm", type=float, default=None, help="grid: x/y step (paper's)")
    collect.add_argument("--depth-step-mm", type=float, default=None, help="grid: depth step (paper's)")
    collect.set_defaults(handler=_collect)


def _add_import_command(commands) -> None:
    """The ``import`` command."""
    importer = commands.add_parser("import", help="import the original release's csv + mp4 recordings")
    importer.add_argument("csv", type=Path, help="targets_video.csv")
    importer.add_argument("--output", type=Path, required=True)
    importer.add_argument("--videos", type=Path, default=None, help="video folder (default: videos/)")
    importer.add_argument("--grid-frame", choices=("alphabet", "arrows"), default=None)
    importer.add_argument("--resume", action="store_true", help="continue an interrupted import")
    importer.add_argument(
        "--restart",
        action="store_true",
        help="discard an interrupted import (OUTPUT.partial), e.g. after a fix",
    )
    importer.set_defaults(handler=_import)


def _add_classify_command(commands) -> None:
    """The ``classify`` command."""
    classify = commands.add_parser("classify", help="train and evaluate the supervised key classifier")
    classify.add_argument("--train", default="keys-train", help="dataset file or default dataset name")
    classify.add_argument("--validation", default="keys-validation", help="dataset file or default name")
    classify.add_argument(
        "--output", type=Path, default=None, help="run folder (default: runs/classifier__...)"
    )
    classify.add_argument("--epochs", type=int, default=60, help="maximum epochs (early stopping)")
    classify.add_argument("--seed", type=_non_negative, default=0)
    classify.add_argument("--sensor", default="braille_331", choices=sorted(SENSORS))
    classify.add_argument(
        "--threads", type=_positive, default=1, help="torch CPU threads (default 1: one per process)"
    )
    classify.add_argument("--overwrite", action="store_true", help="replace an existing --output folder")
    classify.set_defaults(handler=_classify)


def _add_train_command(commands) -> None:
    """The ``train`` command: a preset, every setting of the run as an option on top of it."""
    from tactile_braille.cli_config import add_config_options

    trainer = commands.add_parser(
        "train", help="train an agent on a task (checkpointed, resumable)",
        usage="tactile-braille train [TASK [ALGO]] [--preset NAME] [--SETTING VALUE ...] [--resume RUN_DIR]",
        description="Settings come from --preset (the paper's Table II by default); every option below "
        "overrides the preset's value (docs/agents.md lists them).",
    )  # fmt: skip
    trainer.add_argument("task", nargs="?", help="environment id, e.g. DiscreteArrows-v0")
    trainer.add_argument("algo", nargs="?", choices=agent_names(), help="default dqn")
    trainer.add_argument(
        "--preset", choices=TRAINING_PRESETS,
        help="the paper's hyperparameters (default), the released code's, or ours (fast)",
    )  # fmt: skip
    trainer.add_argument("--run-dir", type=Path, default=None, help="run folder (default: runs/...)")
    trainer.add_argument(
        "--resume", type=Path, default=None, metavar="RUN_DIR",
        help="continue a run from its last checkpoint, with its settings (--epochs N extends it; "
        "--threads, --device and --dataset may change; any other change is refused)",
    )  # fmt: skip
    trainer.add_argument("--quiet", action="store_true", help="no progress bar")
    rig = trainer.add_argument_group("a robot (implies --backend rig)")
    rig.add_argument("--rig-config", type=Path, default=None, help="the UR5 rig's settings (JSON)")
    rig.add_argument("--simulated-rig", action="store_true", help="the UR5 code path on simulated hardware")
    add_config_options(trainer)
    trainer.set_defaults(handler=_train)


def _add_report_command(commands) -> None:
    """The ``report`` command."""
    report = commands.add_parser(
        "report", help="reports of training runs (and over runs and seeds)",
        description="Writes each run's report.md and curve.png in its folder; with --output, only the "
        "report over the runs, under OUTPUT. Every run is checked before anything is written.",
    )  # fmt: skip
    report.add_argument("runs", nargs="+", type=Path, metavar="RUN_DIR")
    report.add_argument(
        "--transfer",
        nargs="+",
        type=Path,
        default=(),
        metavar="RUN_DIR",
        help="--output: runs whose transfer.json (evaluate --world) gets a section of its own",
    )
    report.add_argument(
        "--warm-start", nargs="+", type=Path, default=(), metavar="RUN_DIR",
        help="--output: warm-started runs (train --init-from) and their sources: a section of their own",
    )  # fmt: skip
    report.add_argument(
        "--episodes", type=_positive, default=100, help="each run's final test episodes (default 100)"
    )
    report.add_argument(
        "--output",
        type=Path,
        default=None,
        help="write the report over all runs instead (Table III, curves, typing, Figure 4), and nothing "
        "in the runs' folders: OUTPUT/results.md, or OUTPUT itself if it ends in .md (its figures then "
        "go in a folder of the same name); a run with a checkpoint needs the typing evaluation of its "
        "last epoch first (tactile-braille evaluate RUN_DIR)",
    )
    report.add_argument("--title", default="Results", help="title of results.md")
    report.add_argument("--notes", type=Path, default=None, help="Markdown file placed after the table")
    report.set_defaults(handler=_report)


def _add_evaluate_command(commands) -> None:
    """The ``evaluate`` command: our runs, or any callable with ``--policy``."""
    evaluate = commands.add_parser(
        "evaluate", help="the paper's typing evaluation of training runs, or of any policy (--policy)",
        description="Score RUN_DIRs (writes typing.json and result.json in each), or, with --policy "
        "MODULE:NAME, the callable NAME (observation dict -> action) on TASK (writes --output).",
    )  # fmt: skip
    evaluate.add_argument("targets", nargs="+", type=Path, metavar="RUN_DIR|TASK")
    evaluate.add_argument(
        "--policy",
        metavar="MODULE:NAME",
        help="a callable to score: a module (importable, or in the current folder) or file.py, and a name",
    )
    evaluate.add_argument(
        "--method", help="required with --policy: the method's name on the leaderboard (free text)"
    )
    evaluate.add_argument(
        "--output", type=Path, help="required with --policy: the results file to write (JSON)"
    )
    evaluate.add_argument("--overwrite", action="store_true", help="--policy: replace an existing --output")
    evaluate.add_argument(
        "--track",
        choices=("tactile", "proprio"),
        help="--policy: what the policy learnt from (docs/benchmark.md; default tactile)",
    )
    evaluate.add_argument(
        "--protocol",
        choices=("paper", "released"),
        help="--policy: no reset between keys (paper, the default) or a reset per key (released)",
    )
    evaluate.add_argument(
        "--backend", choices=BACKENDS, help="--policy: observations' source (default: dataset)"
    )
    evaluate.add_argument(
        "--dataset", type=Path, help="--policy: the dataset backend's file (default: cached)"
    )
    evaluate.add_argument("--train-seed", type=_non_negative, help="--policy: the training seed, recorded")
    evaluate.add_argument(
        "--env-steps", type=_non_negative, help="--policy: environment steps trained, recorded"
    )
    evaluate.add_argument(
        "--epochs", type=_non_negative, help="--policy: epochs (250 steps) trained, recorded"
    )
    evaluate.add_argument("--no-sentences", action="store_true", help="alphabet tasks: skip the sentences")
    evaluate.add_argument(
        "--world",
        action="append",
        metavar="WORLD",
        help="RUN_DIR: type in WORLD instead (render, frame:DX,DY,DEG, sensor:NAME, or transfer for the "
        "suite; no sentences); writes transfer.json, leaves typing.json (repeatable; docs/evaluation.md)",
    )
    evaluate.add_argument(
        "--seed", type=int, default=0, help="seed of the start poses (part of the fingerprint)"
    )
    evaluate.set_defaults(handler=_evaluate)


def _add_leaderboard_command(commands) -> None:
    """The ``leaderboard`` command."""
    board = commands.add_parser("leaderboard", help="rank results files per task and track (a markdown page)")
    board.add_argument("results", nargs="+", type=Path, metavar="RESULT", help="results files or run folders")
    board.add_argument("--output", type=Path, help="the page to write (default: print it)")
    board.add_argument("--title", default="Leaderboard")
    board.add_argument(
        "--reference",
        action="append",
        default=[],
        metavar="TASK=FINGERPRINT",
        help="rank TASK's results under this fingerprint (default: the one most of those scored as the "
        "registered environment comes hold: the paper's protocol, the default world)",
    )
    board.add_argument("--strict", action="store_true", help="refuse results under other conditions")
    board.add_argument(
        "--figure",
        type=Path,
        metavar="PNG",
        help="also draw each task's performance profiles (the share of seeds typing above each accuracy) "
        "into PNG, shown on the page (needs --output)",
    )
    board.add_argument(
        "--headline",
        type=Path,
        metavar="PAGE",
        help="also write the headline table (per task: the paper, our best per track, the best other "
        "method) between PAGE's headline markers (the README's)",
    )
    board.set_defaults(handler=_leaderboard)


def _integer(text: str, kind: str) -> int:
    """``text`` as an integer, or argparse's error naming the kind of integer the option takes."""
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid {kind} integer: {text!r}") from None


def _non_negative(text: str) -> int:
    value = _integer(text, "non-negative")
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a non-negative integer, got {value}")
    return value


def _positive(text: str) -> int:
    value = _integer(text, "positive")
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {value}")
    return value


def _add_sweep_command(commands) -> None:
    """The ``sweep`` command: the ``train`` command's settings apply to every trial."""
    from tactile_braille.cli_config import add_config_options

    sweeper = commands.add_parser("sweep", help="train tasks x algorithms x seeds (Ray Tune when installed)")
    sweeper.add_argument(
        "--tasks", nargs="+", required=True, help="e.g. DiscreteArrows-v0 DiscreteAlphabet-v0"
    )
    sweeper.add_argument("--algos", nargs="+", required=True, choices=agent_names())
    sweeper.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    sweeper.add_argument("--preset", choices=TRAINING_PRESETS, default="paper")
    sweeper.add_argument("--backend", choices=[b for b in BACKENDS if b != "rig"], default=None)
    sweeper.add_argument("--report", type=Path, default=None, help="write REPORT/results.md over the runs")
    sweeper.add_argument("--variant", default=None, metavar="NAME",
                         help="name of the settings given below, in each trial's folder "
                              "(TASK__ALGO__NAME__SEED); needed with any of them")  # fmt: skip
    _add_sweep_options(sweeper, "runs/sweep")
    add_config_options(sweeper, skip=("seed", *SWEEP_RUN_OPTIONS))  # seeds: --seeds
    sweeper.set_defaults(handler=_sweep)


def _machine(args: argparse.Namespace) -> dict:
    """The machine settings given to ``tune`` (:data:`tactile_braille.tuning.MACHINE`)."""
    from tactile_braille.agents.run import MACHINE_SETTINGS
    from tactile_braille.cli_config import resolve_precision

    given = {name: getattr(args, name) for name in MACHINE_SETTINGS}
    machine = {name: value for name, value in given.items() if value is not None}
    machine["precision"] = resolve_precision(args.precision, args.device or "cpu")
    return machine


def _tune(args: argparse.Namespace) -> int:
    from tactile_braille import tuning

    if args.action == "search":
        found = tuning.tune(
            args.task, args.algo, args.preset, args.trials, args.study, args.seeds, _machine(args)
        )
        best = found["best"]
        if best is None:
            print(f"{found['trials']} trials finished, none complete (all pruned)")
        else:
            print(f"{found['trials']} trials; best #{best['number']}: accuracy {best['accuracy']:.3f} in "
                  f"{best['total_steps']} steps with {best['params']}")  # fmt: skip
        return 0
    records = tuning.run_seeds(args.task, args.algo, args.preset, args.study, args.seeds, args.root,
                               args.into, _machine(args))  # fmt: skip
    for record in records:
        print(f"{record}: {_typed(record / 'result.json')}")
    return 0


def _typed(result_file: Path) -> str:
    import json

    report = json.loads(result_file.read_text())["report"]
    return f"accuracy {report['accuracy']:.3f} in {report['total_steps']} steps"


def _add_tune_command(commands) -> None:
    """The ``tune`` command: the benchmark's tuning protocol for this project's agents."""
    tune = commands.add_parser(
        "tune", help="search an agent's settings on tuning seeds (Optuna), then train them on fresh seeds",
        description="The benchmark's tuning protocol (docs/benchmark.md): `search` runs an Optuna study of "
        "the agent's search space from a preset on tuning seeds; `run` trains the best trial's settings on "
        "fresh seeds and archives their records, each carrying the search.",
    )  # fmt: skip
    actions = tune.add_subparsers(dest="action", required=True)
    for name, text in (("search", "run the search until it holds --trials trials"),
                       ("run", "train the best trial's settings on --seeds")):  # fmt: skip
        action = actions.add_parser(name, help=text)
        action.add_argument("task", help="environment id, e.g. DiscreteArrows-v0")
        action.add_argument("algo", choices=agent_names())
        action.add_argument("--preset", choices=TRAINING_PRESETS, required=True, help="the untuned settings")
        action.add_argument("--study", type=Path, required=True,
                            help="folder of the search's study (SQLite) and its record (JSON; `run` reads "
                            "either)")  # fmt: skip
        action.add_argument("--epochs", type=int, default=None, help="each run's epochs (the preset's)")
        action.add_argument("--precision", choices=(*PRECISIONS, "auto"), default="fp32")
        action.add_argument("--threads", type=int, default=1, help="torch threads per run (default 1)")
        action.add_argument("--device", default=None, help="torch device (default cpu)")
        action.add_argument("--dataset", default=None, help="the dataset backend's file (default: cached)")
        action.set_defaults(handler=_tune)
    search, run = actions.choices["search"], actions.choices["run"]
    search.add_argument("--trials", type=int, required=True, help="trials to finish in all")
    search.add_argument("--seeds", type=int, nargs="+", default=[100],
                        help="the tuning seeds each trial trains on, in turn (100)")  # fmt: skip
    run.add_argument("--seeds", type=int, nargs="+", required=True, help="fresh seeds (not tuning seeds)")
    run.add_argument("--root", type=Path, default=Path("runs/tuned"), help="the runs' folders (runs/tuned)")
    run.add_argument("--into", type=Path, required=True, help="folder of the records")


def _archive(args: argparse.Namespace) -> int:
    from tactile_braille.sweep import archive_run

    for run in args.runs:
        print(f"archived {run} in {archive_run(run, args.into)}")
    return 0


def _add_archive_command(commands) -> None:
    """The ``archive`` command."""
    archive = commands.add_parser(
        "archive", help="copy runs' records (settings, world, progress, typing; no checkpoint) to a folder"
    )
    archive.add_argument("runs", nargs="+", type=Path, metavar="RUN_DIR")
    archive.add_argument("--into", type=Path, required=True, help="the records go to INTO/<run folder name>")
    archive.set_defaults(handler=_archive)


def _add_benchmark_command(commands) -> None:
    """The ``benchmark`` command."""
    bench = commands.add_parser(
        "benchmark",
        help="reproduce the simulated part of the paper's Table III",
        description="Runs default to bf16 autocast and one torch thread each, the settings of the "
        "committed Table III rows (a run with other settings makes a row of its own in the report).",
    )
    bench.add_argument("--paper", action="store_true", help="the paper's 8 simulated task x algorithm runs")
    bench.add_argument("--presets", nargs="+", choices=TRAINING_PRESETS, default=["paper"],
                       help="one sweep per preset, in ROOT/PRESET (and ARCHIVE/PRESET)")  # fmt: skip
    bench.add_argument("--tasks", nargs="+", default=None, help="only these tasks' rows (default: all)")
    bench.add_argument("--algos", nargs="+", default=None, help="only these algorithms' rows (default: all)")
    bench.add_argument("--num-seeds", type=int, default=5, help="seeds 0..N-1 (the paper's 5)")
    bench.add_argument("--seeds", nargs="+", type=int, default=None, help="these seeds instead")
    bench.add_argument("--report", type=Path, default=None, help="default: ROOT/report; one per preset")
    _add_sweep_options(bench, "runs/paper-benchmark")
    bench.set_defaults(handler=_benchmark, precision="bf16", threads=1)


def _add_data_command(commands) -> None:
    """The ``data`` command."""
    data = commands.add_parser("data", help="generate (or reuse) the default datasets in the cache")
    data.add_argument("--sensor", default="braille_331", choices=sorted(SENSORS))
    data.add_argument("--seed", type=_non_negative, default=0)
    data.set_defaults(handler=_data)


def _add_keycaps_command(commands) -> None:
    """The ``keycaps`` command."""
    keycaps = commands.add_parser(
        "keycaps", help="write 3D-printable braille keycaps (STL) and a preview PNG"
    )
    keycaps.add_argument(
        "--out", type=Path, required=True, help="folder for keycap_<KEY>.stl and the preview"
    )
    keycaps.add_argument("--keys", default=None, help="comma-separated keys (default: the 31 task keys)")
    keycaps.add_argument("--resolution-mm", type=float, default=0.25, help="grid step of the top surface")
    keycaps.set_defaults(handler=_keycaps)


def _add_rig_command(commands) -> None:
    """The ``rig`` command."""
    rig = commands.add_parser("rig", help="set up and check the UR5 rig (docs/hardware.md)")
    rig_commands = rig.add_subparsers(dest="rig_command", required=True)
    check = rig_commands.add_parser("check", help="a few taps; prints the arm's commands")
    check.add_argument("--config", type=Path, default=None, help="rig settings (JSON); none: simulated rig")
    check.add_argument("--simulated", action="store_true", help="simulated hardware (with --config's frames)")
    check.add_argument(
        "--dry-run", action="store_true", help="log the arm's commands instead of sending them"
    )
    check.add_argument("--keys", default="A,F,J,SPACE", help="comma-separated keys to tap")
    check.add_argument("--depth", type=float, default=5.0, help="tap depth in mm (8 presses the keys)")
    check.set_defaults(handler=_rig_check)
    calibrate = rig_commands.add_parser(
        "calibrate", help="fit the work frame to tool poses on reference keys"
    )
    calibrate.add_argument("--config", type=Path, default=None, help="rig settings (JSON)")
    calibrate.add_argument("--simulated", action="store_true", help="simulated hardware and operator")
    calibrate.add_argument("--keys", default="Q,P,Z,RIGHT", help="reference keys, far apart")
    calibrate.add_argument("--write", action="store_true", help="store the fitted frame in --config")
    calibrate.set_defaults(handler=_rig_calibrate)
    crop = rig_commands.add_parser("crop", help="propose the sensor's crop box; write a threshold preview")
    crop.add_argument("--config", type=Path, default=None, help="rig settings (JSON)")
    crop.add_argument("--simulated", action="store_true", help="simulated camera")
    crop.add_argument(
        "--output", type=Path, default=Path("outputs/threshold_preview.png"), help="preview PNG"
    )
    crop.add_argument("--write", action="store_true", help="store the crop box in --config")
    crop.set_defaults(handler=_rig_crop)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``tactile-braille``."""
    parser = argparse.ArgumentParser(
        prog="tactile-braille", description="Learning to type on a braille keyboard by touch."
    )
    commands = parser.add_subparsers(dest="command", required=True)

    _add_show_command(commands)
    _add_collect_command(commands)
    _add_import_command(commands)
    _add_classify_command(commands)
    _add_train_command(commands)
    _add_report_command(commands)
    _add_evaluate_command(commands)
    _add_leaderboard_command(commands)
    _add_archive_command(commands)
    _add_sweep_command(commands)
    _add_tune_command(commands)
    _add_benchmark_command(commands)
    _add_data_command(commands)
    _add_keycaps_command(commands)
    _add_rig_command(commands)
    return parser


def _short_command(argv: Sequence[str]) -> str:
    """``argv`` joined for a shell, each run of folders that are all the entries of one parent folder
    written ``parent/*`` (the same command, as a reader can take it in)."""
    words: list[str] = []
    index = 0
    while index < len(argv):
        parent = Path(argv[index]).parent
        end = index
        while end < len(argv) and Path(argv[end]).parent == parent and Path(argv[end]).is_dir():
            end += 1
        named = {Path(word) for word in argv[index:end]}
        if end - index > 1 and str(parent) != "." and set(parent.iterdir()) == named:
            words.append(shlex.quote(str(parent)) + "/*")
            index = end
        else:
            words.append(shlex.quote(argv[index]))
            index += 1
    return " ".join(words)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``tactile-braille``."""
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    args.argv = argv
    try:
        return args.handler(args)
    except (OSError, ValueError, RigError, LockedError, ImportError) as error:
        # DatasetError is a ValueError; an OSError is a path, a permission or a full disk; an ImportError
        # an optional library not installed: what the user can fix gets its message, not a traceback.
        print(f"tactile-braille: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
