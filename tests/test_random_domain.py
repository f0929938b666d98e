"""cfteach.domains.random: reproducible random gridworlds that keep the goal reachable."""

from __future__ import annotations

import numpy as np
import pytest

from cfteach.domains.random import random_gridworld_dict


def _flood(free: set[tuple[int, int]], start: tuple[int, int]) -> set[tuple[int, int]]:
    """Independent reachability: repeated neighbour expansion until nothing changes."""
    seen = {start}
    while True:
        grown = seen | {(x + dx, y + dy) for x, y in seen
                        for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1))} & free
        if grown == seen:
            return seen
        seen = grown


@pytest.mark.parametrize("seed", range(12))
def test_walls_never_cut_off_any_free_cell(seed: int) -> None:
    d = random_gridworld_dict(7, 6, 4, 32, seed, wall_fraction=0.35)
    w, h = d["domain"]["width"], d["domain"]["height"]
    walls = {tuple(c) for c in d["domain"]["walls"]}
    free = {(x, y) for x in range(1, w + 1) for y in range(1, h + 1)} - walls
    start, goal = tuple(d["agent"]["start"]), tuple(d["goal"]["agent_at"])
    assert start in free and goal in free and start != goal
    assert _flood(free, start) == free
    assert len(walls) > 0
    for v in d["variants"]:
        for cells in v["add_cells"].values():
            for c in cells:
                assert tuple(c) in free and tuple(c) != goal


def test_shape_of_the_domain_follows_the_arguments() -> None:
    d = random_gridworld_dict(10, 10, 5, 4096, 0)
    assert len(d["variants"]) == 12
    names = [f["name"] for f in d["features"]]
    assert names == ["kind1", "kind2", "kind3", "kind4", "step"]
    weights = np.array([f["weight"] for f in d["features"]])
    assert (weights < 0).all() and weights[-1] == -1.0 and (weights[:-1] < -1).all()
    # Each kind is switched on by some bit, and later kinds yield to earlier ones.
    kinds = [next(iter(v["add_cells"])) for v in d["variants"]]
    assert set(kinds) == set(names[:-1])
    assert d["features"][3]["unless"] == ["kind1", "kind2", "kind3"]
    assert d["beliefs"]["prior"] == [[0, 0, 0, 0, -1]]
    assert np.array_equal(d["beliefs"]["posterior"], -np.eye(5, dtype=int))


def test_same_seed_same_domain_other_seed_other_domain() -> None:
    a = random_gridworld_dict(8, 8, 4, 64, 5)
    b = random_gridworld_dict(8, 8, 4, 64, 5)
    c = random_gridworld_dict(8, 8, 4, 64, 6)
    assert a == b
    assert a != c


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((1, 5, 3, 8, 0), "width must be at least 2"),
        ((5, 5, 1, 8, 0), "n_features must be at least 2"),
        ((5, 5, 3, 12, 0), "power of two"),
        ((5, 5, 3, 8, -1), "seed must be at least 0"),
    ],
)
def test_bad_arguments_are_named(args: tuple, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        random_gridworld_dict(*args)
    with pytest.raises(TypeError, match="width must be an int"):
        random_gridworld_dict(5.0, 5, 3, 8, 0)  # type: ignore[arg-type]


def test_random_gridworld_loads_as_a_domain_with_reachable_goal() -> None:
    from cfteach.domains.random import random_gridworld

    dom = random_gridworld(6, 5, 4, 16, 2)
    data = random_gridworld_dict(6, 5, 4, 16, 2)
    assert len(dom.instances()) == 16
    assert dom.feature_names == ("kind1", "kind2", "kind3", "step")
    raw = np.array([f["weight"] for f in data["features"]])
    np.testing.assert_allclose(dom.weights, raw / np.linalg.norm(raw))
    n_free = 6 * 5 - len(data["domain"]["walls"])
    for inst in dom.instances():
        states = inst.states()
        # every free cell but the (terminal) goal is a reachable state
        assert len(states) == n_free - 1
        reaches_goal = any(inst.step(s, a)[2] for s in states for a in range(4))
        assert reaches_goal
    # bit b switches on the cells of variant b
    last = dom.instances()[-1]
    for v in data["variants"]:
        for kind, cells in v["add_cells"].items():
            assert {tuple(c) for c in cells} <= set(last.cells(kind))
    assert dom.instances()[0].cells("kind1") == frozenset()


def test_generator_is_reachable_from_the_domains_package() -> None:
    import cfteach.domains as domains

    dom = domains.random_gridworld(4, 4, 3, 4, seed=0)
    assert "random_gridworld" in domains.__all__
    assert dom.feature_names[-1] == "step" and len(dom.instances()) == 4
