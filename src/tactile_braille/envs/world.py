"""Where an environment's observations come from and by which rules: the accepted values, checked once.

The environments' ``backend``, ``edges``, ``tap_depth``, ``key_grid`` and
``frame_noise`` arguments each take one of a few values, and some only on some
tasks or backends. :func:`check_world` is the one check of those rules: the
environments call it before they build anything, and a training config
(:class:`~tactile_braille.agents.config.TrainConfig`) calls it when it is made,
so that a bad setting is refused before a run starts. The ``Literal`` types
here are the value sets; the tuples are the same, for messages and choices.

Importing this module loads only the standard library (the frame-noise check
reads the rigs' yaw limit when it runs): the config imports it to annotate its
fields.
"""

from __future__ import annotations

import math
import typing
from collections.abc import Sequence
from typing import Literal

Backend = Literal["dataset", "render", "rig"]
Edges = Literal["stop", "overrun"]
TapDepth = Literal["commanded", "released"]
KeyGrid = Literal["rig", "released"]

BACKENDS: tuple[str, ...] = typing.get_args(Backend)
"""Where observations come from: ``"dataset"``, stored taps (the paper's simulation); ``"render"``, the
live renderer; ``"rig"``, any rig (a robot)."""
EDGES: tuple[str, ...] = typing.get_args(Edges)
"""What a continuous task's workspace edge does to a move that crosses it: ``"stop"``, the sensor stops
at the edge (the real rig's safety limits, the released robot environment); ``"overrun"``, the released
simulator's: the commanded position runs on past the edge and only the tap is made at the nearest point
inside, so a move back must first undo the overrun."""
TAP_DEPTHS: tuple[str, ...] = typing.get_args(TapDepth)
"""Which stored depth a continuous tap reads on the dataset backend: ``"commanded"``, the sample at the
commanded depth (2-8 mm: the paper's 0-6 mm plus its constant 2 mm); ``"released"``, the released
simulator's lookup, which compares the commanded 2-8 mm with its data's 0-6 mm labels, so every tap
reads the sample :data:`~tactile_braille.envs.core.RELEASED_DEPTH_SHIFT_MM` deeper, the deepest (8 mm)
from 6 mm on."""
GRIDS: tuple[str, ...] = typing.get_args(KeyGrid)
"""The discrete tasks' key grids by name (each key set's ``key_grids``,
:data:`~tactile_braille._tasks.KEY_SETS`): ``"rig"``, the original robot's (the alphabet's third row
starts under A), and ``"released"``, the released simulator's (that row one column right, Z under S);
the arrows' grid is the same in both."""
WORLD_RULES = ("edges", "tap_depth", "key_grid")
"""The rules in which a world may depart from ours (the released simulator's), as ``world`` records them."""


def check_world(
    continuous: bool | None,
    backend: str,
    *,
    edges: str = "stop",
    tap_depth: str = "commanded",
    key_grid: str = "rig",
    frame_noise: Sequence[float] | None = None,
    task: str | None = None,
) -> None:
    """Refuse a world the task or the backend does not have, before anything is built.

    Args:
        continuous: the braille task's action kind; None for a task without a keyboard (another
            goal-conditioned environment), on which only our world's defaults are accepted.
        backend: one of :data:`BACKENDS`.
        edges: one of :data:`EDGES`; ``"overrun"`` on a continuous task only (a discrete move off the
            key grid stays put).
        tap_depth: one of :data:`TAP_DEPTHS`; ``"released"`` on a continuous task on the dataset backend
            only (it is the released simulator's lookup of the stored grid).
        key_grid: one of :data:`GRIDS`; ``"released"`` on a discrete task only.
        frame_noise: None, or ``(mm, degrees)`` on the render backend (:func:`check_frame_noise`).
        task: how messages name the task (an environment id), if known.

    Raises:
        ValueError: naming the setting, what it is for, and what to set instead.
    """
    where = f" for {task}" if task else ""
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; choose one of {BACKENDS}")
    if edges not in EDGES:
        raise ValueError(f"edges must be one of {EDGES}, got {edges!r}")
    if edges != "stop" and not continuous:
        raise ValueError(
            f"edges={edges!r} is the continuous braille tasks' (a discrete move off the key grid stays "
            f"put): set edges='stop'{where}"
        )
    if tap_depth not in TAP_DEPTHS:
        raise ValueError(f"tap_depth must be one of {TAP_DEPTHS}, got {tap_depth!r}")
    if tap_depth != "commanded" and not (continuous and backend == "dataset"):
        raise ValueError(
            f"tap_depth={tap_depth!r} is the released simulator's lookup of the continuous braille tasks' "
            f"stored grid, on the dataset backend: set tap_depth='commanded'{where} on the {backend} backend"
        )
    check_key_grid(key_grid, continuous, task)
    check_frame_noise(frame_noise, backend)


def check_key_grid(key_grid: str, continuous: bool | None, task: str | None = None) -> None:
    """Refuse a key grid that is not one of :data:`GRIDS`, or another than the robot's off the discrete
    braille tasks (``continuous`` and ``task`` as :func:`check_world`'s)."""
    if key_grid not in GRIDS:
        raise ValueError(f"key_grid must be one of {GRIDS}, got {key_grid!r}")
    if key_grid != "rig" and (continuous is None or continuous):
        raise ValueError(
            f"key_grid={key_grid!r} is the discrete braille tasks' grid (a continuous task moves over "
            f"the keyboard): set key_grid='rig'" + (f" for {task}" if task else "")
        )


def check_frame_noise(frame_noise: Sequence[float] | None, backend: str) -> None:
    """Refuse a work-frame error that is not ``(mm, degrees)``, both finite and >= 0 and degrees at most
    the rigs' :data:`~tactile_braille.rigs.miscalibrated.MAX_FRAME_ROTATION_DEG`, or one asked off the
    render backend (None: no error, accepted everywhere)."""
    if frame_noise is None:
        return
    from tactile_braille.rigs.miscalibrated import MAX_FRAME_ROTATION_DEG  # the rigs: only when asked

    noise = tuple(frame_noise)
    finite = all(isinstance(value, int | float) and math.isfinite(value) and value >= 0 for value in noise)
    if len(noise) != 2 or not finite or noise[1] > MAX_FRAME_ROTATION_DEG:
        raise ValueError(
            f"frame_noise is (mm, degrees), both >= 0 and finite, degrees at most "
            f"{MAX_FRAME_ROTATION_DEG:g}, got {frame_noise}"
        )
    if backend != "render":
        raise ValueError(
            f"frame_noise randomises the live renderer's work frame: use backend='render', not {backend!r}"
        )
