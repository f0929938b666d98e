"""Exact uniform sampling on a region of S^2, O(1) work per sample whatever its size.

Polygons are fanned into spherical triangles from the interior direction; a triangle is
picked with probability proportional to its area and sampled with Arvo's area-preserving
map (J. Arvo, "Stratified sampling of spherical triangles", SIGGRAPH 1995), or, for small
triangles where Arvo's formulas cancel, by exact rejection in the gnomonic projection. Hemispheres
and lunes are sampled in polar coordinates about their axis (Archimedes: the height is
uniform).
"""

from __future__ import annotations

import numpy as np

from .sphere3 import polygon_vertices, triangle_area


def _normalise(x: np.ndarray) -> np.ndarray:
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def _orthonormal_pair(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    e = np.zeros(3)
    e[int(np.argmin(np.abs(a)))] = 1.0
    b = np.cross(a, e)
    b /= np.linalg.norm(b)
    return b, np.cross(a, b)


def sample_sphere(m: int, rng: np.random.Generator) -> np.ndarray:
    """Uniform on the whole sphere (normalised Gaussians)."""
    return _normalise(rng.standard_normal((m, 3)))


def sample_hemisphere(n: np.ndarray, m: int, rng: np.random.Generator) -> np.ndarray:
    """Uniform on ``{w : n . w >= 0}`` (height along n uniform on [0, 1])."""
    b, c = _orthonormal_pair(n)
    z = rng.random(m)
    phi = 2 * np.pi * rng.random(m)
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    return z[:, None] * n + r[:, None] * (np.cos(phi)[:, None] * b + np.sin(phi)[:, None] * c)


def sample_lune(n1: np.ndarray, n2: np.ndarray, m: int, rng: np.random.Generator) -> np.ndarray:
    """Uniform on ``{w : n1 . w >= 0, n2 . w >= 0}`` for non-parallel unit normals.

    About the axis ``a = n1 x n2`` the lune is an azimuth wedge of width pi - theta centred
    on the bisector of the two normals; the height along ``a`` is uniform on [-1, 1].
    """
    a = _normalise(np.cross(n1, n2))
    bis = _normalise(n1 + n2)
    side = np.cross(a, bis)
    theta = np.arctan2(np.linalg.norm(np.cross(n1, n2)), n1 @ n2)
    half = (np.pi - theta) / 2
    z = 2 * rng.random(m) - 1
    phi = (2 * rng.random(m) - 1) * half
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    d = np.cos(phi)[:, None] * bis + np.sin(phi)[:, None] * side
    return z[:, None] * a + r[:, None] * d


def fan_triangles(
    unit_ordered: np.ndarray, centre: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Triangles (centre, v_j, v_{j+1}) covering a polygon, and their areas."""
    v = polygon_vertices(unit_ordered)
    b = v
    c = np.roll(v, -1, axis=0)
    a = np.broadcast_to(centre, b.shape)
    return a, b, c, triangle_area(a, b, c)


def arvo(
    a: np.ndarray, b: np.ndarray, c: np.ndarray, area: np.ndarray, xi1: np.ndarray, xi2: np.ndarray
) -> np.ndarray:
    """Arvo's map from (xi1, xi2) in [0, 1)^2 to triangle (a, b, c), all arrays per sample."""
    # angle at a between arcs ab and ac
    nab = np.cross(a, b)
    nac = np.cross(a, c)
    alpha = np.arctan2(
        np.linalg.norm(np.cross(nab, nac), axis=1), np.einsum("ij,ij->i", nab, nac)
    )
    cos_c = np.einsum("ij,ij->i", a, b)
    sub = xi1 * area
    s = np.sin(sub - alpha)
    t = np.cos(sub - alpha)
    uu = t - np.cos(alpha)
    vv = s + np.sin(alpha) * cos_c
    q = ((vv * t - uu * s) * np.cos(alpha) - vv) / ((vv * s + uu * t) * np.sin(alpha))
    q = np.clip(q, -1.0, 1.0)
    perp = _normalise(c - np.einsum("ij,ij->i", c, a)[:, None] * a)
    c_hat = q[:, None] * a + np.sqrt(1.0 - q * q)[:, None] * perp
    z = 1.0 - xi2 * (1.0 - np.einsum("ij,ij->i", c_hat, b))
    z = np.clip(z, -1.0, 1.0)
    perp2 = c_hat - np.einsum("ij,ij->i", c_hat, b)[:, None] * b
    nrm = np.linalg.norm(perp2, axis=1, keepdims=True)
    perp2 = np.divide(perp2, nrm, out=np.zeros_like(perp2), where=nrm > 0)
    return z[:, None] * b + np.sqrt(1.0 - z * z)[:, None] * perp2


#: Triangles with every side shorter than this (radians) are sampled by gnomonic
#: rejection instead of Arvo's map, whose formulas lose precision on tiny triangles.
SMALL_TRIANGLE = 0.05


def gnomonic_rejection(
    a: np.ndarray, b: np.ndarray, c: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """Exact uniform points in small spherical triangles (one per row of a, b, c).

    The gnomonic projection onto the plane tangent at ``a`` maps the triangle to a planar
    triangle, and the sphere's area element is ``dA / |x|^3`` there. So: draw ``x``
    uniformly in the planar triangle, keep it with probability ``1 / |x|^3`` (at least
    ``cos^3(side)``), redraw the rejected ones. No cancellation at any size.
    """
    out = np.empty_like(a)
    todo = np.arange(len(a))
    while len(todo):
        aa, bb, cc = a[todo], b[todo], c[todo]
        db = bb / np.einsum("ij,ij->i", bb, aa)[:, None] - aa
        dc = cc / np.einsum("ij,ij->i", cc, aa)[:, None] - aa
        r = rng.random((2, len(todo)))
        flip = r.sum(axis=0) > 1
        r[:, flip] = 1 - r[:, flip]
        off = r[0][:, None] * db + r[1][:, None] * dc
        x = aa + off
        n2 = np.einsum("ij,ij->i", x, x)
        keep = rng.random(len(todo)) * n2**1.5 <= 1.0
        out[todo[keep]] = x[keep] / np.sqrt(n2[keep])[:, None]
        todo = todo[~keep]
    return out


def sample_polygon(
    unit_ordered: np.ndarray, centre: np.ndarray, m: int, rng: np.random.Generator
) -> np.ndarray:
    """Uniform on a convex spherical polygon given its ordered irredundant normals."""
    a, b, c, areas = fan_triangles(unit_ordered, centre)
    cum = np.cumsum(areas)
    pick = np.searchsorted(cum, rng.random(m) * cum[-1], side="right")
    pick = np.minimum(pick, len(areas) - 1)
    sides = np.stack(
        [np.einsum("ij,ij->i", a, b), np.einsum("ij,ij->i", b, c), np.einsum("ij,ij->i", a, c)]
    )
    small = np.arccos(np.clip(sides.min(axis=0), -1.0, 1.0)) < SMALL_TRIANGLE
    out = np.empty((m, 3))
    use_small = small[pick]
    if use_small.any():
        ps = pick[use_small]
        out[use_small] = gnomonic_rejection(a[ps], b[ps], c[ps], rng)
    if (~use_small).any():
        pl = pick[~use_small]
        xi = rng.random((2, len(pl)))
        out[~use_small] = _normalise(arvo(a[pl], b[pl], c[pl], areas[pl], xi[0], xi[1]))
    return out
