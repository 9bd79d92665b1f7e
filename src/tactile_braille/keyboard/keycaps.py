"""3D-printable braille keycaps, cut from the same keyboard model the simulator touches.

The top of each keycap *is* the simulator's keyboard surface
(:class:`~tactile_braille.keyboard.surface.KeyboardSurface`: the flat
rounded top, the braille dots or arrow ridges of
:mod:`~tactile_braille.keyboard.braille`, the skirt), sampled over the key's
footprint, so a printed cap and its simulated twin feel the same. Under it
is a printable body (:class:`KeycapGeometry`): walls, a hollow that clears
the switch's housing, and a stem column with a Cherry MX cross socket (plus
stabiliser sockets on SPACE).

The solid is a height field on a rectilinear grid whose lines include every
edge of the socket and the hollow: the top surface on the grid's nodes, the
underside one flat level per cell (so the socket's walls are vertical and
exact), side walls around the outline. That makes a closed, consistently
oriented (outward) triangle mesh, written as binary STL with NumPy alone.

STL axes: ``X`` to the typist's right, ``Y`` away from the typist, ``Z`` up
from the rim, millimetres; the braille reads correctly from above. In the
keyboard frame that is ``X = -y``, ``Y = -x`` about the key centre.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tactile_braille._io import atomic_path
from tactile_braille.keyboard.braille import BRAILLE_DOTS, BrailleGeometry, dot_positions_mm
from tactile_braille.keyboard.layout import ALL_TASK_KEYS, KeyboardLayout
from tactile_braille.keyboard.surface import KeyboardSurface

STABILISER_OFFSETS_MM: dict[float, float] = {2.0: 11.9, 2.25: 11.9, 2.75: 11.9, 6.25: 50.0}
"""Cherry plate-mount stabiliser stems either side of the centre stem, by key width (u)."""

_STL_TRIANGLE = np.dtype([("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("attribute", "<u2")])


@dataclass(frozen=True)
class KeycapGeometry:
    """The printable body under the modelled keycap top (mm).

    Attributes:
        base_inset_mm: the cap's footprint is the key cell less this on each
            side (an 18 mm cap on the 19 mm pitch).
        height_mm: from the rim's bottom to the flat top.
        wall_mm: thickness of the side walls at the rim.
        hollow_height_mm: height of the hollow inside, which the switch's
            housing enters as the key goes down (4 mm total travel).
        roof_mm: least material over the hollow.
        stem_column_diameter_mm: the column that carries the socket.
        socket_arm_length_mm, socket_arm_width_mm: the cross socket (Cherry MX: 4.0 x 1.3).
        socket_depth_mm: how far the stem goes in.
        resolution_mm: grid step of the top surface (and of curved outlines).
    """

    base_inset_mm: float = 0.5
    height_mm: float = 10.0
    wall_mm: float = 1.2
    hollow_height_mm: float = 5.0
    roof_mm: float = 1.2
    stem_column_diameter_mm: float = 5.5
    socket_arm_length_mm: float = 4.0
    socket_arm_width_mm: float = 1.3
    socket_depth_mm: float = 4.0
    resolution_mm: float = 0.25

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not value > 0:
                raise ValueError(f"{name} must be positive, got {value!r}")
        if self.resolution_mm < 0.01:
            raise ValueError(
                f"resolution_mm {self.resolution_mm} is finer than 0.01 mm, which no printer resolves "
                "and whose mesh would not fit in memory"
            )
        if self.socket_depth_mm >= self.hollow_height_mm:
            raise ValueError(
                "socket_depth_mm must be less than hollow_height_mm (the column holds the socket)"
            )
        if self.socket_arm_length_mm >= self.stem_column_diameter_mm:
            raise ValueError("the socket's cross must fit inside the stem column")


@dataclass(frozen=True)
class Keycap:
    """One keycap: its height fields and its closed triangle mesh (STL axes, mm).

    Attributes:
        key: key name.
        xs, ys: grid lines along X and Y.
        top_mm: (len(xs), len(ys)) top height at the grid nodes.
        bottom_mm: (len(xs) - 1, len(ys) - 1) underside height of each cell.
        vertices: (n, 3) mesh vertices.
        triangles: (m, 3) vertex indices, counter-clockwise seen from outside.
        stems_mm: X positions of the stem sockets (centre first).
    """

    key: str
    xs: np.ndarray
    ys: np.ndarray
    top_mm: np.ndarray
    bottom_mm: np.ndarray
    vertices: np.ndarray
    triangles: np.ndarray
    stems_mm: tuple[float, ...]

    @property
    def facets(self) -> np.ndarray:
        """(m, 3, 3) triangle corners."""
        return self.vertices[self.triangles]


def _grid_lines(half: float, features: list[float], step: float) -> np.ndarray:
    """Lines from -half to half about ``step`` apart that include every feature edge exactly."""
    features = sorted({round(f, 9) for f in features if -half < f < half} | {-half, half})
    lines = [features[0]]
    for start, end in itertools.pairwise(features):
        count = max(int(np.ceil((end - start) / step - 1e-9)), 1)
        lines.extend(np.linspace(start, end, count + 1)[1:])
    return np.array(lines)


def _body_heights(key_width_u: float, pitch_mm: float, geometry: KeycapGeometry):
    """Grid lines, stem positions and the underside height of each cell."""
    g = geometry
    half_x = key_width_u * pitch_mm / 2 - g.base_inset_mm
    half_y = pitch_mm / 2 - g.base_inset_mm
    offset = STABILISER_OFFSETS_MM.get(key_width_u)
    stems = (0.0,) if offset is None else (0.0, -offset, offset)
    arm, width, column = g.socket_arm_length_mm / 2, g.socket_arm_width_mm / 2, g.stem_column_diameter_mm / 2
    x_features = [-(half_x - g.wall_mm), half_x - g.wall_mm]
    for s in stems:
        x_features += [s - arm, s - width, s + width, s + arm, s - column, s + column]
    y_features = [-(half_y - g.wall_mm), half_y - g.wall_mm, -arm, -width, width, arm, -column, column]
    xs = _grid_lines(half_x, x_features, g.resolution_mm)
    ys = _grid_lines(half_y, y_features, g.resolution_mm)
    cx = (xs[:-1] + xs[1:])[:, None] / 2
    cy = (ys[:-1] + ys[1:])[None, :] / 2
    inner = (np.abs(cx) < half_x - g.wall_mm) & (np.abs(cy) < half_y - g.wall_mm)
    bottom = np.where(inner, g.hollow_height_mm, 0.0)
    for s in stems:
        dx, dy = np.abs(cx - s), np.abs(cy)
        bottom = np.where(np.hypot(dx, dy) < column, 0.0, bottom)
        cross = ((dx < arm) & (dy < width)) | ((dx < width) & (dy < arm))
        bottom = np.where(cross, g.socket_depth_mm, bottom)
    return xs, ys, stems, np.broadcast_to(bottom, (len(xs) - 1, len(ys) - 1)).copy()


def _ladder(chain_a: list[int], chain_b: list[int], z: dict[int, float]) -> list[tuple[int, int, int]]:
    """Triangles between two vertical chains of vertices (each sorted by height, same bottom and top)."""
    triangles, i, j = [], 0, 0
    while i < len(chain_a) - 1 or j < len(chain_b) - 1:
        advance_a = j == len(chain_b) - 1 or (i < len(chain_a) - 1 and z[chain_a[i + 1]] <= z[chain_b[j + 1]])
        if advance_a:
            triangles.append((chain_a[i], chain_a[i + 1], chain_b[j]))
            i += 1
        else:
            triangles.append((chain_a[i], chain_b[j + 1], chain_b[j]))
            j += 1
    return triangles


def build_keycap(
    key: str,
    layout: KeyboardLayout | None = None,
    surface: KeyboardSurface | None = None,
    geometry: KeycapGeometry | None = None,
) -> Keycap:
    """The printable keycap of ``key``: the modelled top over a body with an MX stem socket.

    Args:
        key: a key of the layout.
        layout: the keyboard (default: the paper's).
        surface: the keyboard surface the simulator uses (built from
            ``layout`` if not given; pass one to share its raster).
        geometry: the printable body.

    Raises:
        ValueError: the body does not fit under the top (roof too thin).
    """
    layout = layout or KeyboardLayout()
    surface = surface or KeyboardSurface(layout)
    geometry = geometry or KeycapGeometry()
    cell = layout.key(key)
    xs, ys, stems, bottom = _body_heights(cell.width_u, layout.pitch_mm, geometry)
    grid_x, grid_y = np.meshgrid(xs, ys, indexing="ij")
    # STL X = -y, Y = -x about the key centre (see the module docstring).
    top = geometry.height_mm + surface.sample(cell.centre_x_mm - grid_y, cell.centre_y_mm - grid_x)
    lowest_top = np.minimum.reduce([top[:-1, :-1], top[1:, :-1], top[:-1, 1:], top[1:, 1:]])
    hollow = bottom >= geometry.hollow_height_mm
    if (lowest_top - bottom < np.where(hollow, geometry.roof_mm, 0.5)).any():
        raise ValueError(f"{key}: the keycap's top comes too close to its underside; raise height_mm")
    vertices, triangles = _mesh(xs, ys, top, bottom)
    return Keycap(key, xs, ys, top, bottom, vertices, triangles, stems)


def _mesh(
    xs: np.ndarray, ys: np.ndarray, top: np.ndarray, bottom: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    nx, ny = len(xs), len(ys)
    top_xyz = zip(np.repeat(xs, ny), np.tile(ys, nx), top.ravel(), strict=True)
    vertices: list[tuple[float, float, float]] = [(float(x), float(y), float(z)) for x, y, z in top_xyz]
    top_id = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = top_id[:-1, :-1], top_id[1:, :-1], top_id[1:, 1:], top_id[:-1, 1:]
    faces = [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]  # up

    # Underside: one vertex per (node, level) for each level of the cells around the node.
    padded = np.pad(bottom, 1, constant_values=np.nan)
    around = np.stack([padded[:-1, :-1], padded[1:, :-1], padded[:-1, 1:], padded[1:, 1:]], -1)
    level_id: dict[tuple[int, int, float], int] = {}
    levels_at: dict[tuple[int, int], list[float]] = {}
    z_of: dict[int, float] = {}
    for i in range(nx):
        for j in range(ny):
            levels_at[i, j] = [float(v) for v in np.unique(around[i, j][~np.isnan(around[i, j])])]
            for level in levels_at[i, j]:
                z_of[len(vertices)] = level
                level_id[i, j, level] = len(vertices)
                vertices.append((xs[i], ys[j], level))
    ids = np.vectorize(lambda i, j, z: level_id[i, j, z], otypes=[np.int64])
    ci, cj = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), indexing="ij")
    ba, bb = ids(ci, cj, bottom), ids(ci + 1, cj, bottom)
    bc, bd = ids(ci + 1, cj + 1, bottom), ids(ci, cj + 1, bottom)
    faces += [np.stack([ba, bc, bb], -1).reshape(-1, 3), np.stack([ba, bd, bc], -1).reshape(-1, 3)]  # down

    walls: list[tuple[int, int, int]] = []
    wanted: list[tuple[float, float]] = []  # outward normal (x, y) of each wall triangle

    def chain(i: int, j: int, low: float, high: float) -> list[int]:
        return [level_id[i, j, z] for z in levels_at[i, j] if low <= z <= high]  # sorted by np.unique

    def wall(n0: tuple[int, int], n1: tuple[int, int], low: float, high: float, normal: tuple[float, float]):
        new = _ladder(chain(*n0, low, high), chain(*n1, low, high), z_of)
        walls.extend(new)
        wanted.extend([normal] * len(new))

    for i in range(1, nx - 1):  # between cells (i-1, j) and (i, j), in the plane x = xs[i]
        for j in np.flatnonzero(bottom[i - 1] != bottom[i]):
            left, right = bottom[i - 1, j], bottom[i, j]
            wall(
                (i, j),
                (i, j + 1),
                min(left, right),
                max(left, right),
                (1.0, 0.0) if right > left else (-1.0, 0.0),
            )
    for j in range(1, ny - 1):  # between cells (i, j-1) and (i, j), in the plane y = ys[j]
        for i in np.flatnonzero(bottom[:, j - 1] != bottom[:, j]):
            low_cell, high_cell = bottom[i, j - 1], bottom[i, j]
            normal = (0.0, 1.0) if high_cell > low_cell else (0.0, -1.0)
            wall((i, j), (i + 1, j), min(low_cell, high_cell), max(low_cell, high_cell), normal)

    # Outer walls: from the rim (level 0) up to the top surface.
    rim = [(i, 0) for i in range(nx)] + [(nx - 1, j) for j in range(ny)]
    rim += [(i, ny - 1) for i in range(nx - 1, -1, -1)] + [(0, j) for j in range(ny - 1, -1, -1)]
    for (i0, j0), (i1, j1) in itertools.pairwise(rim):
        if (i0, j0) == (i1, j1):
            continue
        b0, b1 = level_id[i0, j0, 0.0], level_id[i1, j1, 0.0]
        t0, t1 = top_id[i0, j0], top_id[i1, j1]
        normal = (0.0, -1.0) if j0 == j1 == 0 else (1.0, 0.0) if i0 == i1 == nx - 1 else (
            (0.0, 1.0) if j0 == j1 == ny - 1 else (-1.0, 0.0))  # fmt: skip
        walls += [(b0, b1, t1), (b0, t1, t0)]
        wanted += [normal, normal]

    vertices_array = np.array(vertices, dtype=np.float64)
    triangles = np.concatenate([*faces, np.array(walls, dtype=np.int64).reshape(-1, 3)])
    # Orient the walls outward (their ladders are built in either sense).
    corners = vertices_array[triangles[-len(walls) :]] if walls else np.zeros((0, 3, 3))
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    flip = (normals[:, :2] * np.array(wanted).reshape(-1, 2)).sum(-1) < 0
    wall_triangles = triangles[-len(walls) :] if walls else triangles[:0]
    wall_triangles[flip] = wall_triangles[flip][:, [0, 2, 1]]
    return vertices_array, triangles


def mesh_volume_mm3(facets: np.ndarray) -> float:
    """Signed volume enclosed by triangles (divergence theorem); positive when they face outward."""
    facets = np.asarray(facets, dtype=np.float64)
    return float(np.einsum("ij,ij->i", facets[:, 0], np.cross(facets[:, 1], facets[:, 2])).sum() / 6.0)


def write_stl(path: str | Path, facets: np.ndarray, name: str = "keycap") -> Path:
    """Write triangles (m, 3, 3) as binary STL (atomically); normals from the winding."""
    facets = np.asarray(facets, dtype=np.float64)
    normals = np.cross(facets[:, 1] - facets[:, 0], facets[:, 2] - facets[:, 0])
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.divide(normals, lengths, out=np.zeros_like(normals), where=lengths > 0)
    records = np.zeros(len(facets), dtype=_STL_TRIANGLE)
    records["normal"] = normals
    records["vertices"] = facets
    header = f"tactile_braille keycap {name}".encode("ascii", "replace")[:80].ljust(80, b" ")
    with atomic_path(path) as temporary:
        temporary.write_bytes(header + np.uint32(len(facets)).tobytes() + records.tobytes())
    return Path(path)


def read_stl(path: str | Path) -> np.ndarray:
    """The triangles (m, 3, 3) of a binary STL file (float32)."""
    data = Path(path).read_bytes()
    if len(data) < 84:
        raise ValueError(f"{path} is too short to be a binary STL")
    count = int(np.frombuffer(data, dtype="<u4", count=1, offset=80)[0])
    if len(data) != 84 + count * _STL_TRIANGLE.itemsize:
        raise ValueError(
            f"{path}: header says {count} triangles, the file holds {len(data) - 84} bytes after it"
        )
    return np.frombuffer(data, dtype=_STL_TRIANGLE, count=count, offset=84)["vertices"].copy()


def braille_cell_stl_mm(geometry: BrailleGeometry | None = None) -> dict[int, tuple[float, float]]:
    """STL (X, Y) of the six dot positions of a braille cell on a keycap, by dot number."""
    cell: dict[int, tuple[float, float]] = {}
    for letter, dots in BRAILLE_DOTS.items():
        for dot, (x, y) in zip(dots, dot_positions_mm(letter, geometry), strict=True):
            cell[dot] = (-float(y), -float(x))
    return dict(sorted(cell.items()))


def write_keycaps(
    output: str | Path,
    keys: tuple[str, ...] = ALL_TASK_KEYS,
    geometry: KeycapGeometry | None = None,
    layout: KeyboardLayout | None = None,
) -> list[Path]:
    """Write ``keycap_<KEY>.stl`` for each key and ``keycaps_preview.png`` into ``output``."""
    layout = layout or KeyboardLayout()
    surface = KeyboardSurface(layout)
    output = Path(output)
    written, caps = [], []
    for key in keys:
        cap = build_keycap(key, layout, surface, geometry)
        written.append(write_stl(output / f"keycap_{key}.stl", cap.facets, key))
        caps.append(cap)
    written.append(save_keycap_preview(caps, output / "keycaps_preview.png"))
    return written


def save_keycap_preview(caps: list[Keycap], path: str | Path) -> Path:
    """A PNG of the keycaps: a shaded top view of each, and the underside of the first."""
    from matplotlib.colors import LightSource

    from tactile_braille._figures import new_figure, save_figure

    shade = LightSource(azdeg=315, altdeg=35)
    panels = len(caps) + 1
    columns = min(panels, 8)
    rows = int(np.ceil(panels / columns))
    fig, axes = new_figure(rows, columns, figsize=(2.0 * columns, 2.1 * rows))
    for ax in axes.ravel():
        ax.axis("off")
    for ax, cap in zip(axes.ravel(), caps, strict=False):
        extent = (cap.xs[0], cap.xs[-1], cap.ys[0], cap.ys[-1])
        ax.imshow(shade.hillshade(cap.top_mm.T, vert_exag=4.0), cmap="gray", origin="lower", extent=extent)
        ax.set_title(f"{cap.key} top", fontsize=9)
    first = caps[0]
    ax = axes.ravel()[len(caps)]
    image = ax.imshow(first.bottom_mm.T, cmap="viridis", origin="lower",
                      extent=(first.xs[0], first.xs[-1], first.ys[0], first.ys[-1]))  # fmt: skip
    ax.set_title(f"{first.key} underside", fontsize=9)
    fig.colorbar(image, ax=ax, fraction=0.046, pad=0.04).set_label("height (mm)", fontsize=8)
    fig.suptitle("Braille keycaps (STL, mm): shaded tops; underside with the MX socket", fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)
