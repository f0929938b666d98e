"""Belief pictures: the shading is the region (checked against cfteach.geometry and closed-form
areas), the boundary arcs lie on the constraint planes, and the plots show what they claim."""

from __future__ import annotations

import math

import matplotlib
import numpy as np
import pytest

from cfteach.geometry import Region
from cfteach.render import belief as bel

matplotlib.use("Agg")


def face_areas(resolution: int) -> np.ndarray:
    """Exact areas of the lat/long mesh faces: dphi * (cos t0 - cos t1)."""
    theta = np.linspace(0, np.pi, resolution + 1)
    band = np.cos(theta[:-1]) - np.cos(theta[1:])
    return np.repeat(band[:, None], 2 * resolution, axis=1) * (np.pi / resolution)


def on_white(rgba: np.ndarray) -> np.ndarray:
    """The colour a translucent RGBA face shows over the white figure background."""
    return np.round(255 * (rgba[:3] * rgba[3] + (1 - rgba[3]))).astype(int)


def test_mesh_shading_agrees_with_geometry_region_contains():
    rng = np.random.default_rng(3)
    normals = np.array([[-1, 0, 0], [0, 1, 0], [0, 0, -1], [1, 0, -2]], dtype=float)
    pts = rng.normal(size=(4000, 3))
    pts /= np.linalg.norm(pts, axis=1, keepdims=True)
    ours = bel.inside(normals, pts)
    region = Region(normals.astype(int))
    theirs = np.array([region.contains(p) for p in pts])
    assert ours.any() and (ours == theirs).all()


@pytest.mark.parametrize(
    ("normals", "area"),
    [
        ([[0, 0, -1]], 2 * math.pi),  # hemisphere
        ([[-1, 0, 0], [0, 1, 0], [0, 0, -1]], math.pi / 2),  # octant
        ([[1, 0, 0], [-1, 1, 0]], 2 * (math.pi / 4)),  # lune of dihedral angle pi/4: 2*theta
    ],
)
def test_shaded_area_matches_closed_form(normals, area):
    res = 120
    _, centres = bel.sphere_mesh(res)
    shaded = face_areas(res)[bel.inside(np.array(normals, float), centres)].sum()
    assert face_areas(res).sum() == pytest.approx(4 * math.pi)
    assert shaded == pytest.approx(area, rel=0.03)
    assert Region(np.array(normals)).area() == pytest.approx(area, rel=1e-9)


def test_boundary_arcs_lie_on_constraint_planes_inside_the_region():
    normals = np.array([[-1, 0, 0], [0, 1, 0], [0, 0, -1], [-1, 0, -2]], dtype=float)
    arcs = bel.boundary_arcs(normals)
    assert arcs
    for arc in arcs:
        assert np.allclose(np.linalg.norm(arc, axis=1), 1)
        assert (arc @ normals.T >= -1e-9).all()
        on_some_plane = np.isclose(arc @ normals.T, 0, atol=1e-9).any(axis=1)
        assert on_some_plane.all()
    # the fourth constraint is redundant (x <= 0, z <= 0 imply x + 2z <= 0): the edges are
    # the octant's three quarter circles, total length 3 * pi / 2
    total = sum(np.linalg.norm(np.diff(a, axis=0), axis=1).sum() for a in arcs)
    assert total == pytest.approx(3 * math.pi / 2, rel=0.01)


def test_sphere_picture_shows_the_region_and_w_star(tmp_path):
    w = np.array([-3, 3.5, -1.0])
    fig = bel.plot_belief_sphere([[-1, 0, 0], [0, 1, 0], [0, 0, -1]], w_true=w, resolution=40)
    fig.canvas.draw()
    img = np.asarray(fig.canvas.buffer_rgba())[..., :3].astype(int)
    green = (np.abs(img - on_white(bel.BELIEF_COLOR)).max(axis=-1) <= 12).mean()
    assert green > 0.03  # the region covers a visible part of the picture
    ax = fig.axes[0]
    stars = [c for c in ax.collections if len(c.get_sizes()) and c.get_sizes().max() >= 100]
    assert stars  # the w* marker was drawn
    bel.save_figure(fig, tmp_path / "sphere.png")
    assert (tmp_path / "sphere.png").stat().st_size > 1000


def test_sphere_with_bec_shades_overlap_and_rejects_wrong_dimension():
    # seen from -x: the upper half is BEC only (yellow), the lower half both (olive)
    fig = bel.plot_belief_sphere([[0, 0, -1]], bec=[[-1, 0, 0]], resolution=30, view=(0, 180))
    fig.canvas.draw()
    img = np.asarray(fig.canvas.buffer_rgba())[..., :3].astype(int)
    for color in (bel.BOTH_COLOR, bel.BEC_COLOR):
        near = np.abs(img - (255 * color[:3]).astype(int)).max(axis=-1) <= 40
        assert near.mean() > 0.05
    with pytest.raises(ValueError, match=r"needs 3 features.*shape \(1, 4\)"):
        bel.plot_belief_sphere([[0, 0, -1, 1]])


def test_area_curves_plot_each_conditions_series():
    curricula = {
        cond: {
            "prior": [[0, 0, -1]],
            "demos": [{"belief_area_after": 2.0 / (k + 1)}, {"belief_area_after": 0.5 / (k + 1)}],
        }
        for k, cond in enumerate(["proposed", "baseline"])
    }
    fig = bel.plot_belief_areas(curricula)
    lines = {ln.get_label(): ln for ln in fig.axes[0].get_lines()}
    assert list(lines) == ["baseline", "proposed"]  # the paper's condition order
    x, y = lines["proposed"].get_data()
    assert list(x) == [0, 1, 2]
    assert y[0] == pytest.approx(2 * math.pi)  # the prior w_step <= 0 is a hemisphere
    assert list(y[1:]) == [2.0, 0.5]
    assert fig.axes[0].get_yscale() == "log"


def test_region_vertices_of_the_octant_are_its_three_axes():
    verts = bel.region_vertices(np.array([[-1, 0, 0], [0, 1, 0], [0, 0, -1]], float))
    expected = {(-1, 0, 0), (0, 1, 0), (0, 0, -1)}
    assert {tuple(int(round(x)) for x in v) for v in verts} == expected
    assert bel.region_radius(np.array([[0, 0, -1]], float)) is None  # a hemisphere


def test_tiny_regions_get_a_zoom_inset_that_shows_them():
    # a thin wedge around w = (0, 0, -1): |x| <= 0.01 |z|, |y| <= 0.01 |z| (about 1 degree)
    normals = np.array([[100, 0, -1], [-100, 0, -1], [0, 100, -1], [0, -100, -1]], float)
    radius = bel.region_radius(normals)
    assert radius == pytest.approx(math.atan(0.01 * math.sqrt(2)), rel=1e-6)
    fig = bel.plot_belief_sphere(normals, w_true=[0, 0, -1], resolution=24)
    assert len(fig.axes) == 2
    inset = fig.axes[1]
    image = inset.get_images()[0].get_array()
    h, w = image.shape[:2]
    centre = np.asarray(image[h // 2, w // 2])
    assert np.allclose(centre, bel.BELIEF_COLOR)  # the region fills the inset's middle
    assert np.allclose(np.asarray(image[2, 2]), [1, 1, 1, 1])  # and not its corner
    big = bel.plot_belief_sphere([[-1, 0, 0], [0, 1, 0], [0, 0, -1]], resolution=24)
    assert len(big.axes) == 1
