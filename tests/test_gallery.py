"""The gallery of tactile images."""

from __future__ import annotations

import os
import stat

import numpy as np
import pytest

from tactile_braille.gallery import GALLERY_DEPTH_MM, live_gallery_tiles, save_gallery
from tactile_braille.keyboard.layout import ALL_TASK_KEYS
from tactile_braille.rigs.virtual import VirtualRig


@pytest.fixture(scope="module")
def tiles():
    return live_gallery_tiles(VirtualRig(seed=0), keys=("A", "B", "SPACE", "UP"))


def test_tiles_titles_and_images(tiles):
    titles = [title for title, _, _ in tiles]
    assert titles == [
        "A",
        "B",
        "SPACE",
        "UP",
        "A +4 mm x",
        "A +4 mm y",
        "G|H gap",
        "A pressed 8 mm -> A",
        "no contact",
    ]
    for _, frame, observation in tiles:
        assert frame.shape == (480, 640) and frame.dtype == np.uint8
        assert observation.shape == (100, 100) and observation.dtype == np.uint8
        assert set(np.unique(observation).tolist()) <= {0, 255}


def test_default_gallery_covers_all_task_keys_without_pressing_them():
    assert GALLERY_DEPTH_MM == 4.5
    tiles = live_gallery_tiles(VirtualRig(seed=None))
    titles = [title for title, _, _ in tiles]
    assert titles[: len(ALL_TASK_KEYS)] == list(ALL_TASK_KEYS)  # no "-> KEY" suffix: nothing pressed
    assert len(tiles) == len(ALL_TASK_KEYS) + 5


def test_save_gallery_writes_png(tiles, tmp_path):
    path = save_gallery(tiles, tmp_path / "out" / "gallery.png", title="test")
    assert path == tmp_path / "out" / "gallery.png"
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in path.parent.iterdir()) == ["gallery.png"]


def test_save_gallery_overwrites(tiles, tmp_path):
    target = tmp_path / "gallery.png"
    target.write_bytes(b"old")
    save_gallery(tiles[:2], target, title="again")
    assert target.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_save_gallery_without_tiles_raises(tmp_path):
    with pytest.raises(ValueError, match="no tiles"):
        save_gallery([], tmp_path / "g.png", title="empty")


def test_saved_gallery_has_umask_permissions(tiles, tmp_path):
    umask = os.umask(0)
    os.umask(umask)
    if 0o666 & ~umask == 0o600:
        pytest.skip("this umask gives 0600 anyway")
    path = save_gallery(tiles[:1], tmp_path / "g.png", title="perms")
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask
