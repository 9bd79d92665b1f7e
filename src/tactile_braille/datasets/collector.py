"""Run a collection procedure on any rig and store the samples, resumably."""

from __future__ import annotations

from pathlib import Path

from tactile_braille._version import __version__
from tactile_braille.datasets.procedures import Procedure
from tactile_braille.datasets.store import DatasetMetadata, DatasetWriter
from tactile_braille.keyboard.layout import NONE_KEY
from tactile_braille.rigs.base import Rig
from tactile_braille.sensor.processing import process_frame

GENERATOR_VERSION = f"{__version__}+samples3"
"""Version of the sample generator (procedures, rig model, renderer, processing).

Bump the suffix whenever a change alters the samples a collection produces:
cached default datasets made by another version are regenerated."""


def dataset_metadata(rig: Rig, procedure: Procedure, seed: int) -> DatasetMetadata:
    """The metadata a collection of ``procedure`` on ``rig`` records."""
    description = rig.describe()
    return DatasetMetadata(
        key_names=(*(key.name for key in rig.layout.keys), NONE_KEY),
        procedure=procedure.describe(),
        keyboard=description["keyboard"],
        sensor=description["sensor"],
        rig=description["rig"],
        seed=int(seed),
        generator_version=GENERATOR_VERSION,
    )


def collect(
    rig: Rig,
    procedure: Procedure,
    output: str | Path,
    seed: int = 0,
    resume: bool = False,
    restart: bool = False,
    progress: bool = True,
    shard_size: int = 256,
) -> Path:
    """Make every tap of ``procedure`` on ``rig`` and write the dataset ``output``.

    Each tap is made with the rig reseeded from ``(seed, tap index)``, so a
    sample does not depend on the taps before it: a collection interrupted at
    any point (Ctrl-C, ``kill -9``, a rig fault) and continued with
    ``resume=True`` produces the same dataset as an uninterrupted one. At most
    ``shard_size`` samples are lost to a crash.

    Returns:
        The path of the finished dataset.
    """
    writer = DatasetWriter(
        output,
        dataset_metadata(rig, procedure, seed),
        len(procedure),
        resume=resume,
        shard_size=shard_size,
        restart=restart,
    )
    names = writer.metadata.key_names
    name_index = {name: i for i, name in enumerate(names)}
    pending = writer.pending()
    if progress:
        from tqdm.auto import tqdm

        pending = tqdm(pending, desc=f"collecting {Path(output).name}", unit="tap", initial=writer.done,
                       total=len(procedure))  # fmt: skip
    try:
        for index in pending:
            spec = procedure.tap(index, rig.layout)
            rig.reseed([int(seed), index])
            sample = rig.tap(spec.x_mm, spec.y_mm, spec.depth_mm, spec.yaw_deg)
            pressed = sample.pressed_key or NONE_KEY
            if pressed not in name_index:
                raise ValueError(f"the rig reported an unknown key {pressed!r}")
            writer.add(
                index,
                process_frame(sample.frame, rig.processing),
                sample.pose.as_array(),
                name_index[spec.label or pressed],
                name_index[pressed],
            )
        writer.flush()
        return writer.finalize()
    except BaseException:
        writer.flush()  # keep what was collected when a rig fault or Ctrl-C stops us
        raise
    finally:
        writer.close()  # let a retry (in this process too) take the dataset
