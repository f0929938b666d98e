"""Synthetic gridworld domains of any size and number of features, for scale-out sweeps.

The paper's domains stop at 3 features and a few hundred instances. To measure how teaching
and simulated learners behave beyond that, `random_gridworld` draws a tiles-like domain:
`n_features - 1` "leave a cell of kind k" features (as the tiles domain's A/B tiles) plus
a step feature, random negative weights, random walls that keep every free cell (and so
the goal) reachable, and `log2(n_instances)` variant bits, each switching on a few cells
of one kind. Everything is drawn from `seed`, and the domain is built through the same
declarative loader as user files (`parse_spec`, as `cfteach.domains.from_dict` does), so it
is an ordinary `Domain` (and `random_gridworld_dict(...)` can be saved as a TOML domain
file).
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from cfteach.domains.model import Domain
from cfteach.domains.spec import parse_spec

__all__ = ["RANDOM_SPEC_HELP", "is_random_spec", "parse_random_spec", "random_gridworld",
           "random_gridworld_dict"]

#: How a random domain is written wherever a domain name or file is accepted.
RANDOM_SPEC_HELP = "random:WxH:fF:nN:sS (e.g. random:10x10:f5:n64:s0)"


def _check_int(name: str, value: object, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise TypeError(f"random_gridworld: {name} must be an int, got {value!r}")
    if value < low:
        raise ValueError(f"random_gridworld: {name} must be at least {low}, got {value}")
    return int(value)


def _connected(free: set[tuple[int, int]]) -> bool:
    """Whether the 4-neighbourhood graph of the free cells is one piece."""
    if not free:
        return False
    start = next(iter(free))
    seen = {start}
    queue = deque([start])
    while queue:
        x, y = queue.popleft()
        for nb in ((x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)):
            if nb in free and nb not in seen:
                seen.add(nb)
                queue.append(nb)
    return len(seen) == len(free)


def random_gridworld_dict(width: int, height: int, n_features: int, n_instances: int,
                          seed: int, *, wall_fraction: float = 0.15,
                          cells_per_variant: int = 2, name: str | None = None
                          ) -> dict[str, Any]:
    """The domain-file data (the TOML format of docs/domains.md, as a dict) of a random
    gridworld; see `random_gridworld`."""
    width = _check_int("width", width, 2)
    height = _check_int("height", height, 2)
    n_features = _check_int("n_features", n_features, 2)
    n_instances = _check_int("n_instances", n_instances, 2)
    cells_per_variant = _check_int("cells_per_variant", cells_per_variant, 1)
    _check_int("seed", seed, 0)
    if n_instances & (n_instances - 1):
        raise ValueError(
            "random_gridworld: n_instances must be a power of two (instances are all "
            f"combinations of on/off variant bits), got {n_instances}"
        )
    if not 0.0 <= wall_fraction < 1.0:
        raise ValueError(f"random_gridworld: wall_fraction must be in [0, 1), got {wall_fraction}")
    n_bits = n_instances.bit_length() - 1
    n_kinds = n_features - 1
    rng = np.random.default_rng(seed)

    cells = [(x, y) for x in range(1, width + 1) for y in range(1, height + 1)]
    # Start and goal: two distinct cells at least half the grid's span apart.
    min_dist = max(1, (width + height - 2) // 2)
    while True:
        i, j = rng.choice(len(cells), size=2, replace=False)
        start, goal = cells[int(i)], cells[int(j)]
        if abs(start[0] - goal[0]) + abs(start[1] - goal[1]) >= min_dist:
            break

    # Walls: try cells in random order, keep a wall only if the free cells stay connected.
    free = set(cells)
    walls: list[tuple[int, int]] = []
    n_walls = int(round(wall_fraction * len(cells)))
    for k in rng.permutation(len(cells)):
        if len(walls) >= n_walls:
            break
        c = cells[int(k)]
        if c in (start, goal):
            continue
        free.discard(c)
        if _connected(free):
            walls.append(c)
        else:
            free.add(c)

    # Variant bits: bit b switches on `cells_per_variant` free cells of kind (b mod kinds);
    # the goal is never a kind cell (it is terminal, so it could never be left).
    tile_pool = sorted(free - {goal})
    kind_names = [f"kind{k + 1}" for k in range(n_kinds)]
    variants = []
    for b in range(n_bits):
        kind = kind_names[b % n_kinds]
        picks = rng.choice(len(tile_pool), size=min(cells_per_variant, len(tile_pool)),
                           replace=False)
        variants.append({"add_cells": {kind: [list(tile_pool[int(p)]) for p in sorted(picks)]}})

    # Weights: every kind costs more than a step (as in tiles), all negative.
    kind_weights = -np.round(rng.uniform(1.5, 8.0, size=n_kinds), 2)
    features: list[dict[str, Any]] = []
    for k, kname in enumerate(kind_names):
        feat: dict[str, Any] = {"name": kname, "label": f"Kind {k + 1} cell",
                                "weight": float(kind_weights[k]),
                                "when": {"leaves_cells": kname}}
        if k:
            feat["unless"] = kind_names[:k]
        features.append(feat)
    features.append({"name": "step", "label": "Step", "weight": -1.0})

    eye = np.eye(n_features, dtype=int)
    dname = name or f"random-{width}x{height}-f{n_features}-n{n_instances}-s{seed}"
    return {
        "domain": {
            "name": dname,
            "title": f"Random gridworld {width}x{height}, {n_features} features",
            "description": (f"Synthetic domain from cfteach.domains.random_gridworld(seed={seed}): "
                            "walk to the goal; leaving a cell of each kind has its own cost."),
            "width": width,
            "height": height,
            "discount": 1.0,
            "walls": [list(w) for w in sorted(walls)],
        },
        "cells": {k: [] for k in kind_names},
        "agent": {"start": list(start)},
        "goal": {"agent_at": list(goal)},
        "variants": variants,
        "features": features,
        "beliefs": {
            "prior": [[0] * (n_features - 1) + [-1]],
            "posterior": (-eye).tolist(),
        },
    }


def random_gridworld(width: int, height: int, n_features: int, n_instances: int,
                     seed: int, **options: Any) -> Domain:
    """A random `Domain` with `n_features` features and `n_instances` instances (a power of
    two: `log2(n_instances)` variant bits), reproducible from `seed`.

    Options: `wall_fraction` (share of cells that become walls, default 0.15; walls never
    disconnect the free cells), `cells_per_variant` (cells a variant bit switches on, 2),
    `name`. Example: ``random_gridworld(10, 10, 5, 4096, seed=0)``.
    """
    data = random_gridworld_dict(width, height, n_features, n_instances, seed, **options)
    return Domain.from_spec(parse_spec(data, source=f"random_gridworld(seed={seed})"))


def is_random_spec(text: object) -> bool:
    """Whether a domain argument is a random-domain spec (``random:...``)."""
    return isinstance(text, str) and text.startswith("random:")


def parse_random_spec(spec: str) -> tuple[int, int, int, int, int]:
    """``random:WxH:fF:nN:sS`` -> (width, height, n_features, n_instances, seed).

    Every command that takes a domain accepts this form (`cfteach.domains.load`), so a
    synthetic domain can be checked, taught and rendered like a file."""
    parts = spec.split(":")[1:]
    try:
        if len(parts) != 4:
            raise ValueError
        w, h = (int(x) for x in parts[0].lower().split("x"))
        keys = {p[0].lower(): int(p[1:]) for p in parts[1:]}
        if set(keys) != {"f", "n", "s"}:
            raise ValueError
    except (ValueError, IndexError):
        raise ValueError(f"bad random domain {spec!r}: write {RANDOM_SPEC_HELP}") from None
    return w, h, keys["f"], keys["n"], keys["s"]
