"""How a region of reward weights is drawn on the unit sphere: the shading mesh, the exact
boundary arcs, the view, the axes and their labels, and the zoomed inset for small regions.
`render/belief.py` composes these into its pictures (and re-exports the public ones).

Shading is computed from the constraints directly and vectorised: a face of the sphere mesh
is inside a region iff its centre `p` satisfies `normals @ p >= 0` for every normal. Region
boundaries are drawn exactly, as the arcs of each constraint's great circle that satisfy all
the other constraints, so even regions smaller than one mesh face stay visible.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

BELIEF_COLOR = np.array([0.30, 0.69, 0.31, 0.85])  # green, as in the paper's Fig. 4
BEC_COLOR = np.array([0.99, 0.85, 0.21, 0.85])  # yellow
BOTH_COLOR = np.array([0.55, 0.62, 0.10, 0.95])  # where they overlap
OUTSIDE_COLOR = np.array([0.85, 0.87, 0.90, 0.35])


def _normals(constraints: Any, name: str) -> np.ndarray:
    """Constraint rows as a float array `[k, 3]`; a clear error for anything else."""
    arr = np.asarray(constraints, dtype=float)
    if arr.size == 0:
        return np.zeros((0, 3))
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(
            f"{name}: the sphere picture needs 3 features, i.e. constraints of shape [k, 3]; "
            f"got shape {arr.shape}"
        )
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: constraints contain non-finite values")
    return arr


def inside(normals: np.ndarray, points: np.ndarray, tol: float = 0.0) -> np.ndarray:
    """Boolean mask over `points[..., 3]`: every constraint `n . p >= -tol` holds."""
    if len(normals) == 0:
        return np.ones(points.shape[:-1], dtype=bool)
    return np.all(points @ normals.T >= -tol, axis=-1)


def _region_colors(nb: np.ndarray, ne: np.ndarray | None, points: np.ndarray,
                   outside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """RGBA per point of `points[..., 3]`: belief green, BEC yellow, both olive, else
    `outside`; also the mask of points inside the belief."""
    in_b = inside(nb, points)
    colors = np.broadcast_to(outside, points.shape[:-1] + (4,)).copy()
    colors[in_b] = BELIEF_COLOR
    if ne is not None:
        in_e = inside(ne, points)
        colors[in_e & ~in_b] = BEC_COLOR
        colors[in_e & in_b] = BOTH_COLOR
    return in_b, colors


def _plane_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors `u`, `v` that complete the unit vector `n` to a right-handed frame."""
    helper = np.eye(3)[np.argmin(np.abs(n))]
    u = np.cross(n, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def sphere_mesh(resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertices `[r+1, 2r+1, 3]` of a latitude/longitude mesh and unit face centres `[r, 2r, 3]`."""
    theta = np.linspace(0.0, np.pi, resolution + 1)  # polar angle
    phi = np.linspace(-np.pi, np.pi, 2 * resolution + 1)  # azimuth
    t, p = np.meshgrid(theta, phi, indexing="ij")
    verts = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    centres = (verts[:-1, :-1] + verts[1:, :-1] + verts[:-1, 1:] + verts[1:, 1:]) / 4.0
    norms = np.linalg.norm(centres, axis=-1, keepdims=True)
    return verts, centres / np.maximum(norms, 1e-12)


def boundary_arcs(normals: np.ndarray, n_points: int = 720) -> list[np.ndarray]:
    """The region's edges: for each constraint, the points of its great circle inside all others."""
    arcs = []
    t = np.linspace(0.0, 2 * np.pi, n_points, endpoint=False)
    for i, n in enumerate(normals):
        norm = np.linalg.norm(n)
        if norm == 0:
            continue
        u, v = _plane_basis(n / norm)
        circle = np.cos(t)[:, None] * u + np.sin(t)[:, None] * v
        others = np.delete(normals, i, axis=0)
        keep = inside(others, circle, tol=1e-9)
        if not keep.any():
            continue
        # Split into contiguous runs (the circle is closed, so rotate to start at a gap).
        if keep.all():
            arcs.append(np.vstack([circle, circle[:1]]))
            continue
        start = int(np.argmin(keep))
        order = np.roll(np.arange(n_points), -start)
        run: list[int] = []
        for idx in order:
            if keep[idx]:
                run.append(int(idx))
            elif run:
                arcs.append(circle[run])
                run = []
        if run:
            arcs.append(circle[run])
    return arcs


def _view_of(direction: np.ndarray) -> tuple[float, float]:
    d = direction / np.linalg.norm(direction)
    elev = float(np.degrees(np.arcsin(np.clip(d[2], -1, 1))))
    azim = float(np.degrees(np.arctan2(d[1], d[0])))
    return elev, azim


LIFT = 1.01  # marks and arcs sit just above the sphere's surface


def _auto_view(direction: np.ndarray | None) -> tuple[float, float]:
    """(elevation, azimuth) looking at `direction` (a default when None or zero), slightly
    from the side so the sphere reads as 3-D with the direction still in front."""
    if direction is None or np.linalg.norm(direction) < 1e-9:
        direction = np.array([1.0, -1.0, 0.6])
    elev, azim = _view_of(direction)
    return (max(-55.0, min(55.0, elev + 10.0)), azim + 18.0)


def _eye(view: tuple[float, float]) -> np.ndarray:
    """Unit vector towards the viewer for an (elevation, azimuth) in degrees."""
    el, az = np.radians(view[0]), np.radians(view[1])
    return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


def _sphere_axes(ax: Any, title: str | None) -> tuple[Any, Any]:
    """(figure, 3-D axes): the given axes, or a new square figure with one."""
    import matplotlib.pyplot as plt

    if ax is None:
        fig = plt.figure(figsize=(3.6, 3.6), dpi=100)
        ax = fig.add_subplot(projection="3d", computed_zorder=False)
        fig.subplots_adjust(left=0, right=1, bottom=0, top=0.92 if title else 1.0)
        return fig, ax
    return ax.figure, ax


def _draw_mesh(ax: Any, verts: np.ndarray, centres: np.ndarray, colors: np.ndarray,
               eye: np.ndarray) -> None:
    """One quad per mesh face; only the faces turned towards the viewer (orthographic view),
    with colours as one float array (matplotlib's fast path)."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    quads = np.stack([verts[:-1, :-1], verts[1:, :-1], verts[1:, 1:], verts[:-1, 1:]], axis=2)
    visible = centres @ eye > -0.08
    mesh = Poly3DCollection(
        quads[visible], facecolors=colors[visible], edgecolors="none", linewidths=0
    )
    mesh.set_antialiased(False)
    ax.add_collection3d(mesh)


def _finish_sphere(fig: Any, ax: Any, view: tuple[float, float],
                   feature_names: Sequence[str], w_true: Sequence[float] | None) -> None:
    """Axis stubs and names, the true weights (red star), the orthographic camera."""
    eye = _eye(view)
    labels: list[tuple[np.ndarray, str]] = []
    for k, name in enumerate(list(feature_names)[:3]):
        axis = np.eye(3)[k]
        if axis @ eye > -0.2:  # a stub for each positive axis that is not hidden
            ax.plot(*zip(1.0 * axis, 1.25 * axis, strict=True), color="#444444", lw=1.0)
        labels.append((1.33 * axis, f"+{name}"))
    star = None  # where "w*" goes: beside its star, or nowhere when the star is hidden
    if w_true is not None:
        w = np.asarray(w_true, dtype=float)
        w = w / np.linalg.norm(w)
        if w @ eye > 0.02:
            ax.scatter(*(w[:, None] * LIFT), color="#b71c1c", marker="*", s=110,
                       depthshade=False)
            star = w * LIFT
    ax.set_proj_type("ortho")
    ax.view_init(elev=view[0], azim=view[1])
    ax.set_box_aspect((1, 1, 1), zoom=1.4)
    ax.set_xlim(-1.05, 1.05)
    ax.set_ylim(-1.05, 1.05)
    ax.set_zlim(-1.05, 1.05)
    ax.set_axis_off()
    _place_labels(fig, ax, labels, star=star)


def region_vertices(normals: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Corners of a region: unit vectors on two constraint planes that satisfy all others."""
    units = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    k = len(units)
    if k < 2:
        return np.zeros((0, 3))
    i, j = np.triu_indices(k, 1)
    cross = np.cross(units[i], units[j])
    norm = np.linalg.norm(cross, axis=1)
    cross = cross[norm > 1e-12] / norm[norm > 1e-12, None]
    cand = np.vstack([cross, -cross])
    return cand[np.all(cand @ units.T >= -tol, axis=1)]


def region_radius(normals: np.ndarray) -> float | None:
    """Largest angle (radians) from the corners' mean direction to a corner; None when the
    region has no corners (a hemisphere or lune) or is not small enough to be bounded."""
    if len(normals) < 3:
        return None
    verts = region_vertices(normals)
    if len(verts) < 3:
        return None
    c = verts.mean(axis=0)
    if np.linalg.norm(c) < 1e-9:
        return None
    c /= np.linalg.norm(c)
    return float(np.arccos(np.clip(verts @ c, -1, 1)).max())


def _zoom_inset(
    fig: Any,
    nb: np.ndarray,
    ne: np.ndarray | None,
    w_true: Any,
    samples: Any,
    extent: float,
    pixels: int = 160,
) -> None:
    """A magnified, flat (gnomonic) view of a small belief region in the figure's corner:
    great circles are straight lines there, so the region keeps its true polygon shape."""
    verts = region_vertices(nb)
    c = verts.mean(axis=0)
    c /= np.linalg.norm(c)
    u, v = _plane_basis(c)
    half = 1.6 * np.tan(extent) + 1e-9
    g = np.linspace(-half, half, pixels)
    gx, gy = np.meshgrid(g, g[::-1])
    pts = c + gx[..., None] * u + gy[..., None] * v
    pts /= np.linalg.norm(pts, axis=-1, keepdims=True)
    _, colors = _region_colors(nb, ne, pts, np.array([1.0, 1.0, 1.0, 1.0]))
    inset = fig.add_axes((0.66, 0.03, 0.32, 0.32))
    inset.imshow(colors, extent=(-half, half, -half, half), interpolation="nearest")

    def flat(p: np.ndarray) -> np.ndarray:
        p = np.atleast_2d(np.asarray(p, dtype=float))
        p = p / np.linalg.norm(p, axis=1, keepdims=True)
        d = p @ c
        q = p / np.where(d > 1e-9, d, np.nan)[:, None]
        return np.stack([q @ u, q @ v], axis=1)

    corners = flat(verts)
    order = np.argsort(np.arctan2(corners[:, 1], corners[:, 0]))
    ring = corners[np.r_[order, order[:1]]]
    inset.plot(ring[:, 0], ring[:, 1], color="#1b5e20", lw=1.2)
    if samples is not None:
        sp = flat(np.asarray(samples, dtype=float).reshape(-1, 3))
        inset.scatter(sp[:, 0], sp[:, 1], color="#d62728", s=8)
    if w_true is not None:
        wp = flat(w_true)
        inset.scatter(wp[:, 0], wp[:, 1], color="#b71c1c", marker="*", s=60)
    inset.set_xlim(-half, half)
    inset.set_ylim(-half, half)
    inset.set_xticks([])
    inset.set_yticks([])
    for spine in inset.spines.values():
        spine.set_color("#666666")
    inset.set_title(f"zoom: {np.degrees(2 * half):.2g}° wide", fontsize=7, pad=2)


def _fig_xy(fig: Any, ax: Any, point: np.ndarray) -> np.ndarray:
    from mpl_toolkits.mplot3d import proj3d

    x2, y2, _ = proj3d.proj_transform(*point, ax.get_proj())
    return fig.transFigure.inverted().transform(ax.transData.transform((x2, y2)))


def _overlaps(a: Any, b: Any) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def _place_labels(fig: Any, ax: Any, labels: list[tuple[np.ndarray, str]],
                  star: np.ndarray | None = None) -> list[Any]:
    """Axis names, and "w*" beside its star, as figure texts; returns the Text objects.

    Each name sits beyond the end of its axis stub and extends away from the sphere's
    centre, so the stub never runs through it; measured boxes are then moved inside the
    figure and off one another (and "w*" off its star)."""
    from matplotlib.transforms import Bbox

    renderer = fig.canvas.get_renderer()
    to_fig = fig.transFigure.inverted()
    centre = _fig_xy(fig, ax, np.zeros(3))
    items = [(text, _fig_xy(fig, ax, point), 0.0) for point, text in labels]
    if star is not None:
        items.append(("w*", _fig_xy(fig, ax, star), 0.03))
    taken: list[Any] = []
    if star is not None:
        sx, sy = items[-1][1]
        taken.append(Bbox([[sx - 0.03, sy - 0.03], [sx + 0.03, sy + 0.03]]))  # the star
    texts = []
    for text, (fx, fy), gap in items:
        dx, dy = fx - centre[0], fy - centre[1]
        ha = "left" if dx >= 0 else "right"
        va = "bottom" if dy >= 0 else "top"
        red = text == "w*"
        t = fig.text(fx + (gap if dx >= 0 else -gap), fy + (gap if dy >= 0 else -gap), text,
                     fontsize=9 if red else 8, ha=ha, va=va,
                     color="#b71c1c" if red else "black")
        box = t.get_window_extent(renderer).transformed(to_fig)
        shift_x = max(0.0, 0.01 - box.x0) - max(0.0, box.x1 - 0.99)
        shift_y = max(0.0, 0.01 - box.y0) - max(0.0, box.y1 - 0.91)
        if abs(shift_x) > 1e-9 and not red:  # pushed back over its stub: step off the line
            shift_y += 0.6 * box.height if dy >= 0 else -0.6 * box.height
        box = box.translated(shift_x, shift_y)
        step = box.height + 0.005
        for _ in range(6):  # away from the centre, vertically, until nothing is hit
            if not any(_overlaps(box, other) for other in taken):
                break
            move = step if (dy >= 0 and box.y1 + step <= 0.91) or box.y0 - step < 0.01 \
                else -step
            box = box.translated(0.0, move)
            shift_y += move
        x, y = t.get_position()
        t.set_position((x + shift_x, y + shift_y))
        taken.append(box)
        texts.append(t)
    return texts
