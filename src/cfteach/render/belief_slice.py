"""Belief pictures on a known-weight slice: with 3 features and one known weight the belief
is drawn in the plane of the two free weights, as arcs along the edge of the L1 ball
(measure ``edge``) or as a polygon inside it (measure ``ball``), never as a sphere.

The JSON's ``settings.known`` (`cfteach.teaching.known.settings_entry`) says which slice.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from cfteach.geometry.slice import KnownSlice, _intervals, _polygon, _square
from cfteach.render._slice_measure import prior_measure as prior_measure
from cfteach.render._slice_measure import slice_of
from cfteach.render.belief import plot_belief_sphere

BELIEF = "#2e9d4a"
BEC = "#e0b000"
SLICE = "#b8b8b8"


def _arcs(sl: KnownSlice, rows: Any) -> list[np.ndarray]:
    """Polylines of the belief on the edge (one per feasible piece of a side)."""
    a, b = sl.affine(np.asarray(rows, dtype=float).reshape(-1, sl.dim))
    sq = _square(sl.radius)
    out = []
    for j, lo, hi in _intervals(a, b, sl.radius):
        p, q = sq[j], sq[(j + 1) % 4]
        out.append(np.array([p + lo * (q - p), p + hi * (q - p)]))
    return out


def _draw(ax: Any, sl: KnownSlice, rows: Any, color: str, label: str, width: float) -> None:
    rows = np.asarray(rows, dtype=float).reshape(-1, sl.dim)
    if sl.measure == "edge":
        for k, seg in enumerate(_arcs(sl, rows)):
            ax.plot(seg[:, 0], seg[:, 1], color=color, lw=width, solid_capstyle="round",
                    label=label if k == 0 else None)
        return
    a, b = sl.affine(rows)
    poly = _polygon(a, b, sl.radius)
    if len(poly) >= 3:
        ax.fill(poly[:, 0], poly[:, 1], color=color, alpha=0.55, lw=1.2, ec=color, label=label)
    elif len(poly):
        ax.plot(poly[:, 0], poly[:, 1], color=color, lw=width, label=label)


def plot_belief_slice(constraints: Any, sl: KnownSlice, *, bec: Any = None,
                      feature_names: Sequence[str] = (), title: str | None = None,
                      ax: Any = None) -> Any:
    """Draw a belief (green), optionally a BEC (yellow), on the slice; w* as a star."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    if len(sl.free) != 2:
        raise ValueError(f"the slice picture needs exactly two unknown weights, got "
                         f"{len(sl.free)} (use --no-report)")
    fig, ax = plt.subplots(figsize=(4.2, 4.2), dpi=100) if ax is None else (ax.figure, ax)
    sq = np.vstack([_square(sl.radius), _square(sl.radius)[:1]])
    if sl.measure == "edge":
        ax.plot(sq[:, 0], sq[:, 1], color=SLICE, lw=1.5, label="the slice (|w|₁ = 1)")
    else:
        ax.fill(sq[:, 0], sq[:, 1], color=SLICE, alpha=0.3, lw=1, ec=SLICE,
                label="the slice (|w|₁ ≤ 1)")
    _draw(ax, sl, constraints, BELIEF, "belief", 4.0)
    if bec is not None:
        _draw(ax, sl, bec, BEC, "BEC", 2.2)
    star = sl.w_true[sl.free]
    ax.plot(star[0], star[1], marker="*", ms=12, color="black", ls="none", label="w*")
    names = list(feature_names) or [f"w{i}" for i in range(sl.dim)]
    ax.set_xlabel(f"{names[sl.free[0]]} weight")
    ax.set_ylabel(f"{names[sl.free[1]]} weight")
    fixed = ", ".join(f"{names[k]} = {sl.w_true[k]:+.3g}" for k in sl.known)
    ax.set_title((f"{title}\n" if title else "") + f"known: {fixed}", fontsize=9)
    ax.set_aspect("equal")
    lim = 1.08 * sl.radius
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.axhline(0, color="#dddddd", lw=0.6, zorder=0)
    ax.axvline(0, color="#dddddd", lw=0.6, zorder=0)
    ax.legend(fontsize=7, frameon=False, loc="upper left")
    fig.subplots_adjust(left=0.16, right=0.97, bottom=0.12, top=0.88)
    return fig


def belief_picture(constraints: Any, *, data: Mapping[str, Any], labels: Sequence[str],
                   title: str, bec: Any = None, resolution: int = 60) -> Any:
    """The belief picture a curriculum or tests JSON (`data`) calls for: on its known-weight
    slice when ``settings.known`` is set, else on the sphere (`plot_belief_sphere`)."""
    known = (data.get("settings") or {}).get("known")
    if known:
        sl = slice_of(known, data["weights"], data["feature_names"])
        return plot_belief_slice(constraints, sl, bec=bec, feature_names=labels, title=title)
    return plot_belief_sphere(constraints, bec=bec, w_true=data["weights"],
                              feature_names=labels, title=title, resolution=resolution)
