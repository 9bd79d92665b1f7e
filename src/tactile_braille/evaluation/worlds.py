"""Worlds to type in besides the one a policy learnt in: the transfer tests.

Policies learn on the dataset backend, the paper's simulation: a 3 mm grid of
stored taps, the same images every time. The same typing evaluation can run
in other worlds (``tactile-braille evaluate RUN --world ...``):

* ``render``: the live renderer, the run's own sensor: taps land where
  commanded (no grid), with fresh sensor noise every time.
* ``frame:DX,DY,DEG``: the live renderer with the work frame off by (DX, DY)
  mm and DEG degrees about the task's work-frame origin, a calibration error
  (:class:`~tactile_braille.rigs.miscalibrated.MiscalibratedRig`); e.g.
  ``frame:+1,0,+2``.
* ``sensor:NAME``: the live renderer with another TacTip (``sensor:tactip_127``).

``transfer`` names the suite of :data:`TRANSFER_SUITE`. This is our proxy for
the gap a real deployment meets first (docs/evaluation.md); it does not show
how the real sensor's images differ from rendered ones.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium as gym

from tactile_braille.sensor.config import PRESETS

TRANSFER_SUITE = (
    "render",
    "frame:+1,0,+2",
    "frame:-1,0,-2",
    "frame:0,+1,-2",
    "frame:0,-1,+2",
    "sensor:tactip_127",
)
"""The worlds ``--world transfer`` types in: the live renderer, four calibration errors (1 mm along
each axis, each with a 2 degree turn) and the other TacTip."""
EDGE_ROOM_MM = 5.0
"""How far past the keyboard a miscalibrated rig's taps may land."""


@dataclass(frozen=True)
class World:
    """A world to type in (the module docstring): the live renderer, its sensor and a calibration error.

    Attributes:
        name: how it was asked for (``render``, ``frame:+1,0,+2``, ``sensor:tactip_127``).
        sensor: the TacTip preset, or None for the run's own.
        offset_mm: (x, y) calibration error of the work frame.
        rotation_deg: rotation of the work frame about the task's origin.
    """

    name: str
    sensor: str | None = None
    offset_mm: tuple[float, float] = (0.0, 0.0)
    rotation_deg: float = 0.0

    def make_env(self, task_id: str, sensor: str, **options) -> gym.Env:
        """The task's environment in this world; ``sensor``: the run's own; ``options`` go to ``gym.make``."""
        from tactile_braille.envs.registry import task_of

        sensor = self.sensor or sensor
        if self.offset_mm == (0.0, 0.0) and self.rotation_deg == 0.0:
            return gym.make(task_id, backend="render", sensor=sensor, **options)
        from tactile_braille.rigs.miscalibrated import MiscalibratedRig, with_room
        from tactile_braille.rigs.virtual import VirtualRig

        inner, calibrated = with_room(VirtualRig(sensor=sensor), EDGE_ROOM_MM)
        pivot = task_of(task_id).frame_origin_mm
        rig = MiscalibratedRig(inner, self.offset_mm, self.rotation_deg, pivot, workspace=calibrated)
        return gym.make(task_id, backend="rig", rig=rig, **options)


def parse_world(text: str) -> World:
    """The :class:`World` named ``text`` (the module docstring's forms).

    Raises:
        ValueError: ``text`` names no world, with the forms it could take.
    """
    forms = "render, frame:DX,DY,DEG (mm, mm, degrees), sensor:NAME or transfer"
    kind, _, value = text.partition(":")
    if text == "render":
        return World(text)
    if kind == "sensor" and value in PRESETS:
        return World(text, sensor=value)
    if kind == "sensor":
        raise ValueError(f"unknown sensor {value!r} in world {text!r}; choose one of {sorted(PRESETS)}")
    if kind == "frame":
        try:
            dx, dy, degrees = (float(part) for part in value.split(","))
        except ValueError:
            raise ValueError(
                f"world {text!r}: a frame error is frame:DX,DY,DEG, e.g. frame:+1,0,+2"
            ) from None
        # One name per world: frame:+1,0,+2 however it was written.
        name = "frame:" + ",".join("0" if v == 0 else f"{v:+g}" for v in (dx, dy, degrees))
        return World(name, offset_mm=(dx, dy), rotation_deg=degrees)
    raise ValueError(f"unknown world {text!r}; the forms are {forms}")


def expand_worlds(names: list[str]) -> list[World]:
    """The worlds named (``transfer`` expands to :data:`TRANSFER_SUITE`), each once, in order."""
    expanded = [n for name in names for n in (TRANSFER_SUITE if name == "transfer" else (name,))]
    return list({world.name: world for world in map(parse_world, expanded)}.values())
