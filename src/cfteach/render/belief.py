"""Belief pictures: a region of reward weights on the unit sphere (the paper's Fig. 3), a
particle belief on the sphere, and belief area after each demonstration for the four
conditions of a domain.

How the sphere is drawn (mesh shading, exact boundary arcs, view, labels, zoomed inset) is in
`render/_sphere_view.py`; its public helpers are re-exported here. Uses matplotlib's Agg
backend (no display needed).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from cfteach.render._sphere_view import BEC_COLOR as BEC_COLOR
from cfteach.render._sphere_view import BELIEF_COLOR as BELIEF_COLOR
from cfteach.render._sphere_view import BOTH_COLOR as BOTH_COLOR
from cfteach.render._sphere_view import (
    LIFT,
    OUTSIDE_COLOR,
    _auto_view,
    _draw_mesh,
    _eye,
    _finish_sphere,
    _normals,
    _region_colors,
    _sphere_axes,
    _zoom_inset,
    boundary_arcs,
    inside,
    region_radius,
    sphere_mesh,
)
from cfteach.render._sphere_view import _fig_xy as _fig_xy
from cfteach.render._sphere_view import _overlaps as _overlaps
from cfteach.render._sphere_view import region_vertices as region_vertices

CONDITION_ORDER = ("baseline", "feature_only", "counterfactual_only", "proposed")
CONDITION_COLORS = {
    "baseline": "#7f7f7f",
    "feature_only": "#1f77b4",
    "counterfactual_only": "#ff7f0e",
    "proposed": "#2ca02c",
}


def plot_belief_sphere(
    belief: Any,
    *,
    bec: Any = None,
    w_true: Sequence[float] | None = None,
    samples: Any = None,
    feature_names: Sequence[str] = ("w0", "w1", "w2"),
    title: str | None = None,
    resolution: int = 72,
    ax: Any = None,
    view: tuple[float, float] | None = None,
    zoom: bool | None = None,
) -> Any:
    """Draw a belief region (green) on the unit sphere, optionally a BEC region (yellow), the
    true weights (red star) and sampled human models (red dots). Returns the Figure.

    `zoom` adds an inset magnifying the belief region (gnomonic view around it); by default
    it is added when the region spans less than ~10 degrees, where it would be a dot."""
    import matplotlib

    matplotlib.use("Agg", force=False)

    if resolution < 8:
        raise ValueError(f"resolution must be at least 8, got {resolution}")
    nb = _normals(belief, "belief")
    ne = _normals(bec, "bec") if bec is not None else None
    verts, centres = sphere_mesh(resolution)
    in_b, colors = _region_colors(nb, ne, centres, OUTSIDE_COLOR)
    if view is None:
        direction = None
        if w_true is not None:
            direction = np.asarray(w_true, dtype=float)
        elif in_b.any():
            direction = centres[in_b].mean(axis=0)
        view = _auto_view(direction)
    eye = _eye(view)

    def front(points: np.ndarray, margin: float = 0.02) -> np.ndarray:
        return points @ eye > margin

    fig, ax = _sphere_axes(ax, title)
    _draw_mesh(ax, verts, centres, colors, eye)
    # Only what faces the viewer is drawn on top of the surface (draw order = call order).
    lift = LIFT
    for normals, color, style in ((ne, "#b8860b", "--"), (nb, "#1b5e20", "-")):
        if normals is None:
            continue
        for arc in boundary_arcs(normals):
            vis = front(arc)
            pts = np.where(vis[:, None], arc * lift, np.nan)
            ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], color=color, linewidth=1.6, ls=style)
    if samples is not None:
        s = np.asarray(samples, dtype=float).reshape(-1, 3)
        s = s / np.linalg.norm(s, axis=1, keepdims=True)
        s = s[front(s)] * lift
        ax.scatter(s[:, 0], s[:, 1], s[:, 2], color="#d62728", s=12, depthshade=False)
    _finish_sphere(fig, ax, view, feature_names, w_true)
    extent = region_radius(nb)
    if zoom is None:
        zoom = extent is not None and extent < np.radians(10)
    if zoom and extent is not None:
        _zoom_inset(fig, nb, ne, w_true, samples, extent)
    if title:
        ax.set_title(title, fontsize=10)
    return fig


PARTICLE_COLOR = np.array([0.11, 0.37, 0.13])  # the belief boundary's dark green
PRIOR_COLOR = np.array([0.30, 0.69, 0.31, 0.30])  # the belief green, faint: where w may lie


def plot_particles_sphere(
    particles: Any,
    weights: Any,
    *,
    w_true: Sequence[float] | None = None,
    feature_names: Sequence[str] = ("w0", "w1", "w2"),
    title: str | None = None,
    prior: Any = None,
    ax: Any = None,
    resolution: int = 72,
    view: tuple[float, float] | None = None,
) -> Any:
    """Draw a particle belief (cfteach.closedloop) on the unit sphere as `plot_belief_sphere`
    draws a region: dots in the belief's dark green, bigger and more opaque with more weight
    (relative to an equal share, capped at 6 times it); the
    prior region faintly shaded with its boundary; the true weights as the red star. Only the
    side facing the viewer is drawn (the view centres on w*, else on the weighted mean;
    `view` = (elevation, azimuth) in degrees fixes it, e.g. to compare panels).
    Returns the Figure."""
    import matplotlib

    matplotlib.use("Agg", force=False)

    pts = np.asarray(particles, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"particles: the sphere picture needs 3 features, i.e. particles of "
                         f"shape [P, 3]; got shape {pts.shape}")
    w = np.asarray(weights, dtype=float)
    if w.shape != (len(pts),):
        raise ValueError(f"weights: expected shape [{len(pts)}] (one per particle), "
                         f"got {w.shape}")
    if not (np.all(np.isfinite(pts)) and np.all(np.isfinite(w))) or np.any(w < 0):
        raise ValueError("particles and weights must be finite, weights non-negative")
    if resolution < 8:
        raise ValueError(f"resolution must be at least 8, got {resolution}")
    norms = np.linalg.norm(pts, axis=1, keepdims=True)
    pts = pts / np.where(norms > 0, norms, 1.0)
    nb = _normals(prior, "prior") if prior is not None else None
    verts, centres = sphere_mesh(resolution)
    colors = np.broadcast_to(OUTSIDE_COLOR, centres.shape[:-1] + (4,)).copy()
    if nb is not None:
        colors[inside(nb, centres)] = PRIOR_COLOR
    total = w.sum()
    if view is None:  # centre on w*, else on the weighted mean
        direction = np.asarray(w_true, dtype=float) if w_true is not None else (
            w @ pts / total if total > 0 else None)
        view = _auto_view(direction)
    eye = _eye(view)
    fig, ax = _sphere_axes(ax, title)
    _draw_mesh(ax, verts, centres, colors, eye)
    if nb is not None:
        for arc in boundary_arcs(nb):
            vis = arc @ eye > 0.02
            arc_pts = np.where(vis[:, None], arc * LIFT, np.nan)
            ax.plot(arc_pts[:, 0], arc_pts[:, 1], arc_pts[:, 2], color="#1b5e20",
                    linewidth=1.2, ls=":")
    if total > 0:
        rel = np.minimum(w * (len(w) / total), 6.0)  # 1 for an equally weighted particle
        keep = (pts @ eye > 0.02) & (rel > 0)
        order = np.argsort(rel[keep], kind="stable")  # heavy particles drawn last, on top
        shown, rel = pts[keep][order] * LIFT, rel[keep][order]
        rgba = np.column_stack([np.tile(PARTICLE_COLOR, (len(rel), 1)),
                                np.clip(0.1 + 0.3 * rel, 0.1, 0.9)])
        ax.scatter(shown[:, 0], shown[:, 1], shown[:, 2], s=1 + 5 * rel, c=rgba,
                   edgecolors="none", depthshade=False)
    _finish_sphere(fig, ax, view, feature_names, w_true)
    if title:
        ax.set_title(title, fontsize=10)
    return fig


def belief_area_series(curriculum: Mapping[str, Any]) -> tuple[list[int], list[float]]:
    """(demo counts, areas): the prior's area at 0 (when cfteach.geometry can compute it),
    then `belief_area_after` of each demonstration."""
    xs: list[int] = []
    ys: list[float] = []
    prior = curriculum.get("prior")
    if prior is not None:
        try:
            from cfteach.geometry import Region  # here: drawing alone needs no geometry
            from cfteach.render._slice_measure import prior_measure

            on_slice = prior_measure(curriculum)  # settings.known: the slice's measure
            xs.append(0)
            ys.append(float(Region(np.asarray(prior, dtype=float)).area())
                      if on_slice is None else on_slice)
        except Exception:  # the prior point is optional decoration
            xs, ys = [], []
    for i, demo in enumerate(curriculum.get("demos", []), start=1):
        xs.append(i)
        ys.append(float(demo["belief_area_after"]))
    return xs, ys


def plot_belief_areas(
    curricula: Mapping[str, Mapping[str, Any]],
    *,
    title: str | None = None,
    ax: Any = None,
) -> Any:
    """Belief area (steradians, log scale) after each demonstration, one line per condition."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    own = ax is None
    if ax is None:
        fig, ax = plt.subplots(figsize=(5.0, 3.2), dpi=100)
    else:
        fig = ax.figure
    ordered = [c for c in CONDITION_ORDER if c in curricula] + [
        c for c in curricula if c not in CONDITION_ORDER
    ]
    for k, cond in enumerate(ordered):
        xs, ys = belief_area_series(curricula[cond])
        color = CONDITION_COLORS.get(cond, f"C{k}")
        ax.plot(xs, ys, marker="o", ms=4, lw=1.6, color=color, label=cond, alpha=0.9)
    ax.set_yscale("log")
    from matplotlib.ticker import FuncFormatter, NullFormatter

    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("demonstrations shown")
    sliced = any((c.get("settings") or {}).get("known") for c in curricula.values())
    ax.set_ylabel("belief measure on the known-weight slice" if sliced
                  else "belief area (sr)")
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, frameon=False)
    if title:
        ax.set_title(title, fontsize=10)
    if own:  # fixed margins: tight_layout costs ~1 s on a log axis
        fig.subplots_adjust(left=0.15, right=0.97, bottom=0.16, top=0.9 if title else 0.96)
    return fig


def save_figure(fig: Any, path: Any, *, dpi: int = 100) -> None:
    """Save and close a figure (closing matters when a report draws dozens)."""
    import matplotlib.pyplot as plt

    fig.savefig(path, dpi=dpi)
    plt.close(fig)
