"""Printable braille keycaps: closed meshes, the model's relief, a Cherry MX socket, the STL round trip."""

from __future__ import annotations

from collections import Counter

import cv2
import numpy as np
import pytest

from tactile_braille.cli import main
from tactile_braille.keyboard.braille import BRAILLE_DOTS, BrailleGeometry
from tactile_braille.keyboard.keycaps import (
    KeycapGeometry,
    braille_cell_stl_mm,
    build_keycap,
    mesh_volume_mm3,
    read_stl,
    write_keycaps,
    write_stl,
)
from tactile_braille.keyboard.surface import KeyboardSurface

KEYS = ("A", "Q", "W", "Z", "SPACE", "UP", "LEFT")
HEIGHT_MM = KeycapGeometry().height_mm


@pytest.fixture(scope="module")
def written(tmp_path_factory, layout, surface):
    """The STL files of KEYS (and the preview) written once, and the keycaps they came from."""
    folder = tmp_path_factory.mktemp("keycaps")
    paths = write_keycaps(folder, KEYS, layout=layout)
    caps = {key: build_keycap(key, layout, surface) for key in KEYS}
    return folder, paths, caps


def assert_watertight(facets: np.ndarray) -> None:
    """Every edge is shared by exactly two triangles that run along it in opposite directions."""
    vertices, index = np.unique(facets.reshape(-1, 3), axis=0, return_inverse=True)
    triangles = index.reshape(-1, 3)
    assert len(np.unique(np.sort(triangles, axis=1), axis=0)) == len(triangles), "duplicate triangles"
    directed = Counter(map(tuple, np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]],
                                                  triangles[:, [2, 0]]])))  # fmt: skip
    assert max(directed.values()) == 1, "an edge is run along twice in one direction"
    unmatched = [edge for edge in directed if (edge[1], edge[0]) not in directed]
    assert not unmatched, (
        f"{len(unmatched)} edges border only one triangle, e.g. {vertices[list(unmatched[0])]}"
    )
    areas = np.linalg.norm(np.cross(facets[:, 1] - facets[:, 0], facets[:, 2] - facets[:, 0]), axis=1)
    assert areas.min() > 1e-6, "degenerate triangles"


def top_height_near(facets: np.ndarray, x: float, y: float, radius: float = 0.2) -> float:
    corners = facets.reshape(-1, 3)
    near = (np.abs(corners[:, 0] - x) <= radius) & (np.abs(corners[:, 1] - y) <= radius)
    return float(corners[near, 2].max())


@pytest.mark.parametrize("key", KEYS)
def test_stl_files_are_closed_outward_meshes(written, key):
    folder, _, caps = written
    facets = read_stl(folder / f"keycap_{key}.stl")
    assert facets.shape == caps[key].facets.shape
    assert_watertight(facets)
    volume = mesh_volume_mm3(facets)
    # The same volume as the height fields: linear top over each cell's two triangles, flat underside.
    cap = caps[key]
    top, dx, dy = cap.top_mm, np.diff(cap.xs)[:, None], np.diff(cap.ys)[None, :]
    a, b, c, d = top[:-1, :-1], top[1:, :-1], top[1:, 1:], top[:-1, 1:]
    expected = float((dx * dy * ((a + b + c) / 3 + (a + c + d) / 3) / 2 - dx * dy * cap.bottom_mm).sum())
    assert volume == pytest.approx(expected, rel=1e-4)
    assert volume > 0  # outward normals
    # The stored normals agree with the winding (a slicer trusts either).
    record = np.dtype([("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("attribute", "<u2")])
    stored = np.frombuffer((folder / f"keycap_{key}.stl").read_bytes()[84:], dtype=record)["normal"]
    normals = np.cross(facets[:, 1] - facets[:, 0], facets[:, 2] - facets[:, 0])
    assert (np.einsum("ij,ij->i", stored, normals) > 0).all()


@pytest.mark.parametrize("key", [k for k in KEYS if k in BRAILLE_DOTS])
def test_letters_carry_their_braille_dots(written, key):
    folder, _, _ = written
    facets = read_stl(folder / f"keycap_{key}.stl")
    cell = braille_cell_stl_mm()
    heights = {dot: top_height_near(facets, x, y) - HEIGHT_MM for dot, (x, y) in cell.items()}
    raised = {dot for dot, h in heights.items() if h > 0.25}
    assert raised == set(BRAILLE_DOTS[key]), heights
    for dot in raised:
        assert heights[dot] == pytest.approx(BrailleGeometry().dot_height_mm, abs=0.02)
    for dot in set(cell) - raised:
        assert abs(heights[dot]) < 0.01
    # Between two dots of a column the top is flat again.
    x, y = np.mean([cell[1], cell[2]], axis=0)
    assert top_height_near(facets, x, y, radius=0.1) == pytest.approx(HEIGHT_MM, abs=0.02)


def test_arrows_carry_ridges_and_space_is_blank(written):
    folder, _, _ = written
    up = read_stl(folder / "keycap_UP.stl")
    left = read_stl(folder / "keycap_LEFT.stl")
    space = read_stl(folder / "keycap_SPACE.stl")
    # The shaft of UP runs along Y (away from the typist), LEFT's along X.
    assert top_height_near(up, 0.0, -2.0) > HEIGHT_MM + 0.4
    assert top_height_near(up, -2.0, -2.0) == pytest.approx(HEIGHT_MM, abs=0.02)
    assert top_height_near(left, 2.0, 0.0) > HEIGHT_MM + 0.4
    assert top_height_near(left, 2.0, -2.0) == pytest.approx(HEIGHT_MM, abs=0.02)
    # UP's head points away from the typist: its chevron spreads at +Y, not at -Y.
    assert top_height_near(up, 1.5, 2.0) > HEIGHT_MM + 0.3
    assert top_height_near(up, 1.5, -3.0) == pytest.approx(HEIGHT_MM, abs=0.02)
    assert space.reshape(-1, 3)[:, 2].max() == pytest.approx(HEIGHT_MM, abs=1e-4)


def test_the_relief_comes_from_the_simulators_keyboard_model(layout):
    """Taller dots in the surface model give taller dots on the printed cap."""
    tall = KeyboardSurface(layout, braille=BrailleGeometry(dot_height_mm=0.8))
    cap = build_keycap("A", layout, tall)
    x, y = braille_cell_stl_mm()[1]
    assert top_height_near(cap.facets, x, y) - HEIGHT_MM == pytest.approx(0.8, abs=0.02)


def test_the_underside_has_a_cherry_mx_cross_socket(written):
    _, _, caps = written
    cap = caps["A"]
    geometry = KeycapGeometry()
    area = np.diff(cap.xs)[:, None] * np.diff(cap.ys)[None, :]
    socket = cap.bottom_mm == geometry.socket_depth_mm
    arm, width = geometry.socket_arm_length_mm, geometry.socket_arm_width_mm
    assert area[socket].sum() == pytest.approx(2 * arm * width - width**2, abs=1e-9)  # a 4.0 x 1.3 cross
    cx = (cap.xs[:-1] + cap.xs[1:]) / 2
    cy = (cap.ys[:-1] + cap.ys[1:]) / 2
    rows, columns = np.nonzero(socket)
    assert cx[rows].min() == pytest.approx(-arm / 2, abs=0.2) and cx[rows].max() == pytest.approx(
        arm / 2, abs=0.2
    )
    assert cy[columns].min() == pytest.approx(-arm / 2, abs=0.2)
    assert cap.bottom_mm[0].max() == 0.0 and cap.bottom_mm[:, -1].max() == 0.0  # the rim
    assert (cap.bottom_mm == geometry.hollow_height_mm).any()  # room for the switch's housing
    assert caps["SPACE"].stems_mm == (0.0, -50.0, 50.0)  # SPACE also takes two stabiliser stems
    space_socket = (caps["SPACE"].bottom_mm == geometry.socket_depth_mm) * (
        np.diff(caps["SPACE"].xs)[:, None] * np.diff(caps["SPACE"].ys)[None, :]
    )
    assert space_socket.sum() == pytest.approx(3 * (2 * arm * width - width**2), abs=1e-9)


def test_a_body_too_thin_for_its_top_is_refused(layout, surface):
    with pytest.raises(ValueError, match="raise height_mm"):
        build_keycap("A", layout, surface, KeycapGeometry(height_mm=6.0))
    with pytest.raises(ValueError, match="socket_depth_mm"):
        KeycapGeometry(socket_depth_mm=6.0)


def test_stl_round_trip_and_bad_files(tmp_path):
    facets = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 0, 0], [0, 1, 0], [0, 0, 1]]], dtype=float)
    path = write_stl(tmp_path / "t.stl", facets)
    np.testing.assert_array_equal(read_stl(path), facets.astype(np.float32))
    path.write_bytes(path.read_bytes()[:-3])
    with pytest.raises(ValueError, match="header says 2 triangles"):
        read_stl(path)


def test_preview_png_shows_every_keycap(written):
    folder, paths, _ = written
    preview = folder / "keycaps_preview.png"
    assert paths[-1] == preview
    image = cv2.imread(str(preview))
    assert image is not None and image.shape[1] > image.shape[0]
    # One shaded tile per key plus the underside: the width grows with the keys shown.
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    assert grey.std() > 20


def test_keycaps_command_writes_the_requested_keys(tmp_path, capsys):
    assert (
        main(["keycaps", "--out", str(tmp_path / "caps"), "--keys", "b,right", "--resolution-mm", "0.5"]) == 0
    )
    names = sorted(p.name for p in (tmp_path / "caps").iterdir())
    assert names == ["keycap_B.stl", "keycap_RIGHT.stl", "keycaps_preview.png"]
    assert "wrote 2 STL keycaps" in capsys.readouterr().out
    assert_watertight(read_stl(tmp_path / "caps" / "keycap_B.stl"))
    assert main(["keycaps", "--out", str(tmp_path / "x"), "--keys", "A,NOPE"]) == 2
    assert "unknown keys ['NOPE']" in capsys.readouterr().err


def test_every_task_key_builds_a_closed_cap(layout, surface):
    """All 31 keycaps close (coarse grid to stay fast; the grid lines still hit every socket edge)."""
    from tactile_braille.keyboard.layout import ALL_TASK_KEYS

    coarse = KeycapGeometry(resolution_mm=1.0)
    for key in ALL_TASK_KEYS:
        cap = build_keycap(key, layout, surface, coarse)
        assert mesh_volume_mm3(cap.facets) > 0
        triangles = cap.triangles
        edges = Counter(
            map(tuple, np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]))
        )
        assert all(count == 1 and (b, a) in edges for (a, b), count in edges.items()), key


def test_the_watertight_check_catches_holes_and_flipped_triangles(written):
    _, _, caps = written
    facets = caps["A"].facets
    with pytest.raises(AssertionError, match="border only one triangle"):
        assert_watertight(facets[1:])
    flipped = facets.copy()
    flipped[0] = flipped[0][[0, 2, 1]]
    with pytest.raises(AssertionError, match="run along twice"):
        assert_watertight(flipped)
    assert mesh_volume_mm3(facets[:, [0, 2, 1]]) < 0  # inward normals show as a negative volume
