"""The ``tactile-braille`` command: thin wrappers over the library."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from tactile_braille.sensor.config import PRESETS


def _show(args: argparse.Namespace) -> int:
    from tactile_braille.gallery import live_gallery_tiles, save_gallery
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


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``tactile-braille``."""
    parser = argparse.ArgumentParser(
        prog="tactile-braille", description="Learning to type on a braille keyboard by touch."
    )
    commands = parser.add_subparsers(dest="command", required=True)
    show = commands.add_parser("show", help="write a gallery PNG of tactile images")
    show.add_argument("--output", default="outputs/gallery.png", help="PNG to write")
    show.add_argument("--sensor", default="braille_331", choices=sorted(PRESETS))
    show.add_argument("--depth", type=float, default=5.0, help="tap depth in mm (default 5)")
    show.add_argument("--seed", type=int, default=0, help="seed of the sensor nuisances")
    show.set_defaults(handler=_show)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``tactile-braille``."""
    args = build_parser().parse_args(argv)
    return args.handler(args)


if __name__ == "__main__":
    sys.exit(main())
