"""The ``tactile-braille`` command line."""

from __future__ import annotations

import pytest

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
